"""Throughput of the fast diffuse tracer against raw Embree queries on the same rays, and the
reference engine's time.

Usage
-----
    python benchmarks/bench_diffuse.py [--rays 200000] [--repeats 7] [--bounces 1] [--threads N]
                                       [--reference-rays 20000]

All measured in this run, on the thesis tank (``scenes.builtin.builtin_scene("thesis-tank")``)
at its default sonar pose, with the tracer's own ray directions for the seed:

* ``raw intersect x1``: one embreex INTERSECT call on those rays (float32 buffers prepared
  beforehand) on an Embree scene built here from the ray caster's triangles: what the tracer's
  first bounce would cost if it only asked Embree for the hits; ``raw intersect xN``: the same
  rays in the tracer's chunks of ``CHUNK_RAYS`` on N threads (embreex releases the GIL), the
  baseline of the threaded tracer. (In a box tank with convex objects the tracer finds its first
  hits without Embree, :mod:`acoustisim.propagation.fast.diffuse_hits`; the number of rays it
  still asks Embree about is printed.)
* ``tracer x1``, ``tracer xN``: :func:`acoustisim.propagation.fast.diffuse.trace_diffuse`
  (sampling, first hits, Lambert next-event estimation with exact occlusion to the three
  receivers, speckle) on 1 and N threads; ``tracer centre xN`` with
  ``diffuse_visibility="centre"``;
* ``diffuse_rows xN``: the tracer plus packing into ``PATH_DTYPE`` rows; ``+ columns xN``: that
  plus :func:`~acoustisim.propagation.fast.columns.complete_columns`;
* ``fast engine`` and ``reference engine``: ``diffuse_rows`` of each engine at
  ``--reference-rays`` rays (default 20,000, the solver's default), one thread.

Every repeat times each stage once, in turn (round-robin: on a shared machine the load changes
between blocks of repeats). Printed: the median wall-clock and CPU (process, all threads) time
and rays per second of each stage, and the medians of the per-repeat ratios (the tracer to the
raw baselines; the reference engine to the fast one); the legs hit -> receiver the tracer
decided with the convex objects' face planes and those it sent to Embree; the relative change
of the diffuse energy per channel with ``diffuse_visibility="centre"``.

``--before-tree DIR [--rounds R]``: a same-run A/B with an older checkout (its ``acoustisim``
and ``scenes``): the raw intersect baselines, the tracer and ``diffuse_rows`` on one and N
threads are timed in this tree and in DIR in alternating subprocesses (:mod:`same_work`), each
with its own round-robin repeats and same-process ratios; printed are the medians over the
rounds, the ratios to the raw baseline in each tree, now / before, and whether the two trees'
diffuse rows agree byte for byte (in the fields both have). The diffuse tracer has no mechanism
added since, and the thesis tank's surfaces are smooth: the two trees trace the same rays.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from same_work import alternating_runs, common_fields_verdict, field_digests, solver_config, tree_root

sys.path.insert(0, str(tree_root(__file__)))

AB_STAGES = ("raw intersect x1", "raw intersect xN", "tracer x1", "tracer xN", "diffuse_rows xN")
"""The stages the ``--before-tree`` A/B times in each tree."""


def timed(function) -> tuple[float, float]:
    """Wall-clock and CPU (process, every thread) seconds of one call."""
    start, start_cpu = time.perf_counter(), time.process_time()
    function()
    return time.perf_counter() - start, time.process_time() - start_cpu


def raw_embree(raycaster, context, directions, n: int):
    """An Embree scene of the ray caster's triangles and the float32 rays (n) from the transmitter
    along ``directions`` (completed to n by repeating them), its BVH built."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    directions = np.concatenate([directions, directions[: n - directions.shape[0]]])
    shift = raycaster.shift_m
    embree = rtcore_scene.EmbreeScene()
    TriangleMesh(embree, np.ascontiguousarray(raycaster.vertices - shift, dtype=np.float32),
                 np.ascontiguousarray(raycaster.faces, dtype=np.int32))
    origins32 = np.ascontiguousarray(np.broadcast_to(context.transmitter_m - shift, (n, 3)), dtype=np.float32)
    directions32 = np.ascontiguousarray(directions, dtype=np.float32)
    embree.run(origins32[:1], directions32[:1], query="INTERSECT")  # BVH built outside the timings
    return embree, origins32, directions32


