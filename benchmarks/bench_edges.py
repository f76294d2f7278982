"""Benchmark of edge diffraction for one pose of the thesis tank (CPU-time medians).

Prints, for the default pose: the CPU-time median of ``solve`` with the edge mechanism alone
(graded edges, keep-all: the "edges only" figure of ``bench_propagation.py``), of
:func:`~acoustisim.propagation.edges.edge_paths` itself, and of ``edge_paths`` with every
visibility leg sent to Embree (``screen=False``: the same-run baseline of the visibility
screen), with the number of legs the screen decides and leaves to Embree.

With ``--before REV``, the same figures for the edge modules of git revision REV
(``acoustisim/propagation/edges.py``, ``edge_*.py`` and ``btm.py`` of REV, over a copy of the
current package, so that only the edge code differs), measured in child processes that
alternate with the current code's for ``--rounds`` rounds (the same load for both), and the
ratios before / now (the median of each round's ratio).

Run: ``python benchmarks/bench_edges.py [--repeats 21] [--before REV] [--rounds 3]``
(``--repeats 9 --before b6e1281 --rounds 12``: about 2 min on the shared 2-core machine).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
EDGE_FILES = ("edges.py", "btm.py")
"""The edge modules besides ``edge_*.py`` (``acoustisim/propagation/``)."""


def _median_cpu(function, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.process_time()
        function()
        times.append(time.process_time() - start)
    return float(np.median(times))


def measure(repeats: int) -> dict[str, float]:
    """The figures of the current ``acoustisim`` (whichever ``import`` finds), in ms."""
    import inspect

    from acoustisim.propagation import SolverConfig, prepare, solve
    from acoustisim.propagation.context import SolveContext
    from acoustisim.propagation.edges import edge_paths
    from scenes.builtin import builtin_scene

    prepared = prepare(builtin_scene("thesis-tank"))
    config = SolverConfig(max_order=3, mechanisms=("edge",), amplitude_floor_db=None)
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    edges = prepared.diffracting_edges
    rows = solve(prepared, config=config)  # compile / warm up
    figures = {"rows": float(len(rows))}
    cases = {"solve_edges_only": lambda: solve(prepared, config=config),
             "edge_paths": lambda: edge_paths(context, config, edges, sort_rows=True)}
    if "screen" in inspect.signature(edge_paths).parameters:
        cases["edge_paths_embree_only"] = lambda: edge_paths(context, config, edges, sort_rows=True, screen=False)
    for function in cases.values():
        function()
    samples: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(repeats):  # interleaved, so all cases see the same load
        for name, function in cases.items():
            samples[name].append(_median_cpu(function, 1))
    for name, values in samples.items():
        figures[name] = float(np.median(values)) * 1e3
    return figures


def _legs() -> tuple[int, int]:
    """(legs decided by the screen, legs left to Embree) at the default pose."""
    from acoustisim.propagation import SolverConfig, prepare
    from acoustisim.propagation import edge_visibility
    from acoustisim.propagation import edges as edges_module
    from acoustisim.propagation.context import SolveContext
    from scenes.builtin import builtin_scene

    prepared = prepare(builtin_scene("thesis-tank"))
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    counts = {}
    original = edges_module.screened_visibility_rays32

    def spy(*args):
        result = original(*args)
        counts["embree"] = int(result[4].size)
        # legs: every element's leg to the transmitter, and to its receiver where that is not
        # the transmitter
        pair, pair_rx, rx, tx = args[0], args[4], args[9], args[8]
        own = ~np.all(rx == tx, axis=1)
        counts["legs"] = int(pair.size + np.sum(own[pair_rx[pair]]))
        return result

    edges_module.screened_visibility_rays32 = spy
    try:
        edges_module.edge_paths(context, SolverConfig(), prepared.diffracting_edges)
    finally:
        edges_module.screened_visibility_rays32 = original
    del edge_visibility
    return counts["legs"] - counts["embree"], counts["embree"]


def _before_tree(revision: str, directory: Path) -> Path:
    """A copy of the current ``acoustisim`` and ``scenes`` packages with the edge modules of
    ``revision``; returns the directory to put first on ``PYTHONPATH``."""
    for package in ("acoustisim", "scenes"):
        shutil.copytree(REPO / package, directory / package, ignore=shutil.ignore_patterns("__pycache__"))
    propagation = directory / "acoustisim" / "propagation"
    for path in propagation.glob("edge_*.py"):
        path.unlink()
    listing = subprocess.run(["git", "ls-tree", "--name-only", revision, "acoustisim/propagation/"], cwd=REPO,
                             check=True, capture_output=True, text=True).stdout.split()
    for name in listing:
        base = name.rsplit("/", 1)[-1]
        if base in EDGE_FILES or (base.startswith("edge_") and base.endswith(".py")):
            text = subprocess.run(["git", "show", f"{revision}:{name}"], cwd=REPO, check=True, capture_output=True,
                                  text=True).stdout
            (propagation / base).write_text(text)
    return directory


def _child(path: Path | None, repeats: int) -> dict[str, float]:
    environment = dict(os.environ)
    if path is not None:
        environment["PYTHONPATH"] = str(path) + os.pathsep + environment.get("PYTHONPATH", "")
    output = subprocess.run([sys.executable, __file__, "--child", "--repeats", str(repeats)], env=environment,
                            check=True, capture_output=True, text=True, cwd=path or REPO).stdout
    return json.loads(output.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=21)
    parser.add_argument("--before", default=None, help="a git revision whose edge modules to time against")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds with --before")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(args.repeats)))
        return
    decided, embree = _legs()
    print(f"thesis tank, default pose: {decided} visibility legs decided by the screen, {embree} left to Embree")
    if args.before is None:
        figures = measure(args.repeats)
        print(f"  CPU medians over {args.repeats} ({int(figures['rows'])} rows): solve edges only "
              f"{figures['solve_edges_only']:.2f} ms; edge_paths {figures['edge_paths']:.2f} ms; edge_paths with "
              f"every leg to Embree {figures['edge_paths_embree_only']:.2f} ms")
        return
    with tempfile.TemporaryDirectory() as scratch:
        before_path = _before_tree(args.before, Path(scratch))
        _child(before_path, 1)  # compile the before tree's numba caches
        results: dict[str, list[dict[str, float]]] = {"before": [], "now": []}
        for _ in range(args.rounds):
            results["before"].append(_child(before_path, args.repeats))
            results["now"].append(_child(None, args.repeats))
    print(f"  CPU medians over {args.repeats} repeats, {args.rounds} alternating rounds (median of the rounds):")
    for name in ("solve_edges_only", "edge_paths"):
        before = float(np.median([r[name] for r in results["before"]]))
        now = float(np.median([r[name] for r in results["now"]]))
        rounds = ", ".join(f"{b[name]:.2f}/{n[name]:.2f}" for b, n in zip(results["before"], results["now"]))
        # the ratio within each round (neighbouring child processes: the nearest in load) is
        # steadier on a shared machine than the ratio of the medians
        ratio = float(np.median([b[name] / n[name] for b, n in zip(results["before"], results["now"])]))
        print(f"    {name}: before ({args.before}) {before:.2f} ms, now {now:.2f} ms; median of the rounds' "
              f"before / now = {ratio:.2f} (rounds before/now: {rounds})")
    rows = {int(r["rows"]) for r in results["before"] + results["now"]}
    print(f"    rows: {sorted(rows)}")


if __name__ == "__main__":
    main()
