"""Sub-sample peak interpolation and peak picking shared by the detectors."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

def log_parabolic_offset(
    left: NDArray[np.float64], centre: NDArray[np.float64], right: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Vertex of the parabola through the logarithms of three equally spaced powers.

    Exact for a Gaussian peak (whose logarithm is a parabola), e.g. the matched-filter envelope
    of a Gaussian pulse; for any smooth peak sampled finely it converges to the continuous
    maximum.

    Parameters
    ----------
    left, centre, right : ndarray, shape (k,)
        Powers (e.g. |z|^2) at offsets -1, 0, +1, normally with ``centre`` the largest (where
        it is not, or a neighbour is 0, the offset is 0 and the peak is ``centre``).

    Returns
    -------
    offset : ndarray, shape (k,)
        Vertex position in units of the spacing, in [-0.5, 0.5].
    peak : ndarray, shape (k,)
        Interpolated power at the vertex.
    """
    left = np.asarray(left, dtype=float)
    centre = np.asarray(centre, dtype=float)
    right = np.asarray(right, dtype=float)
    # Interpolate only around a true local maximum with positive neighbours (not, e.g., at the
    # edge of the searched lags, where a neighbour is 0): elsewhere keep the sample itself.
    usable = (left > 0) & (right > 0) & (centre >= left) & (centre >= right)
    y_l = np.log(np.where(usable, left, 1.0))
    y_c = np.log(np.where(usable, centre, 1.0))
    y_r = np.log(np.where(usable, right, 1.0))
    curvature = y_l - 2.0 * y_c + y_r
    ok = usable & (curvature < 0.0)
    offset = np.clip(np.where(ok, 0.5 * (y_l - y_r) / np.where(ok, curvature, -1.0), 0.0), -0.5, 0.5)
    peak = np.where(ok, np.exp(y_c - 0.25 * (y_l - y_r) * offset), centre)
    return offset, peak