def ab_figures(args) -> dict:
    """One side of the ``--before-tree`` A/B, in whichever tree is imported: the medians (wall, CPU)
    of :data:`AB_STAGES`, the per-repeat ratios to the raw intersect, and the rows' digests."""
    from acoustisim.propagation.context import SolveContext
    from acoustisim.propagation.raycast import RayCaster
    from scenes.builtin import builtin_scene

    try:  # the engines' layout
        from acoustisim.propagation.fast import diffuse as tracer_module
        from acoustisim.propagation.fast.ray_threads import resolve_threads, run_in_order
        from acoustisim.propagation.reference.diffuse import CHUNK_RAYS

        def trace(context, config, threads):
            return tracer_module.trace_diffuse(context, replace(config, threads=threads))

        def rows(context, config, threads):
            return tracer_module.diffuse_rows(context, replace(config, threads=threads))

        def departures(traced):
            return traced.events.departure
    except ModuleNotFoundError:  # one propagation package (before the engines were split)
        from acoustisim.propagation import diffuse as tracer_module
        from acoustisim.propagation.diffuse import CHUNK_RAYS
        from acoustisim.propagation.ray_threads import resolve_threads, run_in_order

        def trace(context, config, threads):
            return tracer_module.trace_diffuse(context, config, threads=threads)

        def rows(context, config, threads):
            return tracer_module.diffuse_paths(context, config, threads=threads)

        def departures(traced):
            return traced.departure_dir

    threads = resolve_threads(args.threads)
    scene = builtin_scene("thesis-tank")
    raycaster = RayCaster.from_scene(scene)
    context = SolveContext.build(scene, scene.sonar, raycaster)
    n = args.rays
    config = solver_config(True, diffuse_rays=n, diffuse_bounces=args.bounces, seed=0)
    embree, origins32, directions32 = raw_embree(
        raycaster, context, departures(trace(context, replace(config, diffuse_bounces=1), threads)), n)
    chunks = [slice(a, min(a + CHUNK_RAYS, n)) for a in range(0, n, CHUNK_RAYS)]
    stages = {
        "raw intersect x1": lambda: embree.run(origins32, directions32, query="INTERSECT"),
        "raw intersect xN": lambda: run_in_order(
            lambda s: embree.run(origins32[s], directions32[s], query="INTERSECT"), chunks, threads),
        "tracer x1": lambda: trace(context, config, 1),
        "tracer xN": lambda: trace(context, config, threads),
        "diffuse_rows xN": lambda: rows(context, config, threads),
    }
    samples: dict[str, list[tuple[float, float]]] = {name: [] for name in stages}
    for _ in range(args.repeats):
        for name, function in stages.items():
            samples[name].append(timed(function))
    out = {"threads": threads, "digests": field_digests(np.asarray(rows(context, config, threads)))}
    for name, values in samples.items():
        out[name] = [statistics.median(w for w, _ in values), statistics.median(c for _, c in values)]
    for traced, raw in (("tracer xN", "raw intersect xN"), ("tracer x1", "raw intersect x1")):
        out[f"{traced} / {raw}"] = [statistics.median(a[i] / b[i] for a, b in zip(samples[traced], samples[raw]))
                                    for i in (0, 1)]
    return out


