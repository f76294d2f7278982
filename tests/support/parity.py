"""Row-by-row comparison of two engines' paths: the parity suite's one assertion.

Two engines may number their paths differently and order rows of equal delay differently, so
rows are matched by what they are: (channel, kind, order, object_ids) then delay; runs of rows
whose delays agree within the tolerance are ordered by their interaction points and gain.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

DELAY_TOLERANCE_S = 1e-12
"""Delays agree within 1 ps (issue 16): 1.5 nm of path, far below anything a 20 MHz record
resolves, yet about 1000 times the float64 rounding of a 10 ms delay."""

AMPLITUDE_RTOL = 1e-9
"""Amplitudes agree within 1e-9 relative: the engines evaluate the same formulas in different
orders (compiled loops, fused passes), which moves the last few of the 16 digits."""


def canonical_order(rows: NDArray[Any], delay_tolerance_s: float = DELAY_TOLERANCE_S) -> NDArray[np.intp]:
    """An order of ``rows`` (PATH_DTYPE) that depends on what the rows are, not on their ids.

    Sorted by channel, kind, order, object ids, then delay quantised to 100 x the tolerance,
    then interaction points and gain (so that rows of one arrival that agree to rounding in
    delay still pair up).
    """
    points = np.nan_to_num(rows["points_m"].reshape(rows.size, -1), nan=-1.0)
    keys = [np.round(rows["geometric_gain"], 6)]
    keys += [np.round(points[:, j], 6) for j in range(points.shape[1] - 1, -1, -1)]
    keys += [np.floor(rows["delay_s"] / (100.0 * delay_tolerance_s))]
    keys += [rows["object_ids"][:, j] for j in range(rows["object_ids"].shape[1] - 1, -1, -1)]
    keys += [rows["order"], rows["kind"], rows["channel"]]
    return np.lexsort(keys)


def assert_rows_match(actual: NDArray[Any], expected: NDArray[Any], *, delay_tolerance_s: float = DELAY_TOLERANCE_S,
                      amplitude_rtol: float = AMPLITUDE_RTOL, label: str = "") -> None:
    """Assert that two engines' rows describe the same arrivals.

    Same number of rows; after :func:`canonical_order`, equal channel, kind, order and object
    ids, delays within ``delay_tolerance_s``, amplitudes and geometric gains within
    ``amplitude_rtol`` relative (to the larger of the two, or of the strongest row for rows
    below 1e-12 of it), phases within 1e-9 rad (mod 2 pi), directions and points within 1e-9 m.
    """
    prefix = f"{label}: " if label else ""
    assert actual.size == expected.size, f"{prefix}{actual.size} rows against {expected.size}"
    if actual.size == 0:
        return
    a = actual[canonical_order(actual, delay_tolerance_s)]
    e = expected[canonical_order(expected, delay_tolerance_s)]
    for name in ("channel", "kind", "order", "object_ids"):
        bad = np.flatnonzero(np.any((a[name] != e[name]).reshape(a.size, -1), axis=1))
        assert bad.size == 0, f"{prefix}{name} differs at {bad.size} rows, first {a[bad[0]]} vs {e[bad[0]]}"
    delay_error = np.abs(a["delay_s"] - e["delay_s"])
    assert delay_error.max() <= delay_tolerance_s, f"{prefix}delays differ by up to {delay_error.max():.3g} s"
    for name in ("amplitude", "geometric_gain"):
        floor = max(float(np.abs(e[name]).max()), 1e-300) * 1e-12
        relative = np.abs(a[name] - e[name]) / np.maximum(np.maximum(np.abs(a[name]), np.abs(e[name])), floor)
        assert relative.max() <= amplitude_rtol, (
            f"{prefix}{name} differs by up to {relative.max():.3g} relative (row {int(np.argmax(relative))})")
    phase = np.angle(np.exp(1j * (a["phase_rad"] - e["phase_rad"])))
    assert np.abs(phase).max() <= 1e-9, f"{prefix}phases differ by up to {np.abs(phase).max():.3g} rad"
    for name in ("departure_dir", "arrival_dir"):
        assert np.abs(a[name] - e[name]).max() <= 1e-9, f"{prefix}{name} differs"
    points_a, points_e = a["points_m"], e["points_m"]
    assert np.array_equal(np.isnan(points_a), np.isnan(points_e)), f"{prefix}interaction point counts differ"
    both = ~np.isnan(points_a)
    if both.any():
        assert np.abs(points_a[both] - points_e[both]).max() <= 1e-9, f"{prefix}interaction points differ"
