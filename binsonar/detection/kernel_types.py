"""The typed bundles the compiled detection kernels take (one per concern, read by field name).

numba passes a ``NamedTuple`` of arrays and numbers to a compiled function as a tuple of typed
fields, so a kernel's arguments are a few bundles, not a long positional list or a settings
array read by index. Build them with ``int(...)`` and ``float(...)`` fields (a numpy integer
would compile another specialisation). This module imports numpy only.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray


class CodedRows(NamedTuple):
    """The rows a kernel reads, and how to turn their values into volts.

    Attributes
    ----------
    samples : ndarray, shape (n_rows, n_samples), C-contiguous
        float64 volts, or int16 ADC codes.
    scale : float
        Volts per unit of ``samples``: 1.0 for volts, the code step for codes.
    dc_v : ndarray, shape (n_rows,), float64
        Each row's DC offset (V) still in ``samples`` (zeros for none): the kernels compute
        with ``samples * scale - dc_v``.
    """

    samples: NDArray
    scale: float
    dc_v: NDArray[np.float64]


# --- the threshold detector (``threshold_kernels``) ---


class RowLevels(NamedTuple):
    """Per-row levels of the threshold detector (V), shape (n_rows,) each.

    Attributes
    ----------
    level_v : ndarray
        The threshold on |x - dc|.
    sigma_v : ndarray
        The noise standard deviation (for the echo's SNR and TOF std).
    """

    level_v: NDArray[np.float64]
    sigma_v: NDArray[np.float64]


class CrossingSearch(NamedTuple):
    """Where the threshold detector searches and measures (samples).

    Attributes
    ----------
    first, stop : int
        Searched samples [first, stop) (0 <= first <= stop <= n_samples).
    window : int
        Samples measured from the crossing on (amplitude and energy).
    """

    first: int
    stop: int
    window: int


class CrossingTiming(NamedTuple):
    """How a crossing's sample becomes a time of flight.

    Attributes
    ----------
    sample_rate_hz : float
    t0_s : float
        Time of sample 0 after the trigger (s).
    offset_s : float
        Calibrated offset subtracted from the crossing time (s).
    """

    sample_rate_hz: float
    t0_s: float
    offset_s: float


# --- the local matched filter (``local_kernels``) ---


class CoarseLayout(NamedTuple):
    """The local matched filter's coarse stage and stretches (``local.LocalPlan``), in samples or blocks.

    Attributes
    ----------
    block : int
        Block length B (samples).
    span : int
        Blocks per window.
    reference : int
        The template's envelope-peak index (samples).
    exclusion : int
        Windows blanked each side of a pick (a template length).
    half : int
        Lags searched each side of a pick.
    segment_length : int
        Samples per stretch (2 half + m).
    """

    block: int
    span: int
    reference: int
    exclusion: int
    half: int
    segment_length: int


class LagSearch(NamedTuple):
    """Which lags the local matched filter searches (full-rate samples).

    Attributes
    ----------
    lag_lo, lag_hi : int
        Inclusive range of searched lags.
    candidates : int
        Coarse picks per row.
    """

    lag_lo: int
    lag_hi: int
    candidates: int


class AnalyticTaps(NamedTuple):
    """The analytic template's taps for direct correlations (``local.LocalPlan``).

    Attributes
    ----------
    parts : ndarray, shape (4, m_a + 1), float64
        The conjugated analytic template (real, imaginary; first m_a columns) and its running
        sums, 0 first (``LocalPlan.tap_parts``).
    parts32 : ndarray, shape (2, m_a + 1), float32
        Its first two rows in single precision (``LocalPlan.tap_parts32``), for the search.
    analytic_offset : int
        Index of the template's sample 0 among the taps.
    stride : int
        The search samples every ``stride``-th lag (``LocalPlan.decimation``).
    reach : int
        Direct lags each side of the searched peak for the refinement.
    """

    parts: NDArray[np.float64]
    parts32: NDArray[np.float32]
    analytic_offset: int
    stride: int
    reach: int


class EchoConstants(NamedTuple):
    """What turns a refined peak into an echo (``matched.echo_values``' constants).

    Attributes
    ----------
    t0_s : float
        Time of sample 0 after the trigger (s).
    sample_rate_hz : float
    template_t0_s : float
        The template's time origin (s): a TOF refers to its reference instant.
    noise_gain : float
        Mean |z|^2 of white noise of 1 V standard deviation (``matched.white_noise_power``).
    peak_response : float
        |z| of an echo equal to the template.
    peak_abs : float
        The template's largest |sample|.
    rms_bandwidth_hz : float
    threshold_factor : float
        |z|^2 over the noise's mean |z|^2 at the detection threshold.
    """

    t0_s: float
    sample_rate_hz: float
    template_t0_s: float
    noise_gain: float
    peak_response: float
    peak_abs: float
    rms_bandwidth_hz: float
    threshold_factor: float


class LocalOutput(NamedTuple):
    """What the local matched filter's kernel writes.

    Attributes
    ----------
    echoes : ndarray, shape (n_rows, 5)
        tof_s, amplitude, snr_db, score, tof_std_s of each row's peak.
    extremes : ndarray, shape (n_rows, 2) or (0, 2)
        Each row's largest and smallest value (units of the samples), read with the coarse
        pass; with no rows, not measured.
    """

    echoes: NDArray[np.float64]
    extremes: NDArray[np.float64]


# --- ADC codes (``code_kernels``) ---


class RobustSubsample(NamedTuple):
    """The robust estimates' subsample (``noise.robust_subsample``): ``segments`` stretches of
    ``length`` samples starting at multiples of ``period`` (the whole row: 1 stretch of n)."""

    period: int
    length: int
    segments: int


class CodeScale(NamedTuple):
    """How codes become volts, and the clipping test.

    Attributes
    ----------
    volts_per_code : float
    mad_to_sigma : float
        The robust noise estimate's factor (``noise.MAD_TO_SIGMA``).
    full_scales_v : ndarray, shape (k,)
        Full scales (V) to test (none: no pass over the whole record).
    """

    volts_per_code: float
    mad_to_sigma: float
    full_scales_v: NDArray[np.float64]


# --- the matched filter's overlap-save blocks (``overlap_save_kernels``) ---


class BlockLayout(NamedTuple):
    """Overlapping blocks of a record: block b starts at sample ``b hop - lead``."""

    hop: int
    lead: int
