"""Multi-echo detection: CA- and OS-CFAR on the square-law matched-filter envelope.

The cell under test is |z|^2 at every sample of the decimated matched-filter envelope. Its
noise level is estimated from reference cells on both sides beyond guard cells (default
+/- 3 us, wider than the response's main lobe). Neighbouring envelope samples are correlated
over about the filter's correlation time tau_c (the integral of the squared correlation
coefficient of |z|^2); taking reference cells tau_c apart makes them nearly independent
(correlation coefficient of |z|^2 about 0.04 for a Gaussian pulse), so the textbook
thresholds for N independent exponential cells apply:

- CA-CFAR: threshold = alpha * mean(reference), alpha = N (Pfa^(-1/N) - 1).
- OS-CFAR (Rohling 1983): threshold = alpha * (k-th smallest reference), with
  Pfa = prod_{i=0}^{k-1} (N - i) / (N - i + alpha), k = round(3N/4) by default.

Then: local maxima above the threshold, strongest first, a minimum separation (default the
main lobe's FWHM), and side-lobe suppression (a weaker peak within ``sidelobe_margin`` of the
side-lobe level the stronger one predicts there is dropped). Each survivor is refined to a
sub-sample TOF like the matched filter's peak.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.matched import (
    MatchedPlan,
    cell_mask,
    check_pfa,
    echo_values,
    envelope,
    filtered_spectrum,
    lag_range,
    noise_mean_power,
    refine_peaks,
    white_noise_power,
)
from binsonar.detection.peaks import local_maxima, select_peaks
from binsonar.recording import RecordingError


def ca_alpha(n_ref: int, pfa: float) -> float:
    """CA-CFAR factor on the mean of N exponential reference cells: N (Pfa^(-1/N) - 1)."""
    return n_ref * (pfa ** (-1.0 / n_ref) - 1.0)


def os_pfa(alpha: float, n_ref: int, k: int) -> float:
    """False-alarm probability of OS-CFAR with factor alpha on the k-th of N cells (Rohling)."""
    i = np.arange(k)
    return float(np.prod((n_ref - i) / (n_ref - i + alpha)))


def os_alpha(n_ref: int, k: int, pfa: float) -> float:
    """OS-CFAR factor for a design Pfa (bisection on the decreasing ``os_pfa``, to 1e-12)."""
    low, high = 0.0, 1.0
    while os_pfa(high, n_ref, k) > pfa:  # doubling until bracketed
        high *= 2.0
    for _ in range(200):  # bisection on a scalar
        mid = 0.5 * (low + high)
        if os_pfa(mid, n_ref, k) > pfa:
            low = mid
        else:
            high = mid
        if high - low <= 1e-12 * high:
            break
    return 0.5 * (low + high)


def reference_offsets(guard_cells: int, step: int, n_per_side: int) -> NDArray[np.intp]:
    """Offsets (cells) of the reference cells: +/-(guard + step), +/-(guard + 2 step), ..."""
    one_side = guard_cells + step * np.arange(1, n_per_side + 1)
    return np.concatenate([-one_side[::-1], one_side])


def _reference_index(n: int, offsets: NDArray[np.intp]) -> NDArray[np.intp]:
    """Indices (N, n) of the reference cells of every cell, mirrored back inside [0, n)."""
    index = np.arange(n)[np.newaxis, :] + offsets[:, np.newaxis]
    period = 2 * (n - 1) if n > 1 else 1
    index = np.abs(index) % period
    return np.where(index > n - 1, period - index, index)


def _dilate(mask: NDArray[np.bool_], half_width: int) -> NDArray[np.bool_]:
    """Boolean mask widened by ``half_width`` cells on each side (along the last axis)."""
    if half_width <= 0:
        return mask
    c = np.cumsum(np.pad(mask.astype(np.int32), ((0, 0), (half_width + 1, half_width))), axis=-1)
    return (c[:, 2 * half_width + 1:] - c[:, : -2 * half_width - 1]) > 0


def cfar_threshold(
    power: NDArray[np.float64],
    offsets: NDArray[np.intp],
    kind: str,
    pfa: float,
    order: int | None = None,
    censor_cells: int = 0,
    floor_power: float = 0.0,
) -> NDArray[np.float64]:
    """CFAR threshold for every cell of each row.

    Parameters
    ----------
    power : ndarray, shape (n_rows, n_cells)
        Square-law envelope.
    offsets : ndarray of int, shape (N,)
        Reference cell offsets; cells falling outside the row are mirrored back inside.
    kind : {"ca", "os"}
    pfa : float
        Design false-alarm probability per cell.
    order : int, optional
        OS rank k (1-based); default round(3 N / 4).
    censor_cells : int
        CA only: if > 0, a second pass excludes from every reference set the cells within
        ``censor_cells`` of a first-pass detection (a strong echo would otherwise raise the
        mean and mask a weaker neighbour), with alpha recomputed for the N' cells left.
    floor_power : float
        Least mean noise power of a cell (the ADC's quantisation noise through the filter):
        the CA reference mean is floored at it, the OS k-th reference at its expected value
        for that noise (floor_power sum_{i<k} 1 / (N - i), the mean k-th order statistic of N
        unit exponentials); the thresholds are then at least their factor times that floor.

    Returns
    -------
    ndarray, shape (n_rows, n_cells)
    """
    n_rows, n = power.shape
    n_ref = offsets.size
    index = _reference_index(n, offsets)
    reference = power[:, index]  # (n_rows, N, n_cells)
    floor_power = float(floor_power)
    if kind == "ca":
        threshold = ca_alpha(n_ref, pfa) * np.maximum(reference.mean(axis=1), floor_power)
        if censor_cells > 0:
            censored = _dilate(power > threshold, censor_cells)
            if censored.any():
                keep = ~censored[:, index]  # (n_rows, N, n_cells)
                count = keep.sum(axis=1)
                total = np.where(keep, reference, 0.0).sum(axis=1)
                counts = np.arange(n_ref + 1)
                alpha = np.concatenate([[np.inf], counts[1:] * (pfa ** (-1.0 / np.maximum(counts[1:], 1)) - 1.0)])
                second = alpha[count] * np.maximum(total / np.maximum(count, 1), floor_power)
                threshold = np.where(count >= 2, second, threshold)
        return threshold
    k = int(round(0.75 * n_ref)) if order is None else int(order)
    if not 1 <= k <= n_ref:
        raise RecordingError(f"os-cfar: order must be in [1, {n_ref}], got {k}")
    kth = np.partition(reference, k - 1, axis=1)[:, k - 1, :]
    kth_floor = floor_power * float(np.sum(1.0 / (n_ref - np.arange(k))))
    return os_alpha(n_ref, k, pfa) * np.maximum(kth, kth_floor)


def cfar_layout(plan: MatchedPlan, guard_s: float, n_reference: int) -> tuple[NDArray[np.intp], int]:
    """Reference offsets (decimated cells) and the spacing between reference cells (cells).

    The spacing is the correlation time tau_c of |z|^2 in cells (at least 1): the reference
    cells are then effectively independent, so N is also the effective number of cells.
    """
    record_s = plan.n_samples / plan.sample_rate_hz
    if not (math.isfinite(guard_s) and 0 <= guard_s <= record_s):
        raise RecordingError(f"guard_s must be >= 0 and at most the record's length ({record_s:g} s), got {guard_s!r}")
    if not (isinstance(n_reference, (int, np.integer)) and n_reference >= 2 and n_reference % 2 == 0):
        raise RecordingError(f"n_reference must be an even integer >= 2, got {n_reference!r}")
    cell_s = plan.decimation / plan.sample_rate_hz
    step = max(1, int(round(plan.correlation_time_s / cell_s)))
    guard = int(math.ceil(guard_s / cell_s))
    return reference_offsets(guard, step, n_reference // 2), step


def detect_cfar(
    rows: NDArray[np.float64],
    plan: MatchedPlan,
    *,
    t0_s: float,
    kind: str = "ca",
    pfa: float = 1e-6,
    guard_s: float = 3e-6,
    n_reference: int = 24,
    order: int | None = None,
    min_separation_s: float | None = None,
    sidelobe_margin_db: float = 6.0,
    max_echoes: int = 64,
    censor: bool = True,
    search_window_s: tuple[float, float] | None = None,
    noise_floor_v: float = 0.0,
) -> list[list[tuple[float, float, float, float, float]]]:
    """All echoes above the CFAR threshold in each row.

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
    plan : MatchedPlan
    t0_s : float
    kind : {"ca", "os"}
    pfa : float
        Design false-alarm probability per (independent) cell.
    guard_s : float
        Guard interval on each side of the cell under test (s).
    n_reference : int
        Number of reference cells (even; half on each side), spaced by the correlation time.
    order : int, optional
        OS-CFAR rank (default round(3 N / 4)).
    min_separation_s : float, optional
        Minimum time between two reported echoes (default: the main lobe's FWHM).
    sidelobe_margin_db : float
        Margin over the predicted side-lobe level below which a weaker peak is dropped.
    max_echoes : int
        At most this many echoes per row (the strongest).
    censor : bool
        CA-CFAR: censor first-pass detections (+/- one main-lobe FWHM) from the reference
        cells in a second pass, so a strong echo does not mask a weaker one nearby.
    search_window_s : (start_s, stop_s), optional
        Only report TOFs in this window (s after the trigger).
    noise_floor_v : float
        Least input noise standard deviation (V), the ADC's quantisation noise: floors the
        reference levels and the noise estimate (see ``cfar_threshold``).

    Returns
    -------
    list (n_rows) of list of (tof_s, amplitude, snr_db, score, tof_std_s), sorted by TOF
    """
    pfa = check_pfa(pfa)
    if kind not in ("ca", "os"):
        raise RecordingError(f"cfar kind must be 'ca' or 'os', got {kind!r}")
    offsets, _ = cfar_layout(plan, guard_s, n_reference)
    separation = plan.mainlobe_fwhm_s if min_separation_s is None else float(min_separation_s)
    if not (math.isfinite(separation) and separation >= 0):
        raise RecordingError(f"min_separation_s must be >= 0, got {min_separation_s!r}")
    spectrum = filtered_spectrum(plan, rows)
    z = envelope(plan, spectrum)
    power = z.real ** 2 + z.imag ** 2
    cell_s = plan.decimation / plan.sample_rate_hz
    censor = int(math.ceil(plan.mainlobe_fwhm_s / cell_s)) if censor else 0
    floor_power = float(white_noise_power(plan, noise_floor_v))
    threshold = cfar_threshold(power, offsets, kind, pfa, order, censor, floor_power)
    noise = noise_mean_power(power, floor_power)
    inside = cell_mask(plan, power.shape[1], lag_range(plan, t0_s, search_window_s))
    sidelobes = plan.sidelobes()
    margin = 10.0 ** (sidelobe_margin_db / 10.0)
    peak_rows: list[NDArray[np.intp]] = []
    peak_cells: list[NDArray[np.intp]] = []
    peak_thresholds: list[NDArray[np.float64]] = []
    for r in range(rows.shape[0]):  # per channel: peak picking on its few candidates
        candidates = local_maxima(power[r], (power[r] > threshold[r]) & inside)
        if candidates.size == 0:
            continue
        kept = candidates[select_peaks(candidates * cell_s, power[r, candidates], separation, sidelobes, margin)]
        if kept.size > max_echoes:
            kept = np.sort(kept[np.argsort(power[r, kept])[::-1][:max_echoes]])
        peak_rows.append(np.full(kept.size, r, dtype=np.intp))
        peak_cells.append(kept)
        peak_thresholds.append(threshold[r, kept])
    out: list[list[tuple[float, float, float, float, float]]] = [[] for _ in range(rows.shape[0])]
    if not peak_rows:
        return out
    row_index = np.concatenate(peak_rows)
    cells = np.concatenate(peak_cells)
    cell_threshold = np.concatenate(peak_thresholds)
    lag, peak = refine_peaks(plan, rows, spectrum, row_index, cells * plan.decimation)
    tof, amplitude, snr_db, _, tof_std = echo_values(plan, lag, peak, noise[row_index], 1.0, t0_s)
    score = peak / cell_threshold
    for k, r in enumerate(row_index):
        out[r].append((float(tof[k]), float(amplitude[k]), float(snr_db[k]), float(score[k]), float(tof_std[k])))
    for echoes in out:
        echoes.sort(key=lambda e: e[0])
    return out