def before_and_after(args) -> None:
    """:func:`ab_figures` in ``args.before_tree`` and in this tree, alternating subprocesses."""
    trees = {"before": str(Path(args.before_tree).resolve()), "now": str(tree_root(__file__))}
    arguments = ["--json", "--rays", str(args.rays), "--repeats", str(args.repeats), "--bounces", str(args.bounces)]
    if args.threads is not None:
        arguments += ["--threads", str(args.threads)]
    runs = alternating_runs(__file__, trees, arguments, args.rounds)
    t = runs["now"][0]["threads"]
    print(f"A/B against {trees['before']}: thesis tank, {args.rays} rays, {args.bounces} bounce(s), {t} thread(s); "
          f"medians over {args.rounds} alternating subprocess rounds of {args.repeats} round-robin repeats; "
          f"{common_fields_verdict(runs['before'][0]['digests'], runs['now'][0]['digests'])}")
    for key in AB_STAGES + ("tracer xN / raw intersect xN", "tracer x1 / raw intersect x1"):
        before = [statistics.median(run[key][i] for run in runs["before"]) for i in (0, 1)]
        now = [statistics.median(run[key][i] for run in runs["now"]) for i in (0, 1)]
        if " / " in key:
            print(f"  {key.replace('N', str(t))}: wall before {before[0]:.2f}, now {now[0]:.2f}; CPU before "
                  f"{before[1]:.2f}, now {now[1]:.2f} (same-process ratios)")
        else:
            print(f"  {key.replace('xN', f'x{t}'):18s} wall before {before[0] * 1e3:8.2f} ms, now "
                  f"{now[0] * 1e3:8.2f} ms "
                  f"(now / before {now[0] / before[0]:.2f}); CPU before {before[1] * 1e3:8.2f} ms, now "
                  f"{now[1] * 1e3:8.2f} ms (now / before {now[1] / before[1]:.2f})")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--bounces", type=int, default=1)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--reference-rays", type=int, default=20_000)
    parser.add_argument("--before-tree", default=None, help="an older checkout: same-run A/B (see the docstring)")
    parser.add_argument("--rounds", type=int, default=3, help="alternating subprocess rounds of --before-tree")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.json:  # one side of the --before-tree A/B
        print(json.dumps(ab_figures(args)))
        return 0
    if args.before_tree:
        before_and_after(args)
        return 0

    from acoustisim.propagation.config import SolverConfig
    from acoustisim.propagation.context import SolveContext
    from acoustisim.propagation.fast import diffuse as fast_diffuse
    from acoustisim.propagation.fast.columns import complete_columns
    from acoustisim.propagation.fast.ray_threads import resolve_threads, run_in_order
    from acoustisim.propagation.raycast import RayCaster
    from acoustisim.propagation.reference import diffuse as reference_diffuse
    from scenes.builtin import builtin_scene

    threads = resolve_threads(args.threads)
    scene = builtin_scene("thesis-tank")
    raycaster = RayCaster.from_scene(scene)
    context = SolveContext.build(scene, scene.sonar, raycaster)
    n, t = args.rays, threads
    config = SolverConfig(diffuse_rays=n, diffuse_bounces=args.bounces, seed=0, threads=t)
    one_thread = replace(config, threads=1)
    centre = replace(config, diffuse_visibility="centre")
    small = SolverConfig(diffuse_rays=args.reference_rays, diffuse_bounces=args.bounces, seed=0, threads=1)

    # the tracer's rays: the departure directions of its first-bounce events (every ray of a
    # closed tank hits something; the few on the free surface, mu = 0, are not events: their
    # places are filled with repeated directions to keep n rays)
    first = fast_diffuse.trace_diffuse(context, replace(config, diffuse_bounces=1))
    embree, origins32, directions32 = raw_embree(raycaster, context, first.events.departure, n)
    chunks = [slice(a, min(a + reference_diffuse.CHUNK_RAYS, n)) for a in range(0, n, reference_diffuse.CHUNK_RAYS)]

    stages = {
        "raw intersect x1": lambda: embree.run(origins32, directions32, query="INTERSECT"),
        f"raw intersect x{t}": lambda: run_in_order(
            lambda s: embree.run(origins32[s], directions32[s], query="INTERSECT"), chunks, t),
        "tracer x1": lambda: fast_diffuse.trace_diffuse(context, one_thread),
        f"tracer x{t}": lambda: fast_diffuse.trace_diffuse(context, config),
        f"tracer centre x{t}": lambda: fast_diffuse.trace_diffuse(context, centre),
        f"diffuse_rows x{t}": lambda: fast_diffuse.diffuse_rows(context, config),
        f"+ columns x{t}": lambda: complete_columns(fast_diffuse.diffuse_rows(context, config), context),
        "fast engine": lambda: fast_diffuse.diffuse_rows(context, small),
        "reference engine": lambda: reference_diffuse.diffuse_rows(context, small),
    }
    samples: dict[str, list[tuple[float, float]]] = {name: [] for name in stages}
    for _ in range(args.repeats):
        for name, function in stages.items():
            samples[name].append(timed(function))

    def ratio(a: str, b: str, index: int) -> float:
        """Median over the repeats of stage a's time over stage b's (wall: 0, CPU: 1)."""
        return statistics.median(x[index] / y[index] for x, y in zip(samples[a], samples[b]))

    exact = fast_diffuse.trace_diffuse(context, config)
    shared = fast_diffuse.trace_diffuse(context, centre)

    def energy(traced) -> np.ndarray:
        return np.bincount(traced.events.channel, weights=traced.events.gain**2, minlength=3)

    change = energy(shared) / energy(exact) - 1.0
    print(f"thesis tank: {raycaster.triangle_count} triangles, {n} rays, {args.bounces} bounce(s), {t} thread(s), "
          f"{exact.events.event.size} receptions; medians of {args.repeats}")
    print(f"  legs hit -> receiver decided by the convex objects' face planes: {exact.convex_legs}; sent to Embree: "
          f"{exact.embree_legs}; rays whose first hit the tracer asked Embree for: {exact.embree_rays}")
    print("  wall-clock medians; CPU-time medians (process, all threads) in brackets")
    for name, values in samples.items():
        wall = statistics.median(w for w, _ in values)
        cpu = statistics.median(c for _, c in values)
        rays = args.reference_rays if name.endswith("engine") else n
        print(f"  {name:20s} {wall * 1e3:9.2f} ms [{cpu * 1e3:8.2f}]   {rays / wall / 1e6:7.3f} M rays/s "
              f"[{rays / cpu / 1e6:7.3f}]")
    print("  ratios: medians over the repeats of the per-repeat ratios")
    for index, label in ((0, "wall"), (1, "CPU")):
        print(f"  {label}: tracer x{t} / raw intersect x{t} = {ratio(f'tracer x{t}', f'raw intersect x{t}', index):.2f}; "
              f"tracer x1 / raw intersect x1 = {ratio('tracer x1', 'raw intersect x1', index):.2f}; "
              f"centre x{t} / raw intersect x{t} = {ratio(f'tracer centre x{t}', f'raw intersect x{t}', index):.2f}; "
              f"diffuse_rows / tracer = {ratio(f'diffuse_rows x{t}', f'tracer x{t}', index):.2f}; "
              f"reference / fast engine ({args.reference_rays} rays, one thread) = "
              f"{ratio('reference engine', 'fast engine', index):.1f}")
    print("  diffuse energy change with diffuse_visibility='centre' per channel (left, centre, right): "
          + ", ".join(f"{100 * c:+.3f} %" for c in change))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
