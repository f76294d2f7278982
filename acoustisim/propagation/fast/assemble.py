"""The fast engine's assembly: :func:`acoustisim.propagation.reference.columns.assemble_rows`'s rows
(derived columns, sorted by channel then delay then the parts' order, amplitude floor), with as
few fresh buffers as it can.

A deterministic pose has some 16 000 rows of 243 bytes, a default solve with diffuse rays
60 000: each fresh buffer of that size costs its copy and a page fault per page, so the steps
work in place where they can:

1. :func:`~acoustisim.propagation.fast.columns.complete_columns` fills the derived columns of
   each part in place (row by row: the same values as on the joined array); the sorted host of
   step 2 gets them as its rows move;
2. the rows are ordered by channel, then delay, then their place in the mechanisms' order (the
   order a stable sort of the joined parts gives). Up to :data:`IN_PLACE_MAX_BYTES` of rows
   (a deterministic pose), the largest part's buffer is grown (realloc) and the rows put in
   order there: when that part is sorted already (the edge rows, which
   :func:`~acoustisim.propagation.fast.edges.edge_rows` writes in this order for the solver), the
   other rows are sorted and merged in (:func:`merge_destinations`), its own rows moved once,
   backwards, to make room, their derived columns filled as they move
   (:func:`~acoustisim.propagation.fast.columns.fill_columns`; the host's sort keys are read
   with its directions, :func:`~acoustisim.propagation.fast.columns.column_inputs`: its
   ``path_length_m / c``, the very bits of its ``delay_s``); otherwise the rows are permuted
   (:func:`permute_records`). Beyond, each part's records are copied straight to their sorted
   places in one new buffer (:func:`scatter_records`);
3. the amplitude floor (:func:`~acoustisim.propagation.fast.floor.floor_mask`) judges the
   sorted rows; the kept ones are moved to the front in place (:func:`compact_records`) and
   the buffer is shrunk (``ndarray.resize``: realloc, no copy of the kept rows).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.fast.bundles import plain_tuple_arguments

from acoustisim.propagation.fast.columns import ColumnInputs, column_inputs, complete_columns, fill_columns
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast.floor import floor_mask
from acoustisim.propagation.paths import PATH_DTYPE, empty_paths_array


IN_PLACE_MAX_BYTES = 8 << 20
"""Rows up to this size (bytes; 34 000 rows) are sorted in place (:func:`permute_records`), larger
sets are scattered into a new buffer (:func:`scatter_records`): the in-place permutation reads
and writes at random, which stays fast only while the rows fit in the last-level cache
(``benchmarks/bench_propagation.py`` times both)."""


class SortKeys(NamedTuple):
    """The keys rows are sorted by: ``channel`` (int8) and ``delay_s`` (float64), shape (n,)."""

    channel: NDArray[np.int8]
    delay_s: NDArray[np.float64]


@njit(cache=True, nogil=True)
def scatter_records(source: NDArray[np.uint8], destination: NDArray[np.int64], out: NDArray[np.uint8]) -> None:
    """``out[destination[i]] = source[i]`` for every record i (rows of raw bytes).

    Parameters
    ----------
    source : ndarray of uint8, shape (n, itemsize)
    destination : ndarray of int64, shape (n,)
    out : ndarray of uint8, shape (m, itemsize)
    """
    width = source.shape[1]
    for i in range(source.shape[0]):
        d = destination[i]
        for b in range(width):
            out[d, b] = source[i, b]


@njit(cache=True, nogil=True)
def compact_records(records: NDArray[np.uint8], kept: NDArray[np.int64]) -> None:
    """Move records ``kept`` (increasing) to the front of ``records``, in order, in place.

    Parameters
    ----------
    records : ndarray of uint8, shape (n, itemsize)
    kept : ndarray of int64, shape (k,)
        Strictly increasing, so ``kept[r] >= r``: each record is read before it is overwritten.
    """
    width = records.shape[1]
    for r in range(kept.size):
        i = kept[r]
        if i != r:
            for b in range(width):
                records[r, b] = records[i, b]


@njit(cache=True, nogil=True)
def permute_records(records: NDArray[np.uint8], destination: NDArray[np.int64]) -> None:
    """Move record i to ``destination[i]`` for every i, in place (a permutation; one cycle at a
    time, each record copied through a one-record buffer).

    Parameters
    ----------
    records : ndarray of uint8, shape (n, itemsize)
    destination : ndarray of int64, shape (n,)
        A permutation of 0 .. n-1.
    """
    n, width = records.shape
    done = np.zeros(n, dtype=np.bool_)
    held = np.empty(width, dtype=np.uint8)
    spare = np.empty(width, dtype=np.uint8)
    for start in range(n):
        if done[start]:
            continue
        done[start] = True
        target = destination[start]
        if target == start:
            continue
        for b in range(width):
            held[b] = records[start, b]
        while True:
            done[target] = True
            if target == start:
                for b in range(width):
                    records[start, b] = held[b]
                break
            for b in range(width):
                spare[b] = records[target, b]
                records[target, b] = held[b]
            held, spare = spare, held
            target = destination[target]


def _bytes(rows: NDArray[Any]) -> NDArray[np.uint8]:
    """A C-contiguous PATH_DTYPE array's records as rows of raw bytes (a view)."""
    return rows.view(np.uint8).reshape(rows.size, PATH_DTYPE.itemsize)


