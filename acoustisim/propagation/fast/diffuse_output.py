"""Where the fast diffuse tracer's chunks write: the solve's output arrays and scratch blocks.

The output arrays are sized for the most events and receptions the rays can make (one event
per ray and bounce, one reception per event and receiver) and carved out of one allocation,
each starting on a 4 KiB page: one mapping large enough for the kernel's transparent huge
pages, and pages that no chunk reaches are never touched and cost no memory.

Chunk c writes its events bounce after bounce, and its receptions likewise: straight into the
output at their final place when every earlier chunk was placed before it started (always so on
one thread: no copy at all), else into a scratch block of one chunk's size, taken from a pool
(a block is reused once its chunk is placed, so its pages are warm and the output's pages are
written once). A finished chunk is placed once every earlier one is: a chunk written in a
scratch block is then copied to its final place
(:func:`~acoustisim.propagation.fast.diffuse_kernels.copy_chunk`), its event indices shifted.
The final places depend on the chunks' counts only, so the arrays are the same for any thread
count.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from acoustisim.propagation.fast.diffuse_kernels import EventArrays, copy_chunk

PAGE_BYTES = 4096
"""Alignment of each array carved out of the output block."""


def event_arrays(events: int, receptions: int, n_rx: int, one_block: bool = False) -> EventArrays:
    """Uninitialised :class:`EventArrays` for ``events`` events and ``receptions`` receptions of
    ``n_rx`` receivers (channel int8 below 128 receivers); ``one_block``: carved out of one
    page-aligned allocation (see the module docstring)."""
    layout = (((events, 3), np.float64), ((events, 3), np.float64), ((events,), np.int32), ((events,), np.int32),
              ((events,), np.int32), ((events,), np.float64), ((events,), np.float64), ((receptions,), np.int32),
              ((receptions,), np.int8 if n_rx < 128 else np.int32), ((receptions,), np.float64))
    if not one_block:
        return EventArrays(*(np.empty(shape, dtype=dtype) for shape, dtype in layout))
    sizes = [-(-math.prod(shape) * np.dtype(dtype).itemsize // PAGE_BYTES) * PAGE_BYTES for shape, dtype in layout]
    block = np.empty(sum(sizes) + PAGE_BYTES, dtype=np.uint8)
    start = -block.ctypes.data % PAGE_BYTES  # the first page boundary in the block
    arrays = []
    for (shape, dtype), size in zip(layout, sizes):
        count = math.prod(shape)
        arrays.append(block[start:start + count * np.dtype(dtype).itemsize].view(dtype).reshape(shape))
        start += size
    return EventArrays(*arrays)


class ChunkPlacement:
    """The solve's output arrays and where each chunk writes (see the module docstring).

    Parameters
    ----------
    n_rays, bounces, n_rx : int
        The solve's rays, bounces and receivers.
    chunk_rays : int
        Rays per chunk.
    """

    def __init__(self, n_rays: int, bounces: int, n_rx: int, chunk_rays: int) -> None:
        capacity = n_rays * bounces  # one event per ray and bounce at most
        self.output = event_arrays(capacity, capacity * n_rx, n_rx, one_block=True)
        self.slot_events = min(chunk_rays, n_rays) * bounces  # the most a chunk makes
        self.slot_receptions = self.slot_events * n_rx
        self._n_rx = n_rx
        self._lock = threading.Lock()
        self._placed = 0  # chunks placed (every one before it too)
        self._events = 0  # their events and receptions
        self._receptions = 0
        self._finished: dict[int, tuple[EventArrays, int, int]] = {}  # finished, not yet placed
        self._pool: list[EventArrays] = []  # scratch blocks free for a chunk

    def start(self, chunk: int) -> tuple[EventArrays, int, int]:
        """Where chunk ``chunk`` writes: the arrays and the rows of its first event and
        reception (the output at the chunk's final place, or a scratch block from row 0)."""
        with self._lock:
            if chunk == self._placed:
                return self.output, self._events, self._receptions
            block = self._pool.pop() if self._pool else None
        if block is None:
            block = event_arrays(self.slot_events, self.slot_receptions, self._n_rx)
        return block, 0, 0

    def finish(self, chunk: int, target: EventArrays, events: int, receptions: int) -> None:
        """Record that chunk ``chunk`` wrote ``events`` and ``receptions`` into ``target`` (from
        the rows :meth:`start` gave); place every finished chunk whose predecessors are placed."""
        copies = []  # (block, events, receptions, first event, first reception)
        with self._lock:
            self._finished[chunk] = (target, events, receptions)
            while self._placed in self._finished:
                block, n_events, n_receptions = self._finished.pop(self._placed)
                if block is not self.output:
                    copies.append((block, n_events, n_receptions, self._events, self._receptions))
                self._events += n_events
                self._receptions += n_receptions
                self._placed += 1
        # outside the lock (the other threads start and finish chunks meanwhile): each copy goes
        # to rows no other chunk writes, and its block returns to the pool once copied
        for block, n_events, n_receptions, first_event, first_reception in copies:
            copy_chunk(n_events, n_receptions, block, first_event, first_reception, self.output)
            with self._lock:
                self._pool.append(block)

    def placed(self) -> EventArrays:
        """The events and receptions of every chunk (all placed): leading views of the output
        arrays (no copy; the block's pages beyond them were never touched).

        Raises
        ------
        RuntimeError
            If a finished chunk is still waiting for an earlier one (an internal error).
        """
        if self._finished:
            raise RuntimeError("diffuse tracer: a chunk was left unplaced")
        m, n = self._events, self._receptions
        out = self.output
        return EventArrays(out.point[:m], out.departure[:m], out.surface[:m], out.parent[:m], out.bounce[:m],
                           out.travelled[:m], out.phase[:m], out.event[:n], out.channel[:n], out.gain[:n])


__all__ = ("PAGE_BYTES", "ChunkPlacement", "event_arrays")