def parabolic_offset(
    left: NDArray[np.float64], centre: NDArray[np.float64], right: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Vertex of the parabola through three equally spaced values (no logarithm).

    Returns
    -------
    offset : ndarray
        In units of the spacing, clipped to [-0.5, 0.5].
    peak : ndarray
        Interpolated value at the vertex.
    """
    curvature = left - 2.0 * centre + right
    safe = np.where(curvature < 0.0, curvature, -1.0)
    offset = np.clip(np.where(curvature < 0.0, 0.5 * (left - right) / safe, 0.0), -0.5, 0.5)
    return offset, centre - 0.25 * (left - right) * offset


def peaks_above(
    values: NDArray[np.float64], threshold: float
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
    """One peak per contiguous region of a 1-D statistic above a threshold.

    Each region (maximal run of samples with ``values > threshold``) gives its maximum, refined
    by ``parabolic_offset`` through its two neighbours (not at the array's first or last
    sample, where a neighbour is missing: offset 0 and the sample's value).

    Parameters
    ----------
    values : ndarray, shape (n,)
    threshold : float

    Returns
    -------
    start : ndarray of int, shape (k,)
        First sample of each region.
    index : ndarray of int, shape (k,)
        Sample of each region's maximum (the first one on a plateau).
    offset : ndarray, shape (k,)
        Vertex offset from ``index`` in samples, in [-0.5, 0.5].
    peak : ndarray, shape (k,)
        Interpolated value at the vertex.
    """
    values = np.asarray(values, dtype=float)
    n = values.size
    above = values > threshold
    bounds = np.flatnonzero(np.diff(np.concatenate([[0], above.astype(np.int8), [0]])))
    start = bounds[::2]
    if start.size == 0:
        empty = np.zeros(0)
        return start.astype(np.intp), start.astype(np.intp), empty, empty
    # Maximum of each region: the regions' maxima by reduceat, then their first position.
    region_max = np.maximum.reduceat(values, start)
    marker = np.zeros(n, dtype=np.intp)
    marker[start] = 1
    region_of = np.cumsum(marker) - 1  # region index of each sample (-1 before the first)
    hits = np.flatnonzero(above & (values == region_max[np.clip(region_of, 0, None)]))
    index = hits[np.searchsorted(hits, start)]  # first maximum at or after each region's start
    inner = (index > 0) & (index < n - 1)
    i = np.clip(index, 1, max(n - 2, 1))
    if n >= 3:
        offset, peak = parabolic_offset(values[i - 1], values[i], values[i + 1])
    else:
        offset, peak = np.zeros(index.size), values[index]
    offset = np.where(inner, offset, 0.0)
    peak = np.where(inner, peak, values[index])
    return start.astype(np.intp), index.astype(np.intp), offset, peak


def local_maxima(values: NDArray[np.float64], mask: NDArray[np.bool_]) -> NDArray[np.intp]:
    """Indices of the local maxima of a 1-D array where ``mask`` is True (plateaus: first sample)."""
    if values.size < 3:
        return np.flatnonzero(mask & (values == values.max())) if values.size else np.zeros(0, dtype=np.intp)
    inner = (values[1:-1] >= values[:-2]) & (values[1:-1] > values[2:])
    is_max = np.concatenate([[values[0] > values[1]], inner, [values[-1] >= values[-2]]])
    return np.flatnonzero(is_max & mask)


def select_peaks(
    positions: NDArray[np.float64],
    powers: NDArray[np.float64],
    min_separation: float,
    sidelobe_power: "SidelobeModel | None" = None,
    sidelobe_margin: float = 4.0,
) -> NDArray[np.intp]:
    """Greedy peak selection: strongest first, a minimum separation, and side-lobe suppression.

    Parameters
    ----------
    positions : ndarray, shape (k,)
        Peak positions (any unit, the same as ``min_separation``).
    powers : ndarray, shape (k,)
        Peak powers.
    min_separation : float
        A weaker peak closer than this to an accepted one is dropped.
    sidelobe_power : callable, optional
        ``sidelobe_power(distance) -> relative power`` of the filter's response to one echo at
        that distance from its peak (1 at 0). A weaker peak whose power is below
        ``sidelobe_margin`` times the side-lobe power predicted from an accepted peak is taken
        as that peak's side lobe and dropped.
    sidelobe_margin : float
        Power ratio (default 4, i.e. 6 dB of margin over the predicted side lobe).

    Returns
    -------
    ndarray of int
        Indices of the kept peaks, in increasing position.
    """
    order = np.argsort(powers)[::-1]
    kept: list[int] = []
    for i in order:  # loop over candidate peaks (few), not samples
        if kept:
            distance = np.abs(positions[kept] - positions[i])
            if np.any(distance < min_separation):
                continue
            if sidelobe_power is not None:
                predicted = powers[kept] * sidelobe_power(distance)
                if np.any(powers[i] < sidelobe_margin * predicted):
                    continue
        kept.append(int(i))
    kept_arr = np.array(kept, dtype=np.intp)
    return kept_arr[np.argsort(positions[kept_arr])] if kept_arr.size else kept_arr


class SidelobeModel:
    """Relative power of a filter's response to one echo versus distance from its peak.

    Parameters
    ----------
    response_power : ndarray, shape (n,)
        |response|^2 / |response(0)|^2 at distances 0, spacing, 2 spacing, ...
    spacing : float
        Distance between entries (same unit as the distances queried).
    """

    def __init__(self, response_power: NDArray[np.float64], spacing: float) -> None:
        self._power = np.asarray(response_power, dtype=float)
        self._spacing = float(spacing)

    def __call__(self, distance: NDArray[np.float64]) -> NDArray[np.float64]:
        """Relative power at these distances (0 beyond the tabulated range)."""
        x = np.abs(np.asarray(distance, dtype=float)) / self._spacing
        return np.interp(x, np.arange(self._power.size), self._power, right=0.0)
