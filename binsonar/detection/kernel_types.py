"""The typed bundles the compiled detection kernels take, one per concern, read by field name.

A kernel's numbers travel in one-element numpy structured arrays (``record(DTYPE, **fields)``),
read as ``p = bundle[0]; p.field``; its per-row results in structured arrays of one record per
row (``ECHO``); its arrays (the samples, their offsets, tables, outputs) as plain arguments,
each named for what it holds. numba dispatches an array of any dtype as fast as a plain array,
where a ``NamedTuple`` argument goes through Python-level type inference on every call (tens of
microseconds once a new ping has evicted the caches: as much as a sub-millisecond detector's
whole budget for arguments). Records a plan can build once are built once (``local.LocalPlan``,
``overlap_save.BlockEnvelopePlan``). The dtypes are immutable module constants. This module
imports numpy only.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

CROSSING_SEARCH = np.dtype([
    ("scale", np.float64),  # volts per unit of the samples: 1.0 for volts, the code step for codes
    ("first", np.int64),  # searched samples [first, stop)
    ("stop", np.int64),
    ("window", np.int64),  # samples measured from the crossing on (amplitude and energy)
    ("sample_rate_hz", np.float64),
    ("t0_s", np.float64),  # time of sample 0 after the trigger (s)
    ("offset_s", np.float64),  # calibrated offset subtracted from the crossing time (s)
])
"""Where the threshold detector searches and measures, and how a crossing becomes a time of flight."""

ECHO = np.dtype([
    ("tof_s", np.float64),
    ("amplitude", np.float64),
    ("snr_db", np.float64),
    ("score", np.float64),
    ("tof_std_s", np.float64),
])
"""Per row: an echo's values (``Echo``'s fields, in its order)."""

LOCAL_SEARCH = np.dtype([
    ("scale", np.float64),  # volts per unit of the samples: 1.0 for volts, the code step for codes
    ("block", np.int64),  # coarse-stage block length B (samples)
    ("span", np.int64),  # blocks per window
    ("reference", np.int64),  # the template's envelope-peak index (samples)
    ("exclusion", np.int64),  # windows blanked each side of a pick (a template length)
    ("half", np.int64),  # lags searched each side of a pick
    ("segment_length", np.int64),  # samples per stretch (2 half + m)
    ("lag_lo", np.int64),  # inclusive range of searched lags
    ("lag_hi", np.int64),
    ("candidates", np.int64),  # coarse picks per row
    ("analytic_offset", np.int64),  # index of the template's sample 0 among the analytic taps
    ("stride", np.int64),  # the search samples every stride-th lag (``LocalPlan.decimation``)
    ("reach", np.int64),  # direct lags each side of the searched peak for the refinement
])
"""The local matched filter's layout (``local.LocalPlan``) and the lags it searches (full-rate samples)."""

ECHO_CONSTANTS = np.dtype([
    ("t0_s", np.float64),  # time of sample 0 after the trigger (s)
    ("sample_rate_hz", np.float64),
    ("template_t0_s", np.float64),  # the template's time origin (s): a TOF refers to its reference instant
    ("noise_gain", np.float64),  # mean |z|^2 of white noise of 1 V std (``matched.white_noise_power``)
    ("peak_response", np.float64),  # |z| of an echo equal to the template
    ("peak_abs", np.float64),  # the template's largest |sample|
    ("rms_bandwidth_hz", np.float64),
    ("threshold_factor", np.float64),  # |z|^2 over the noise's mean |z|^2 at the detection threshold
])
"""What turns a refined matched-filter peak into an echo (``matched.echo_values``' constants)."""

CODE_SCALE = np.dtype([
    ("period", np.int64),  # the robust subsample: ``segments`` stretches of ``length`` samples at
    ("length", np.int64),  # multiples of ``period`` (``noise.robust_subsample``; the whole row:
    ("segments", np.int64),  # one stretch of n_samples)
    ("volts_per_code", np.float64),
    ("mad_to_sigma", np.float64),  # the robust noise estimate's factor (``noise.MAD_TO_SIGMA``)
])
"""How ADC codes become volts and robust statistics (``code_kernels.code_statistics``)."""

BLOCK_LAYOUT = np.dtype([("hop", np.int64), ("lead", np.int64)])
"""Overlapping blocks of a record: block b starts at sample ``b hop - lead``."""


def record(dtype: np.dtype, **fields: Any) -> NDArray[np.void]:
    """A one-element structured array of ``dtype`` with the given fields: all of them, in the
    dtype's order (checked: a missing or misplaced number is a bug, not a default).

    Raises
    ------
    ValueError
        Fields other than the dtype's, or in another order.
    """
    if tuple(fields) != dtype.names:
        raise ValueError(f"record: fields {tuple(fields)} are not {dtype.names}")
    return np.array([tuple(fields.values())], dtype=dtype)


def read_only(array: NDArray) -> NDArray:
    """``array``, made read-only (a record memoised and shared between calls)."""
    array.flags.writeable = False
    return array
