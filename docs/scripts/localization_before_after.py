"""Issue 19's validation table: the ``localization-accuracy`` experiment at a few positions, each
run twice on the same pings (same seed): with the plain matched filter's times (``--no-beam``,
"before") and beam-aware (the default, "after"). Prints one markdown row per position and mode.

    python docs/scripts/localization_before_after.py [--pings 500] [--workers 2] [--out DIR]

Each position is its own experiment run (the experiment's grid is ranges x bearings; the
issue's positions are not a grid); results.json and report.md of every run are kept under
``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

from acoustisim.experiments.config import ExperimentConfig
from acoustisim.experiments.registry import experiment_module

POSITIONS: tuple[tuple[float, float], ...] = ((0.3, 10.0), (0.5, 0.0), (0.8, 8.0), (1.5, -6.0), (2.5, -10.0))
"""(range m, bearing deg): issue 19's three post positions and the corners of its 0.3-2.5 m,
+/-10 deg box."""
HEADER = ("| target | range (m) | bearing (deg) | timing | found | range bias (um) | +/- | bearing bias (mdeg) | +/- "
          "| range sd/reported | bearing sd/reported | var(e/sd) r, b | fused max err (um, mdeg) | issue 19 |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def row(p: dict, timing: str) -> str:
    ok = p["within_tolerance"]
    failed = [k for k in ("bias", "variance", "fused", "detected") if not ok[k]]
    verdict = "pass" if not failed else "FAIL: " + ", ".join(failed)
    return (f"| {p['kind']} | {p['range_m']:g} | {p['bearing_deg']:g} | {timing} | {p['detected']}/{p['n_pings']} "
            f"| {p['range_bias_m'] * 1e6:.1f} | {2 * p['range_bias_se_m'] * 1e6:.1f} "
            f"| {p['bearing_bias_deg'] * 1e3:.1f} | {2 * p['bearing_bias_se_deg'] * 1e3:.1f} "
            f"| {p['range_scatter_to_reported']:.2f} | {p['bearing_scatter_to_reported']:.2f} "
            f"| {p['range_normalised_variance']:.2f}, {p['bearing_normalised_variance']:.2f} "
            f"| {p['fused_range_max_abs_error_m'] * 1e6:.0f}, {p['fused_bearing_max_abs_error_deg'] * 1e3:.0f} "
            f"| {verdict} |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pings", type=int, default=500, help="pings per position and mode (default 500)")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--seed", type=int, default=19)
    parser.add_argument("--out", type=Path, default=None, help="folder for the runs' reports (default: a temporary one)")
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="localization-before-after-"))
    module = experiment_module("localization-accuracy")
    print(f"{args.pings} pings per position and mode at 2E/N0 = 30 dB, fused groups of 20; seed {args.seed}; "
          f"reports under {out}")
    print("'issue 19': |bias| <= 50 um and 20 mdeg, var(e/sd) within 1 +/- 0.2 for range and bearing, every fused "
          "group within 200 um and 50 mdeg, every ping's target found; +/- is twice the bias's standard error.")
    print(HEADER)
    for range_m, bearing_deg in POSITIONS:
        for no_beam, timing in ((True, "plain (--no-beam)"), (False, "beam (default)")):
            folder = out / f"{range_m:g}m_{bearing_deg:g}deg_{'plain' if no_beam else 'beam'}"
            config = ExperimentConfig(name="localization-accuracy", out_dir=folder, seed=args.seed, trials=args.pings,
                                      workers=args.workers, progress=False,
                                      options={"kinds": ["post", "edge"], "ranges": [range_m],
                                               "bearings": [bearing_deg], "fuse_pings": 20, "no_beam": no_beam})
            files = module.run(config).write()
            for p in json.loads(Path(files["results"]).read_text())["positions"]:
                print(row(p, timing), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