@plain_tuple_arguments
@njit(cache=True, nogil=True)
def merge_destinations(host_fields: tuple, host_first: int, others_fields: tuple, canonical: NDArray[np.int64],
                       order: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Sorted places of the rows of a sorted part and of the other rows, by merging.

    The order is by channel, then delay, then canonical index (the row's place in the joined
    parts), as a stable sort of the joined parts by (channel, delay) gives.

    Parameters
    ----------
    host : SortKeys, shape (h,)
        The sorted part's keys, non-decreasing; its canonical indices are
        ``host_first .. host_first + h - 1``.
    others : SortKeys, shape (o,)
        The other rows' keys; ``canonical`` (o,) their canonical indices.
    order : ndarray of int64, shape (o,)
        The other rows in sorted order (a stable sort of them by (channel, delay), their
        canonical indices increasing along their arrays).

    Returns
    -------
    host_destination : ndarray of int64, shape (h,)
        Increasing, ``host_destination[i] >= i``.
    destination : ndarray of int64, shape (o,)
    """
    host, others = SortKeys(*host_fields), SortKeys(*others_fields)
    host_channel, host_delay = host.channel, host.delay_s
    channel, delay = others.channel, others.delay_s
    h = host_channel.size
    o = order.size
    host_destination = np.empty(h, dtype=np.int64)
    destination = np.empty(o, dtype=np.int64)
    i = 0
    j = 0
    for place in range(h + o):
        take_host = j >= o
        if not take_host and i < h:
            k = order[j]
            if host_channel[i] != channel[k]:
                take_host = host_channel[i] < channel[k]
            elif host_delay[i] != delay[k]:
                take_host = host_delay[i] < delay[k]
            else:
                take_host = host_first + i < canonical[k]
        if take_host:
            host_destination[i] = place
            i += 1
        else:
            destination[order[j]] = place
            j += 1
    return host_destination, destination


@njit(cache=True, nogil=True)
def is_sorted(channel: NDArray[np.int8], delay: NDArray[np.float64]) -> bool:
    """Whether rows with these keys are sorted by channel, then delay (non-decreasing; a NaN
    delay after an equal channel is out of order, as a comparison with it is false).

    Parameters
    ----------
    channel : ndarray of int8, shape (n,)
    delay : ndarray of float64, shape (n,)
        Strided views (the fields of the rows) are read in place.
    """
    for i in range(1, channel.size):
        if channel[i] > channel[i - 1]:
            continue
        if channel[i] < channel[i - 1] or not delay[i] >= delay[i - 1]:
            return False
    return True


def _can_take_over(rows: NDArray[Any]) -> bool:
    """Whether a part's buffer can become the result (owned, not a view, writeable, contiguous)."""
    return bool(rows.flags.owndata and rows.base is None and rows.flags.writeable and rows.flags.c_contiguous)


def _merged_in_place(rows: NDArray[Any], parts: list[NDArray[Any]], host: int, delay: NDArray[np.float64],
                     channel: NDArray[np.int8], inputs: ColumnInputs) -> NDArray[Any]:
    """The rows sorted in ``rows``, the buffer of part ``host`` grown to hold them all (its own
    rows first), that part sorted itself: the other rows (their derived columns filled) are sorted and
    merged in; the host's rows, whose derived columns are not filled yet, are spread out to
    make room for them, each moved once, backwards, and its columns filled as it moves
    (:func:`~acoustisim.propagation.fast.columns.fill_columns` with ``inputs``, the host's
    :func:`~acoustisim.propagation.fast.columns.column_inputs`). ``delay`` and ``channel``: every
    part's keys, in the parts' order (the host's from ``inputs``: the bits of its ``delay_s``
    to be)."""
    offsets = np.cumsum([0] + [part.size for part in parts])
    lo, hi = int(offsets[host]), int(offsets[host + 1])
    canonical = np.r_[np.arange(lo), np.arange(hi, int(offsets[-1]))].astype(np.int64)
    other_channel = np.concatenate([channel[:lo], channel[hi:]])
    other_delay = np.concatenate([delay[:lo], delay[hi:]])
    order = np.lexsort((other_delay, other_channel)).astype(np.int64)
    host_destination, destination = merge_destinations(SortKeys(channel[lo:hi], delay[lo:hi]), lo,
                                                       SortKeys(other_channel, other_delay), canonical, order)
    fill_columns(rows, inputs, host_destination)
    records = _bytes(rows)
    at = 0
    for i, part in enumerate(parts):
        if i != host:
            scatter_records(_bytes(part), destination[at:at + part.size], records)
            at += part.size
    return rows


def _sorted_in_place(parts: list[NDArray[Any]], destination: NDArray[np.int64],
                     grown: NDArray[Any] | None = None) -> NDArray[Any] | None:
    """The rows sorted in the largest part's own buffer, grown in place (``ndarray.resize``:
    realloc, which keeps the pages of a large buffer; ``grown``: that buffer grown already, the
    part its first rows), or None when that part's buffer cannot be taken over (not owned, a
    view, read-only)."""
    host = max(range(len(parts)), key=lambda i: parts[i].size)
    n_host = parts[host].size
    offsets = np.cumsum([0] + [part.size for part in parts])
    if grown is None:
        rows = parts[host]
        if not _can_take_over(rows):
            return None
        rows.resize(int(offsets[-1]), refcheck=False)  # no view of the host is alive here
    else:
        rows = grown
    records = _bytes(rows)
    # buffer layout: the host's rows, then the other parts' in order; where each belongs
    where = [destination[offsets[host]:offsets[host + 1]]]
    at = n_host
    for i, part in enumerate(parts):
        if i != host:
            records[at:at + part.size] = _bytes(part)
            where.append(destination[offsets[i]:offsets[i + 1]])
            at += part.size
    permute_records(records, np.concatenate(where))
    return rows


def assemble_rows(parts: Sequence[NDArray[Any]], context: SolveContext, floor_db: float | None,
                  band_hz: tuple[float, float] | None = None) -> NDArray[Any]:
    """The solve's rows from the mechanisms' parts: derived columns, sorted, floored.

    Parameters
    ----------
    parts : sequence of structured ndarray of PATH_DTYPE
        The mechanisms' rows, in the mechanisms' order. Taken over: their derived columns are
        filled in place, and the largest one's buffer becomes the result (resized; do not use
        the parts afterwards).
    context : SolveContext
    floor_db : float or None
        ``SolverConfig.amplitude_floor_db``.
    band_hz : (float, float) or None
        ``SolverConfig.amplitude_floor_band_hz``.

    Returns
    -------
    structured ndarray of PATH_DTYPE, shape (k,)
        A new, C-contiguous array owning its data (for :meth:`Paths.adopt`): every part's rows
        that pass the floor, sorted by channel, then delay, then their order in ``parts``
        (the rows of ``np.concatenate(parts)`` sorted stably by channel and delay).
    """
    parts = [np.ascontiguousarray(part, dtype=PATH_DTYPE) for part in parts]
    parts = [part if part.flags.writeable else part.copy() for part in parts if part.size]
    if not parts:
        return empty_paths_array(0)
    total = sum(part.size for part in parts)
    rows = None
    host = max(range(len(parts)), key=lambda i: parts[i].size)
    grown = None
    if total * PATH_DTYPE.itemsize <= IN_PLACE_MAX_BYTES and _can_take_over(parts[host]):
        # the host's buffer grown to the result's size first, before anything else is
        # allocated: realloc then extends it where it is (with a new allocation behind it, it
        # would copy the rows to a fresh buffer, page faults included); its rows are its start
        grown = parts[host]
        n_host = grown.size
        grown.resize(total, refcheck=False)  # no view of the host is alive here
        parts[host] = grown[:n_host]
        # the host's sort keys read with what its columns derive from (one pass over its rows)
        inputs = column_inputs(parts[host], context)
        for i, part in enumerate(parts):
            if i != host:
                complete_columns(part, context)
        if not is_sorted(inputs.channel, inputs.delay_s):
            fill_columns(parts[host], inputs)
        elif len(parts) == 1:  # sorted already: nothing moves
            fill_columns(grown, inputs)
            rows = grown
        else:
            delay = np.concatenate([inputs.delay_s if i == host else part["delay_s"] for i, part in enumerate(parts)])
            channel = np.concatenate([inputs.channel if i == host else part["channel"]
                                      for i, part in enumerate(parts)])
            rows = _merged_in_place(grown, parts, host, delay, channel, inputs)
    else:
        for part in parts:
            complete_columns(part, context)
    if rows is None:
        delay = np.concatenate([part["delay_s"] for part in parts])
        channel = np.concatenate([part["channel"] for part in parts])
        order = np.lexsort((delay, channel))  # stable: ties keep the parts' order
        destination = np.empty(total, dtype=np.int64)
        destination[order] = np.arange(total)
        if grown is not None:
            rows = _sorted_in_place(parts, destination, grown)
        elif total * PATH_DTYPE.itemsize <= IN_PLACE_MAX_BYTES:
            rows = _sorted_in_place(parts, destination)
    if rows is None:
        rows = np.empty(total, dtype=PATH_DTYPE)
        out = _bytes(rows)
        start = 0
        for part in parts:
            scatter_records(_bytes(part), destination[start:start + part.size], out)
            start += part.size
        del out
    parts.clear()  # the host's view of its rows in ``grown`` among them: none may outlive a resize
    keep = floor_mask(rows, floor_db, context, band_hz)
    if not keep.all():
        kept = np.flatnonzero(keep).astype(np.int64)
        compact_records(_bytes(rows), kept)
        # shrink in place (realloc): no view of ``rows`` is alive here
        rows.resize(kept.size, refcheck=False)
    return rows


__all__ = ("IN_PLACE_MAX_BYTES", "SortKeys", "assemble_rows", "compact_records", "is_sorted", "merge_destinations",
           "permute_records", "scatter_records")
