"""``range-sweep``: the seed's section 4.2.3, figure 4-13 (range 0.1-2.5 m at a fixed bearing)."""

from __future__ import annotations

from typing import Any

from acoustisim.experiments.config import ExperimentConfig
from acoustisim.experiments.report import ExperimentReport

NAME = "range-sweep"
SUMMARY = "edge target, range 0.1-2.5 m at a fixed bearing, threshold vs matched filter (seed fig. 4-13)"
DEFAULT_REPEATS = 8
DEFAULT_PINGS = 50
THRESHOLD_CALIBRATION_RANGE_M = 0.7
"""Where the threshold detector's level and offset are calibrated (m): the shortest range at which
the side receivers see the edge within 8 deg of their axes (d = 65 mm), well inside the pistons'
500 kHz first null (11 deg), so the echo there has the template's shape."""


def add_arguments(parser: Any) -> None:
    """``--start``, ``--stop``, ``--step`` (m), ``--bearing`` (deg), ``--pings``, ``--detectors``."""
    from acoustisim.experiments.sweep import add_sweep_arguments

    parser.add_argument("--start", type=float, default=0.1, help="first range (m, default 0.1)")
    parser.add_argument("--stop", type=float, default=2.5, help="last range (m, default 2.5)")
    parser.add_argument("--step", type=float, default=0.1, help="range step (m, default 0.1)")
    parser.add_argument("--bearing", type=float, default=2.0, help="fixed bearing (deg, default 2)")
    add_sweep_arguments(parser, pings=DEFAULT_PINGS)


def run(config: ExperimentConfig) -> ExperimentReport:
    """Measure every range; ``config.trials`` is the number of measurements per range (default 2)."""
    from acoustisim.errors import InputError
    from acoustisim.experiments.sweep import frange, run_sweep

    start, stop, step = (float(config.option(k, d)) for k, d in (("start", 0.1), ("stop", 2.5), ("step", 0.1)))
    if not (0.05 <= start <= stop <= 8.0 and step > 0):
        raise InputError(f"range sweep: need 0.05 <= start <= stop <= 8 m and step > 0, got {start}, {stop}, {step}")
    bearing = float(config.option("bearing", 2.0))
    return run_sweep(
        config, variable="range_m", values=frange(start, stop, step), fixed={"bearing_deg": bearing},
        default_repeats=DEFAULT_REPEATS, default_pings=DEFAULT_PINGS,
        calibration_at=(THRESHOLD_CALIBRATION_RANGE_M, bearing),
        title=f"Range sweep at {bearing:g} deg: error vs range (cf. seed fig. 4-13)", figure_name="range_sweep.png",
        seed_note=("Seed (fig. 4-13): errors of both detectors grow with range; matched filter within 1 cm, "
                   "threshold within 8 cm; threshold 0.008 s and matched filter 0.866 s per position."),
    )
