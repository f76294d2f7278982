"""Run independent trials in parallel processes, reproducibly, with a progress bar.

Each trial gets its own seed derived from (experiment seed, trial index), so the results do not
depend on the number of workers or the order in which trials finish.
"""

from __future__ import annotations

import os
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np


@dataclass(frozen=True)
class Trial:
    """One unit of work: its index, its seed and its parameters."""

    index: int
    seed: int
    params: tuple[tuple[str, Any], ...]

    def param(self, key: str) -> Any:
        """One parameter's value."""
        return dict(self.params)[key]


def make_trials(seed: int, params: Sequence[dict[str, Any]]) -> list[Trial]:
    """Trials with independent seeds, ``SeedSequence([seed, i])`` for trial ``i``."""
    trials = []
    for i, p in enumerate(params):
        child = np.random.SeedSequence([int(seed), i]).generate_state(1, dtype=np.uint32)[0]
        trials.append(Trial(i, int(child), tuple(p.items())))
    return trials


def default_workers() -> int:
    """Worker processes: the cores this process may use (at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


def run_trials(
    function: Callable[[Trial], dict[str, Any]],
    trials: Sequence[Trial],
    *,
    workers: int | None = None,
    description: str = "trials",
    progress: bool = True,
) -> list[dict[str, Any]]:
    """Run ``function`` on every trial, in ``workers`` processes (1: in this process).

    Returns the results in trial order. ``function`` must be a module-level callable.
    """
    from tqdm import tqdm

    workers = default_workers() if workers is None else max(1, int(workers))
    results: list[dict[str, Any] | None] = [None] * len(trials)
    bar = tqdm(total=len(trials), desc=description, unit="trial", disable=not progress, file=sys.stderr,
               dynamic_ncols=True)
    try:
        if workers == 1 or len(trials) <= 1:
            for trial in trials:
                results[trial.index] = function(trial)
                bar.update()
        else:
            with ProcessPoolExecutor(max_workers=min(workers, len(trials))) as pool:
                futures = {pool.submit(function, trial): trial.index for trial in trials}
                for future in as_completed(futures):
                    results[futures[future]] = future.result()
                    bar.update()
    finally:
        bar.close()
    return [r for r in results if r is not None]
