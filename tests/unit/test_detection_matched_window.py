"""Matched filter: the false-alarm design holds over the searched lags, not the whole record."""

from __future__ import annotations

import numpy as np

from binsonar.detection import detect
from support.detection_signals import FS, pulse_template

N = 32768


def test_false_alarm_rate_over_a_search_window_matches_the_design():
    # The threshold is set so that the maximum over the *searched* lags of noise-only records
    # exceeds it with probability pfa (Rice's up-crossing rate over the searched duration).
    # 50 pings x 3 channels of noise, a window of 1/8 of the record, pfa = 0.2 per row: about
    # 30 false alarms expected; the count must lie within a factor 2 of that (Poisson sd ~5.5,
    # plus the Rice approximation's ~10-30 % at this short duration). A threshold set for the
    # whole record's duration (8x longer) expects only ~6 and fails the lower bound.
    rng = np.random.default_rng(41)
    noise = rng.standard_normal((50, 3, N))
    duration_s = N / FS
    window = (0.4 * duration_s, 0.4 * duration_s + duration_s / 8)
    result = detect(noise, "matched", sample_rate_hz=FS, template=pulse_template(), pfa=0.2,
                    search_window_s=window)
    tofs = [e.tof_s for ping in result.echoes for ch in ping for e in ch]
    assert all(window[0] <= t <= window[1] for t in tofs)
    assert 15 <= len(tofs) <= 60, len(tofs)
