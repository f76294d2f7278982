"""The settings of one experiment run (what the command line gives ``run``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping


@dataclass(frozen=True)
class ExperimentConfig:
    """Settings of one experiment run.

    Attributes
    ----------
    name : str
        The experiment's ``NAME``.
    out_dir : Path
        Folder for results.json, report.md and the figures.
    seed : int
        Master seed; every trial's seed derives from it (``runner.make_trials``).
    trials : int or None
        The experiment's size (its meaning is the experiment's: repetitions per position,
        pings, scenes...); None takes the experiment's default.
    workers : int or None
        Worker processes (None: the usable cores; 1: in this process).
    progress : bool
        Show a progress bar on stderr.
    options : mapping
        The experiment's own options (from its ``add_arguments``), by name.
    """

    name: str
    out_dir: Path
    seed: int = 0
    trials: int | None = None
    workers: int | None = None
    progress: bool = True
    options: Mapping[str, Any] = field(default_factory=dict)

    def option(self, key: str, default: Any = None) -> Any:
        """One of the experiment's own options (``default`` when absent or None)."""
        value = self.options.get(key)
        return default if value is None else value

    def trials_or(self, default: int) -> int:
        """``trials`` or the experiment's default."""
        return int(default if self.trials is None else self.trials)
