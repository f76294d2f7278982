"""The record window: what part of a ping the digitiser keeps (blanking and range gate).

The main bang and the cross-talk (the direct path reaches the side receivers after
d / c, about 44 us for d = 65 mm) saturate the start of every record, and the far walls and a
target's own rear edges come late. A real sonar blanks its receivers for a while after
transmitting and digitises a range window; the simulated recording is cut the same way: the
window's samples are kept and ``t0_s`` becomes the window's start, exactly as a digitiser with
a trigger delay would write it. Nothing else of the recording changes.
"""

from __future__ import annotations

import math
from dataclasses import replace

from binsonar.recording import Recording

BLANKING_S = 70e-6
"""Receiver blanking after the transmit trigger (s): past the cross-talk at ~44 us plus the
pulse's support (about +/- 10 us for the 5 us Gaussian) and the main bang's decay (2 us)."""


def range_window_s(range_m: float, sound_speed_m_s: float, half_width_m: float,
                   blanking_s: float = BLANKING_S) -> tuple[float, float]:
    """Times (s after the trigger) of a range gate ``range_m +/- half_width_m``, not before the blanking.

    Parameters
    ----------
    range_m : float
        Range the gate is centred on (m).
    sound_speed_m_s : float
    half_width_m : float
        Half the gate's depth in range (m).
    blanking_s : float
        Nothing is kept before this time (s).
    """
    start = max(blanking_s, 2.0 * (range_m - half_width_m) / sound_speed_m_s)
    stop = 2.0 * (range_m + half_width_m) / sound_speed_m_s
    return start, stop


def gate_recording(recording: Recording, start_s: float, stop_s: float | None = None) -> Recording:
    """The recording's samples between ``start_s`` and ``stop_s`` (s after the trigger), with ``t0_s`` moved.

    Parameters
    ----------
    recording : Recording
    start_s : float
        First time kept (s); rounded down to a sample.
    stop_s : float, optional
        Last time kept (s); default the end of the record.

    Returns
    -------
    Recording
        Same pings, channels, template, pose and environment; fewer samples.
    """
    fs = recording.sample_rate_hz
    n = recording.waveforms.shape[-1]
    i0 = max(0, int(math.floor((start_s - recording.t0_s) * fs)))
    i1 = n if stop_s is None else min(n, int(math.ceil((stop_s - recording.t0_s) * fs)) + 1)
    if i1 - i0 < 2:
        raise ValueError(f"gate [{start_s!r}, {stop_s!r}] s keeps fewer than 2 samples of the record")
    return replace(recording, waveforms=recording.waveforms[..., i0:i1], t0_s=recording.t0_s + i0 / fs)
