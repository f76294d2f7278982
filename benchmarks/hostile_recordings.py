"""Run binsonar's hostile corpus (damaged recordings, hostile imports, argument lists, outputs) and
count the outcomes by kind.

    python benchmarks/hostile_recordings.py                         # this checkout
    python benchmarks/hostile_recordings.py --root /work/wt/baseline  # another checkout, same corpus

Every command line runs in its own process (``python -m binsonar.cli.main ...``) with a time
limit and an address-space limit; the contract: exit 0 on valid input, exit 2 with exactly one
line on bad input, never a traceback. Kinds (``support.hostile_recordings.classify``): ok,
traceback, hang (past the time limit), usage (an argparse usage block), multi-line, accepted
(bad input given exit 0), refused (valid input refused), crash (another exit code, a signal,
memory exhausted). The corpus is written by ``tests/support/hostile_recordings.py`` with h5py,
numpy, soundfile and scipy only, so the same files serve any version of binsonar.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from support.hostile_recordings import build_corpus, classify  # noqa: E402


def _limits(memory_bytes: int):
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
    return apply


def run_one(root: Path, argv: tuple[str, ...], timeout_s: float, memory_bytes: int) -> tuple[int | None, str, bool, float]:
    """(exit code, stderr, timed out, seconds) of ``binsonar argv`` with ``root`` on the path."""
    env = {**os.environ, "PYTHONPATH": str(root), "PYTHONWARNINGS": "ignore"}
    start = time.perf_counter()
    try:
        done = subprocess.run([sys.executable, "-m", "binsonar.cli.main", *argv], capture_output=True, text=True,
                              timeout=timeout_s, env=env, cwd=root, preexec_fn=_limits(memory_bytes))
    except subprocess.TimeoutExpired as exc:
        stderr = exc.stderr.decode(errors="replace") if isinstance(exc.stderr, bytes) else (exc.stderr or "")
        return None, stderr, True, time.perf_counter() - start
    return done.returncode, done.stderr, False, time.perf_counter() - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=HERE.parent, help="checkout whose binsonar runs (default this one)")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds per command (default 60)")
    parser.add_argument("--memory-gb", type=float, default=4.0, help="address-space limit per command (GB)")
    parser.add_argument("--json", action="store_true", help="print the counts and the failures as JSON")
    parser.add_argument("--show", type=int, default=40, help="failures listed (default 40)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="hostile-") as folder:
        runs = build_corpus(Path(folder))
        counts: collections.Counter[str] = collections.Counter()
        by_family: dict[str, collections.Counter[str]] = collections.defaultdict(collections.Counter)
        failures = []
        elapsed = []
        for run in runs:
            code, stderr, timed_out, seconds = run_one(args.root.resolve(), run.argv, args.timeout,
                                                       int(args.memory_gb * 2**30))
            kind = classify(run.case.expect, code, stderr, timed_out)
            counts[kind] += 1
            by_family[run.case.kind][kind] += 1
            elapsed.append(seconds)
            if kind != "ok":
                last = stderr.strip().splitlines()[-1] if stderr.strip() else ""
                failures.append({"kind": kind, "case": run.case.name, "verb": run.argv[0], "exit": code,
                                 "stderr_last_line": last[:200]})
    summary = {"root": str(args.root), "runs": len(runs), "counts": dict(sorted(counts.items())),
               "by_family": {k: dict(sorted(v.items())) for k, v in sorted(by_family.items())},
               "median_s": sorted(elapsed)[len(elapsed) // 2], "max_s": max(elapsed)}
    if args.json:
        print(json.dumps({**summary, "failures": failures}, indent=1))
        return 0
    print(f"{len(runs)} command lines against {args.root}")
    print("counts: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    for family, family_counts in sorted(by_family.items()):
        print(f"  {family:10s} " + ", ".join(f"{k} {v}" for k, v in sorted(family_counts.items())))
    print(f"seconds per command: median {summary['median_s']:.2f}, max {summary['max_s']:.2f}")
    for failure in failures[: args.show]:
        print(f"  [{failure['kind']}] {failure['verb']} {failure['case']}: exit {failure['exit']}: "
              f"{failure['stderr_last_line']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
