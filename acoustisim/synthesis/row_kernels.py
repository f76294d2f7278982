"""Compiled per-row loops of the path synthesis (numba, cached on disk).

:class:`acoustisim.synthesis.synthesiser.PathSynthesiser` turns each path row into a short
kernel (its echo sampled at fs / q at its exact fractional delay). The loops over rows that
numpy can only express through several temporary (rows x bins) arrays are compiled here:

1. :func:`row_parameters`: per row, its kernel plan, first sample, table indices
   (directivity of each transducer, absorption, fractional delay) and complex weight, in one
   pass over the (strided) path columns that also validates them;
2. :func:`group_rows`: rows of one plan that start on the same sample of the same channel form
   a group (60,922 thesis-tank rows made 11,553 groups);
3. :func:`fill_group_spectra`: each group's kernel spectrum on the plan's bins, the exact sum
   of its rows' spectra ``w P[u, k] D[i_tx, k] D[i_rx, k] A[i_len, k]`` (the inverse FFT is
   linear, so summing before it changes nothing but float32 rounding); one batched
   ``scipy.fft.irfft`` then gives the groups' kernels;
4. :func:`overlap_add`: each group's kernel added into the decimated record at its first
   sample, samples outside ``[0, keep)`` dropped.

The loops run sequentially in row order, so the output is deterministic (byte-identical for
the same rows). ``cache=True`` stores the compiled code in ``__pycache__`` beside this file (or,
when that is read-only, in numba's per-user cache directory; ``NUMBA_CACHE_DIR`` overrides):
the first render in a fresh checkout compiles these and :mod:`ping_loops` (seconds), later
processes load the cache (``benchmarks/bench_synthesis.py`` prints both times).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

ROWS_OK = -1
"""``row_parameters``'s status when every row is valid; otherwise the first bad row's index."""


@njit(cache=True, nogil=True)
def row_parameters(
    delay_s: NDArray[np.float64],
    path_length_m: NDArray[np.float64],
    geometric_gain: NDArray[np.float64],
    phase_rad: NDArray[np.float64],
    angle_tx_rad: NDArray[np.float64],
    angle_rx_rad: NDArray[np.float64],
    channel: NDArray[np.integer],
    fs_dec: float,
    sine_steps: int,
    length_step_m: float,
    delay_steps: int,
    max_spreads: NDArray[np.float64],
    centres: NDArray[np.int64],
    lengths: NDArray[np.int64],
    keep: int,
) -> tuple[
    int, NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64],
    NDArray[np.int64], NDArray[np.complex64],
]:
    """Kernel plan, first sample and table indices of every row.

    Parameters
    ----------
    delay_s, path_length_m, geometric_gain, phase_rad, angle_tx_rad, angle_rx_rad : (n,) float
        The rows' columns (any strides).
    channel : (n,) int
    fs_dec : float
        Sample rate of the decimated grid (Hz).
    sine_steps : int
        Directivity-table entries per unit of |sin(angle)|.
    length_step_m : float
        Absorption-table step (m).
    delay_steps : int
        Phase-table entries per sample of fractional delay.
    max_spreads, centres, lengths : (n_plans,)
        Each plan's largest |sin tx| + |sin rx|, reference-instant index and kernel length,
        shortest plan first.
    keep : int
        Samples (at fs / q) of the record that are kept.

    Returns
    -------
    status : int
        ``ROWS_OK``, or the index of the first row holding a non-finite value, a channel other
        than 0, 1, 2 or a negative path length (the other outputs are then meaningless).
    plan : (n,) int64
        Plan of each row; -1 for a row none of whose kernel falls inside the record, -2 for a
        row arriving after the record's end.
    first : (n,) int64
        Record index (at fs / q, within the row's channel) of the kernel's first sample.
    i_tx, i_rx, i_len, i_frac : (n,) int64
        rint(|sin| sine_steps) of each angle, rint(L / length_step_m), rint(frac delay_steps).
    weight : (n,) complex64
        g exp(j phi), 0 for a row arriving from behind either piston's face.
    """
    n = delay_s.size
    n_plans = max_spreads.size
    plan = np.empty(n, dtype=np.int64)
    first = np.empty(n, dtype=np.int64)
    i_tx = np.empty(n, dtype=np.int64)
    i_rx = np.empty(n, dtype=np.int64)
    i_len = np.empty(n, dtype=np.int64)
    i_frac = np.empty(n, dtype=np.int64)
    weight = np.empty(n, dtype=np.complex64)
    last_centre = centres[n_plans - 1]
    half_pi = 0.5 * math.pi
    for r in range(n):
        total = delay_s[r] + path_length_m[r] + geometric_gain[r] + phase_rad[r] + angle_tx_rad[r] + angle_rx_rad[r]
        if not math.isfinite(total) or channel[r] < 0 or channel[r] > 2 or path_length_m[r] < 0:
            return r, plan, first, i_tx, i_rx, i_len, i_frac, weight
        position = delay_s[r] * fs_dec
        whole = math.floor(position)
        frac = position - whole
        s_tx = abs(math.sin(angle_tx_rad[r]))
        s_rx = abs(math.sin(angle_rx_rad[r]))
        spread = s_tx + s_rx
        p = 0  # searchsorted(max_spreads, spread, "left"), held at the last plan
        while p < n_plans - 1 and max_spreads[p] < spread:
            p += 1
        start = int(whole) - centres[p]
        if whole - last_centre >= keep:
            plan[r] = -2
        elif start + lengths[p] <= 0:
            plan[r] = -1
        else:
            plan[r] = p
        first[r] = start
        i_tx[r] = int(np.rint(s_tx * sine_steps))
        i_rx[r] = int(np.rint(s_rx * sine_steps))
        i_len[r] = int(np.rint(path_length_m[r] * (1.0 / length_step_m)))
        i_frac[r] = int(np.rint(frac * delay_steps))
        # A baffled piston radiates (and receives) only in front of its face.
        front = abs(angle_tx_rad[r]) <= half_pi and abs(angle_rx_rad[r]) <= half_pi
        g = geometric_gain[r] if front else 0.0
        weight[r] = complex(g * math.cos(phase_rad[r]), g * math.sin(phase_rad[r]))
    return ROWS_OK, plan, first, i_tx, i_rx, i_len, i_frac, weight


@njit(cache=True, nogil=True)
def group_rows(
    plan: NDArray[np.int64],
    first: NDArray[np.int64],
    channel: NDArray[np.integer],
    plan_number: int,
    lowest_first: int,
    span: int,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Group the rows of plan ``plan_number`` by (channel, first sample).

    Parameters
    ----------
    plan, first, channel : (n,)
        From :func:`row_parameters`.
    plan_number : int
    lowest_first : int
        A lower bound of ``first`` over the plan's rows.
    span : int
        More than ``first - lowest_first`` for every row of the plan.

    Returns
    -------
    members : (n_rows,) int64
        The plan's rows, group after group, in row order within a group.
    bounds : (n_groups + 1,) int64
        Group g holds ``members[bounds[g]:bounds[g + 1]]``; groups are numbered in the order
        of their first row.
    group_first, group_channel : (n_groups,) int64
    """
    n = plan.size
    slot_group = np.full(3 * span, -1, dtype=np.int64)
    group = np.empty(n, dtype=np.int64)
    counts = np.zeros(n + 1, dtype=np.int64)
    n_groups = 0
    n_rows = 0
    for r in range(n):
        if plan[r] != plan_number:
            continue
        slot = channel[r] * span + (first[r] - lowest_first)
        g = slot_group[slot]
        if g < 0:
            g = n_groups
            slot_group[slot] = g
            n_groups += 1
        group[r] = g
        counts[g + 1] += 1
        n_rows += 1
    bounds = np.cumsum(counts[: n_groups + 1])
    fill = bounds[:n_groups].copy()
    members = np.empty(n_rows, dtype=np.int64)
    group_first = np.empty(n_groups, dtype=np.int64)
    group_channel = np.empty(n_groups, dtype=np.int64)
    for r in range(n):
        if plan[r] != plan_number:
            continue
        g = group[r]
        if fill[g] == bounds[g]:
            group_first[g] = first[r]
            group_channel[g] = channel[r]
        members[fill[g]] = r
        fill[g] += 1
    return members, bounds, group_first, group_channel


@njit(cache=True, nogil=True)
def fill_group_spectra(
    members: NDArray[np.int64],
    bounds: NDArray[np.int64],
    first_group: int,
    i_tx: NDArray[np.int64],
    i_rx: NDArray[np.int64],
    i_len: NDArray[np.int64],
    i_frac: NDArray[np.int64],
    weight: NDArray[np.complex64],
    phase_coarse: NDArray[np.float32],
    phase_fine: NDArray[np.float32],
    directivity_table: NDArray[np.float32],
    absorption_table: NDArray[np.float32],
    spectra: NDArray[np.complex64],
) -> None:
    """Kernel spectra of groups ``first_group ...`` into ``spectra`` (n, Lk/2 + 1), in place.

    ``spectra[g - first_group, k]`` is the sum over the group's rows of
    ``w P[u, k] D[i_tx, k] D[i_rx, k] A[i_len, k]`` on the plan's ``n_bins`` bins (the tables'
    last axis), 0 on the bins above, with the phase ramp ``P[u] = coarse[u // F] fine[u % F]``
    (F = ``phase_fine.shape[1]``) and the absorption held beyond its last entry.
    """
    n_bins = phase_coarse.shape[2]
    n_fine = phase_fine.shape[1]
    last_length = absorption_table.shape[0] - 1
    acc_re = np.empty(n_bins, dtype=np.float32)
    acc_im = np.empty(n_bins, dtype=np.float32)
    spectra[:] = 0.0
    for j in range(spectra.shape[0]):
        g = first_group + j
        acc_re[:] = 0.0
        acc_im[:] = 0.0
        for m in range(bounds[g], bounds[g + 1]):
            # Plain indices, no row views (a view per table and row costs more than its bins).
            r = members[m]
            w_re = weight[r].real
            w_im = weight[r].imag
            c = i_frac[r] // n_fine
            f = i_frac[r] % n_fine
            t = i_tx[r]
            x = i_rx[r]
            a = min(i_len[r], last_length)
            for k in range(n_bins):
                real = directivity_table[t, k] * directivity_table[x, k] * absorption_table[a, k]
                ramp_re = phase_coarse[0, c, k] * phase_fine[0, f, k] - phase_coarse[1, c, k] * phase_fine[1, f, k]
                ramp_im = phase_coarse[0, c, k] * phase_fine[1, f, k] + phase_coarse[1, c, k] * phase_fine[0, f, k]
                acc_re[k] += (ramp_re * w_re - ramp_im * w_im) * real
                acc_im[k] += (ramp_re * w_im + ramp_im * w_re) * real
        out = spectra[j]
        for k in range(n_bins):
            out[k] = complex(acc_re[k], acc_im[k])


@njit(cache=True, nogil=True)
def overlap_add(
    kernels: NDArray[np.float32],
    group_first: NDArray[np.int64],
    group_channel: NDArray[np.int64],
    keep: int,
    record: NDArray[np.float64],
) -> None:
    """Add ``kernels[j]`` (Lk samples) into ``record[group_channel[j], group_first[j]:][:Lk]``,
    dropping samples outside ``[0, keep)``.

    Parameters
    ----------
    kernels : (n, Lk) float32
    group_first, group_channel : (n,) int64
    record : (3, M / q) float64, accumulated in place
    """
    length = kernels.shape[1]
    for j in range(kernels.shape[0]):
        start = group_first[j]
        lo = max(0, -start)
        hi = min(length, keep - start)
        target = record[group_channel[j]]
        kernel = kernels[j]
        for i in range(lo, hi):
            target[start + i] += kernel[i]
