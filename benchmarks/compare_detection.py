"""``bench_detection.py`` in two checkouts, alternately, and the ratios of their per-ping times.

Usage
-----
    python benchmarks/compare_detection.py BEFORE_DIR AFTER_DIR [--rounds 3] [--repeats 31]
        [--methods threshold local-matched matched] [--inputs f64 i16] [--statistic median]

Two checkouts cannot be imported in one process (they are the same package), so each round
runs ``benchmarks/bench_detection.py`` (``--clock cpu --no-seed-table``) in BEFORE_DIR, then in
AFTER_DIR, one after the other, so that both see the same load of a shared machine. Per method
and input form it prints, for the ``detect()``, ``Detector`` and ``prepared`` columns and the
prepared run over numpy's rfft of the record (measured in the same process), the median
(``--statistic median``, the default) or the fastest (``fastest``: on a loaded machine the round
least disturbed by other processes) of the rounds in each checkout, and AFTER / BEFORE.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
from pathlib import Path

ROW = re.compile(r"^(\S+)\s+(f64|i16|array)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)")
COLUMNS = (("detect() ms", 0), ("Detector ms", 2), ("prepared ms", 4), ("prepared/rfft", 5))


def run_bench(checkout: Path, arguments: list[str]) -> dict[tuple[str, str], list[float]]:
    """One run of ``bench_detection.py`` in ``checkout``: per (method, input) its six numbers."""
    environment = dict(os.environ, PYTHONPATH=str(checkout))
    output = subprocess.run([sys.executable, str(checkout / "benchmarks" / "bench_detection.py"), *arguments],
                            cwd=checkout, env=environment, capture_output=True, text=True, check=True).stdout
    rows = {}
    for line in output.splitlines():
        match = ROW.match(line)
        if match:
            rows[(match[1], match[2])] = [float(match[i]) for i in range(3, 9)]
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=31)
    parser.add_argument("--methods", nargs="+", default=["threshold", "local-matched", "matched"])
    parser.add_argument("--inputs", nargs="+", default=["f64", "i16"])
    parser.add_argument("--statistic", choices=("median", "fastest"), default="median",
                        help="of the rounds in each checkout")
    args = parser.parse_args()
    pick = statistics.median if args.statistic == "median" else min
    arguments = ["--repeats", str(args.repeats), "--clock", "cpu", "--no-seed-table", "--methods", *args.methods,
                 "--inputs", *args.inputs]
    runs: dict[str, list[dict]] = {"before": [], "after": []}
    for _ in range(args.rounds):
        runs["before"].append(run_bench(args.before.resolve(), arguments))
        runs["after"].append(run_bench(args.after.resolve(), arguments))
    print(f"{args.statistic} of {args.rounds} rounds (CPU clock, {args.repeats} repeats each): before / after "
          "(after / before)")
    print(f"{'method':16s} {'input':5s} " + " ".join(f"{name:>24s}" for name, _ in COLUMNS))
    for key in runs["before"][0]:
        cells = []
        for _, column in COLUMNS:
            before = pick(run[key][column] for run in runs["before"])
            after = pick(run[key][column] for run in runs["after"])
            cells.append(f"{before:.3f}/{after:.3f} ({after / before:.2f})")
        print(f"{key[0]:16s} {key[1]:5s} " + " ".join(f"{cell:>24s}" for cell in cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
