"""Rerun the seed's comparison of its nine combinations (section 4.2.4, figures 4-15 to 4-17).

For every combination: the rate of correct detections (the seed counts a detection correct
when its range error is below 1 cm, i.e. a TOF error below 2 x 0.01 m / c for the two-way
path), the mean absolute TOF error of the correct ones, and the processing time per position
(all the pings recorded at one position, as the seed timed it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.detection.api import detect
from binsonar.detection.seed import SEED_COMBINATIONS
from binsonar.recording import Recording, RecordingError


@dataclass(frozen=True)
class SeedComparisonRow:
    """One combination's figures.

    Attributes
    ----------
    method : str
        "seed-1" ... "seed-9".
    description : str
    correct_rate : float
        Fraction of (ping, channel) TOFs within the tolerance (0..1).
    mean_abs_error_s : float
        Mean |TOF error| of the correct ones (s); NaN if none.
    seconds_per_position : float
        Processing time of all the pings of the position (s).
    """

    method: str
    description: str
    correct_rate: float
    mean_abs_error_s: float
    seconds_per_position: float


def compare_seed_methods(
    data: Recording | NDArray[np.floating],
    true_tof_s: ArrayLike,
    *,
    sound_speed_m_s: float = 1482.0,
    range_tolerance_m: float = 0.01,
    **detect_options: Any,
) -> tuple[SeedComparisonRow, ...]:
    """Run seed-1 ... seed-9 on the pings of one position and score them against the truth.

    Parameters
    ----------
    data : Recording or array
        The pings of one position, (n_pings, 3, n_samples) (see ``detect``).
    true_tof_s : array_like, shape (3,) or (n_pings, 3)
        True TOF of the echo of interest per channel (s); averaged methods are scored against
        the mean over pings.
    sound_speed_m_s : float
        Converts the range tolerance to time.
    range_tolerance_m : float
        Largest range error counted as correct (the seed: 1 cm); the TOF tolerance is twice it
        over the sound speed (two-way path).
    **detect_options
        Passed to ``detect`` (sample_rate_hz, template, ...).

    Returns
    -------
    tuple of SeedComparisonRow
        In the seed's order.
    """
    truth = np.asarray(true_tof_s, dtype=float)
    if not (np.all(np.isfinite(truth)) and 1000.0 < sound_speed_m_s < 2000.0 and range_tolerance_m > 0):
        raise RecordingError("compare_seed_methods: true_tof_s must be finite, sound speed in (1000, 2000) m/s, "
                             f"tolerance > 0; got speed {sound_speed_m_s!r}, tolerance {range_tolerance_m!r}")
    tolerance_s = 2.0 * range_tolerance_m / sound_speed_m_s
    rows = []
    for combination in SEED_COMBINATIONS:  # nine methods
        result = detect(data, combination.name, **detect_options)
        n_pings = result.n_pings
        expected = np.broadcast_to(truth, (max(n_pings, 1), 3) if truth.ndim == 1 else truth.shape)
        if combination.average:
            expected = expected.mean(axis=0, keepdims=True)
        errors = np.array([
            [ch[0].tof_s - expected[p, c] if ch else np.nan for c, ch in enumerate(ping)]
            for p, ping in enumerate(result.echoes)
        ])
        correct = np.abs(np.nan_to_num(errors, nan=np.inf)) < tolerance_s
        rows.append(SeedComparisonRow(
            method=combination.name,
            description=combination.description,
            correct_rate=float(correct.mean()),
            mean_abs_error_s=float(np.abs(errors[correct]).mean()) if correct.any() else float("nan"),
            seconds_per_position=result.elapsed_s,
        ))
    return tuple(rows)
