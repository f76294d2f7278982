"""Fixed-size chunks of ray work run in a small thread pool, results kept in chunk order.

Embree queries (embreex releases the GIL in ``EmbreeScene.run``) and numpy passes over large
arrays run outside the GIL, so a few Python threads share the cores. The work is split into
chunks whose boundaries depend only on the problem (never on the number of threads), and the
results are returned in chunk order: the output is the same for any thread count.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import TypeVar

from acoustisim.errors import InputError

T = TypeVar("T")
R = TypeVar("R")


def available_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the OS has one), >= 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def resolve_threads(threads: int | None) -> int:
    """The worker count for ``threads``: None -> :func:`available_cores`.

    Raises
    ------
    InputError
        If ``threads`` is not None nor an integer >= 1.
    """
    if threads is None:
        return available_cores()
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise InputError(f"threads = {threads!r}: must be an integer >= 1 or None (all available cores)")
    return threads


def run_in_order(function: Callable[[T], R], tasks: Sequence[T], threads: int) -> list[R]:
    """``[function(task) for task in tasks]``, on up to ``threads`` threads.

    Parameters
    ----------
    function : callable
        Must be thread-safe (no shared mutable state); an exception in any task propagates.
    tasks : sequence
        One item per chunk.
    threads : int
        Worker threads (>= 1); 1, or a single task, runs in the calling thread.

    Returns
    -------
    list
        The results in the order of ``tasks``, whatever order they finished in.
    """
    workers = min(int(threads), len(tasks))
    if workers <= 1:
        return [function(task) for task in tasks]
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="acoustisim-rays") as pool:
        return list(pool.map(function, tasks))


__all__ = ["available_cores", "resolve_threads", "run_in_order"]
