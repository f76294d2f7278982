"""Benchmark of edge diffraction for one pose of the thesis tank (CPU-time medians).

Prints, for the default pose: how many element visibility legs the fast engine's screen
decides and how many it leaves to Embree; the CPU-time medians of ``solve`` with the edge
mechanism alone (graded edges, keep-all), of the fast engine's edge rows
(:func:`acoustisim.propagation.fast.edges.edge_rows`) and of the reference engine's
(:func:`acoustisim.propagation.reference.edge_paths.edge_rows`).

Then the same with one reflection combined with each edge (``SolverConfig(edge_reflections=1, edge_reflection_fresnel_v=None)``:
edge -> mirror or curved surface, and the reverse): the fast and the reference edge rows' CPU
medians and their ratio, and the row count.

With ``--baseline DIR``, the first two figures also for the source tree in DIR (for instance
``/work/wt/baseline``: its ``acoustisim`` and ``scenes`` on ``PYTHONPATH``; a tree from before
the two engines, whose edge rows are ``edges.edge_paths(..., sort_rows=True)``), measured in
child processes that alternate with the current tree's for ``--rounds`` rounds (the same load
for both), and the ratios now / baseline (the median of each round's ratio).

Run: ``python benchmarks/bench_edges.py [--repeats 21] [--baseline /work/wt/baseline] [--rounds 5]``
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent


def _cpu_seconds(function: Callable[[], Any]) -> float:
    start = time.process_time()
    function()
    return time.process_time() - start


def _edge_rows_of_this_tree(context: Any, config: Any, prepared: Any) -> Callable[[], Any]:
    """The fast edge rows of whichever ``acoustisim`` is imported: the fast engine's, or, in a
    tree from before the two engines, ``edge_paths`` sorted for the solver."""
    try:
        from acoustisim.propagation.fast.edges import edge_rows
    except ImportError:
        from acoustisim.propagation.edges import edge_paths

        return lambda: edge_paths(context, config, prepared.diffracting_edges, sort_rows=True)
    return lambda: edge_rows(context, config, prepared)


def measure(repeats: int, reference: bool) -> dict[str, float]:
    """The figures of the imported ``acoustisim`` (ms; ``rows`` a count): ``solve_edges_only``,
    ``fast_edge_rows`` and, with ``reference``, ``reference_edge_rows``."""
    from acoustisim.propagation import SolverConfig, prepare, solve
    from acoustisim.propagation.context import SolveContext
    from scenes.builtin import builtin_scene

    prepared = prepare(builtin_scene("thesis-tank"))
    config = SolverConfig(max_order=3, mechanisms=("edge",), amplitude_floor_db=None)
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    cases = {"solve_edges_only": lambda: solve(prepared, config=config),
             "fast_edge_rows": _edge_rows_of_this_tree(context, config, prepared)}
    figures = {"rows": float(len(cases["fast_edge_rows"]()))}  # (compiles, warms up)
    for function in cases.values():
        function()
    samples: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(repeats):  # interleaved, so all cases see the same load
        for name, function in cases.items():
            samples[name].append(_cpu_seconds(function))
    if reference:
        from acoustisim.propagation.reference.edge_paths import edge_rows

        samples["reference_edge_rows"] = [_cpu_seconds(lambda: edge_rows(context, config, prepared))
                                          for _ in range(max(3, repeats // 4))]
    for name, values in samples.items():
        figures[name] = float(np.median(values)) * 1e3
    return figures


def measure_reflections(repeats: int) -> dict[str, float]:
    """CPU medians (ms) of the fast and the reference edge rows with ``edge_reflections=1`` at the
    thesis tank's default pose (interleaved), and their row count."""
    from acoustisim.propagation import SolverConfig, prepare
    from acoustisim.propagation.context import SolveContext
    from acoustisim.propagation.fast.edges import edge_rows as fast_edge_rows
    from acoustisim.propagation.reference.edge_paths import edge_rows as reference_edge_rows
    from scenes.builtin import builtin_scene

    prepared = prepare(builtin_scene("thesis-tank"))
    config = SolverConfig(max_order=3, mechanisms=("edge",), amplitude_floor_db=None, edge_reflections=1, edge_reflection_fresnel_v=None)
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    cases = {"fast": lambda: fast_edge_rows(context, config, prepared),
             "reference": lambda: reference_edge_rows(context, config, prepared)}
    figures = {"rows": float(len(cases["fast"]()))}
    samples: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(max(3, repeats // 4)):
        for name, function in cases.items():
            samples[name].append(_cpu_seconds(function))
    for name, values in samples.items():
        figures[name] = float(np.median(values)) * 1e3
    return figures


def screened_legs() -> tuple[int, int]:
    """(legs decided by the fast engine's screen, legs left to Embree) at the default pose."""
    from acoustisim.propagation import SolverConfig, prepare
    from acoustisim.propagation.context import SolveContext
    from acoustisim.propagation.fast.edge_elements import discretise_edges
    from acoustisim.propagation.fast.edge_visibility import EdgeLines, LegTargets, scene_screen, screen_element_legs
    from acoustisim.propagation.raycast import DEFAULT_EPS_M
    from acoustisim.propagation.reference.edges import discretisation, edge_pairs
    from scenes.builtin import builtin_scene

    prepared = prepare(builtin_scene("thesis-tank"))
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    pairs = edge_pairs(context, prepared.diffracting_edges)
    elements = discretise_edges(pairs.geometry, discretisation(SolverConfig(), context))
    targets = LegTargets.of(context)
    _, queries = screen_element_legs(elements, pairs.edge, pairs.receiver, EdgeLines.of(prepared.diffracting_edges),
                                     targets, scene_screen(prepared), prepared.raycaster.shift_m, DEFAULT_EPS_M)
    legs = elements.pair.size + int(np.sum(targets.own_leg[pairs.receiver[elements.pair]]))
    return legs - int(queries.element.size), int(queries.element.size)


def _child(tree: Path, repeats: int) -> dict[str, float]:
    environment = dict(os.environ)
    environment["PYTHONPATH"] = str(tree) + os.pathsep + environment.get("PYTHONPATH", "")
    output = subprocess.run([sys.executable, __file__, "--child", "--repeats", str(repeats)], env=environment,
                            check=True, capture_output=True, text=True, cwd=tree).stdout
    return json.loads(output.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=21)
    parser.add_argument("--baseline", type=Path, default=None, help="a source tree to time against")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds with --baseline")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(args.repeats, reference=False)))
        return
    decided, embree = screened_legs()
    print(f"thesis tank, default pose: {decided} visibility legs decided by the screen, {embree} left to Embree")
    figures = measure(args.repeats, reference=True)
    print(f"  CPU medians over {args.repeats} ({int(figures['rows'])} rows): solve edges only "
          f"{figures['solve_edges_only']:.2f} ms; fast edge rows {figures['fast_edge_rows']:.2f} ms; reference "
          f"edge rows {figures['reference_edge_rows']:.2f} ms")
    reflections = measure_reflections(args.repeats)
    print(f"  with edge_reflections=1 ({int(reflections['rows'])} rows), CPU medians over "
          f"{max(3, args.repeats // 4)}: fast edge rows {reflections['fast']:.1f} ms, reference edge rows "
          f"{reflections['reference']:.1f} ms; reference / fast = {reflections['reference'] / reflections['fast']:.1f}")
    if args.baseline is None:
        return
    _child(args.baseline, 1)  # compile the baseline tree's numba caches
    results: dict[str, list[dict[str, float]]] = {"baseline": [], "now": []}
    for _ in range(args.rounds):
        results["baseline"].append(_child(args.baseline, args.repeats))
        results["now"].append(_child(REPO, args.repeats))
    print(f"  against {args.baseline}: CPU medians over {args.repeats} repeats, {args.rounds} alternating rounds:")
    for name in ("solve_edges_only", "fast_edge_rows"):
        baseline = float(np.median([r[name] for r in results["baseline"]]))
        now = float(np.median([r[name] for r in results["now"]]))
        rounds = ", ".join(f"{b[name]:.2f}/{n[name]:.2f}" for b, n in zip(results["baseline"], results["now"]))
        # the ratio within each round (neighbouring child processes: the nearest in load) is
        # steadier on a shared machine than the ratio of the medians
        ratio = float(np.median([n[name] / b[name] for b, n in zip(results["baseline"], results["now"])]))
        print(f"    {name}: baseline {baseline:.2f} ms, now {now:.2f} ms; median of the rounds' now / baseline = "
              f"{ratio:.3f} (rounds baseline/now: {rounds})")
    rows = {int(r["rows"]) for r in results["baseline"] + results["now"]}
    print(f"    rows: {sorted(rows)}")


if __name__ == "__main__":
    main()
