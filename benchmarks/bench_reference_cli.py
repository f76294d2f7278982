"""Wall and CPU time of the documented commands on the fast and the reference engine.

Runs, in turn, ``acoustisim simulate thesis-tank -o FILE --backend B`` and ``acoustisim demo
--out DIR --backend B`` for B in fast and reference (``--rounds`` times each, alternating), each
as a fresh process importing this tree (:func:`~same_work.tree_root`, so
``ACOUSTISIM_BENCH_TREE=DIR`` times another checkout), and prints per command the median wall
time and CPU time (user + system of the process and its children) and reference / fast. A
fresh process pays its imports and the compiled kernels' cache loads, as a user's command does.
The outputs go to a temporary folder, removed afterwards.

Run: ``python benchmarks/bench_reference_cli.py [--rounds R] [--commands simulate demo]``
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from same_work import TREE_VARIABLE, tree_root

ENTRY = "import sys; from acoustisim.cli import main; sys.argv[0] = 'acoustisim'; sys.exit(main())"
"""The ``acoustisim`` console script, run by this interpreter in the tree imported."""


def command_arguments(command: str, backend: str, folder: Path) -> list[str]:
    """The command line (after ``acoustisim``) of ``command`` on ``backend``, writing into ``folder``."""
    if command == "simulate":
        return ["simulate", "thesis-tank", "-o", str(folder / f"ping-{backend}.h5"), "--backend", backend]
    return ["demo", "--out", str(folder / f"demo-{backend}"), "--backend", backend]


def timed_run(arguments: list[str], root: Path) -> tuple[float, float]:
    """Wall and CPU time (s; user + system of the child) of one command in a fresh process."""
    env = dict(os.environ, PYTHONPATH=str(root), **{TREE_VARIABLE: str(root)})
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    result = subprocess.run([sys.executable, "-c", ENTRY, *arguments], env=env, cwd=root, capture_output=True,
                            text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if result.returncode:
        raise RuntimeError(f"acoustisim {' '.join(arguments)} failed:\n{result.stderr[-3000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--commands", nargs="+", choices=("simulate", "demo"), default=["simulate", "demo"])
    args = parser.parse_args()
    root = tree_root(__file__)
    with tempfile.TemporaryDirectory() as folder:
        for command in args.commands:
            timed_run(command_arguments(command, "fast", Path(folder)), root)  # warm the kernels' cache
            samples: dict[str, list[tuple[float, float]]] = {"fast": [], "reference": []}
            for _ in range(args.rounds):
                for backend in samples:
                    samples[backend].append(timed_run(command_arguments(command, backend, Path(folder)), root))
            wall = {b: statistics.median(w for w, _ in s) for b, s in samples.items()}
            cpu = {b: statistics.median(c for _, c in s) for b, s in samples.items()}
            print(f"acoustisim {' '.join(command_arguments(command, 'B', Path('OUT')))} ({root}; medians over "
                  f"{args.rounds} alternating runs): fast wall {wall['fast']:.1f} s, CPU {cpu['fast']:.1f} s; "
                  f"reference wall {wall['reference']:.1f} s, CPU {cpu['reference']:.1f} s; reference / fast wall "
                  f"{wall['reference'] / wall['fast']:.2f}, CPU {cpu['reference'] / cpu['fast']:.2f}")


if __name__ == "__main__":
    main()
