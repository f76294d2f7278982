"""Throughput of the diffuse reverberation tracer against raw Embree queries on the same rays.

Usage
-----
    python benchmarks/bench_diffuse.py [--rays 200000] [--repeats 7] [--bounces 1] [--threads N]
                                       [--before FILE]

``--threads``: worker threads of the threaded stages (default: every core available).
``--before FILE``: an older ``acoustisim/propagation/diffuse.py`` (e.g. from ``git show
REV:acoustisim/propagation/diffuse.py > /tmp/diffuse_before.py``) whose ``trace_diffuse`` is
timed interleaved with the current one on one thread (same context, config and load). It
imports the current ``diffuse_kernels``, so it works only for a revision whose kernels have
the same signatures; for older ones run this script in a separate checkout of that revision
(``git archive REV | tar -x -C /tmp/old && cd /tmp/old && PYTHONPATH=/tmp/old python
benchmarks/bench_diffuse.py``) alternately with the current one.

All measured in this run, on the thesis tank (``scenes.builtin.builtin_scene("thesis-tank")``)
at its default sonar pose, with the tracer's own ray directions for the seed:

* ``raw intersect x1``: one embreex INTERSECT call on those rays (float32 buffers prepared
  beforehand), on an Embree scene built here from the ray caster's triangles: the baseline
  the issue names; ``raw intersect xN``: the same rays in the tracer's chunks of
  ``CHUNK_RAYS`` on N threads (embreex releases the GIL), the baseline of the threaded tracer;
* ``raw same work``: the raw Embree calls the exact tracer would make if it asked Embree for
  every first hit (that INTERSECT, plus one OCCLUDED call on as many hit -> receiver legs as
  it sends to Embree: facing the receiver, crossing the box of an object without face planes;
  the legs crossing only convex objects' boxes are decided by the face planes, without
  Embree, and on the thesis tank, whose objects are all convex, no leg is left), single call
  and threaded. The tracer finds the first hits themselves without Embree in a box tank with
  convex objects (:mod:`acoustisim.propagation.diffuse_hits`: on the thesis tank it asks
  Embree about no ray; the count is printed), so both raw baselines are now the cost of the
  queries it no longer makes, and the ratios compare its whole work with them;
* ``tracer embree``: the same with ``first_hits="embree"``: every first hit from Embree
  INTERSECT, the path of general meshes (non-box tanks, non-convex objects);
* ``tracer``: :func:`acoustisim.propagation.diffuse.trace_diffuse` (sampling, first hits,
  Lambert next-event estimation with exact occlusion to the three receivers, speckle),
  on 1 and N threads, and with ``visibility="centre"`` (approximate, off by default);
* ``diffuse_paths``: the tracer plus packing into ``PATH_DTYPE`` rows (N threads);
* ``+ columns``: that plus :func:`~acoustisim.propagation.fast.columns.complete_columns` (what
  :func:`~acoustisim.propagation.solve` adds to every mechanism's rows).

Every repeat times each stage once, in turn (round-robin: on a shared machine the load
changes between blocks of repeats). Printed: the median wall-clock and CPU (process, all
threads) seconds and rays per second of each stage, and the medians of the per-repeat
ratios of the tracer to the raw baselines measured the same way (goals:
>= 5 million rays/s; within 2x of raw intersect); the legs hit -> receiver (first bounce)
that cross an object's box (the ones the box screen alone would send to Embree), those the
tracer decided with the convex objects' face planes, and those it still sent to Embree; the
rays whose first hit it asked Embree for. The relative change of the diffuse energy per
channel with ``visibility="centre"`` is printed too.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from acoustisim.propagation.fast.columns import complete_columns  # noqa: E402
from acoustisim.propagation.config import SolverConfig  # noqa: E402
from acoustisim.propagation.context import SolveContext  # noqa: E402
from acoustisim.propagation.diffuse import (  # noqa: E402
    CHUNK_RAYS,
    ObjectScreen,
    diffuse_paths,
    trace_diffuse,
)
from acoustisim.propagation.ray_threads import resolve_threads, run_in_order  # noqa: E402
from acoustisim.propagation.raycast import DEFAULT_EPS_M, RayCaster  # noqa: E402
from scenes.builtin import builtin_scene  # noqa: E402


def median_time(function, repeats: int) -> tuple[float, float]:
    """Median wall-clock and CPU (process, every thread) seconds of ``repeats`` calls."""
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        function()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return statistics.median(wall), statistics.median(cpu)


def chunked(n: int) -> list[slice]:
    """The tracer's chunks of ``n`` rays."""
    return [slice(a, min(a + CHUNK_RAYS, n)) for a in range(0, n, CHUNK_RAYS)]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--bounces", type=int, default=1)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--before", default=None, help="an older diffuse.py to compare with")
    args = parser.parse_args()
    threads = resolve_threads(args.threads)

    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    scene = builtin_scene("thesis-tank")
    raycaster = RayCaster.from_scene(scene)
    context = SolveContext.build(scene, scene.sonar, raycaster)
    config = SolverConfig(diffuse_rays=args.rays, diffuse_bounces=args.bounces, seed=0)
    n = args.rays

    # the tracer's rays: its departure directions (every ray of a closed tank hits something;
    # the few on the free surface, mu = 0, are not events: redraw none, time the events' rays
    # plus as many more from the same directions to keep n rays)
    events = trace_diffuse(context, SolverConfig(diffuse_rays=n, diffuse_bounces=1, seed=0), threads=threads)
    directions = events.departure_dir
    directions = np.concatenate([directions, directions[: n - directions.shape[0]]])
    shift = raycaster.shift_m
    vertices32 = np.ascontiguousarray(raycaster.vertices - shift, dtype=np.float32)
    faces32 = np.ascontiguousarray(raycaster.faces, dtype=np.int32)
    embree = rtcore_scene.EmbreeScene()
    TriangleMesh(embree, vertices32, faces32)
    origins32 = np.ascontiguousarray(np.broadcast_to(context.transmitter_m - shift, (n, 3)), dtype=np.float32)
    directions32 = np.ascontiguousarray(directions, dtype=np.float32)
    embree.run(origins32[:1], directions32[:1], query="INTERSECT")  # BVH built outside the timings

    # the legs crossing an object's box: first hits facing a receiver, near an object (its
    # own box skipped for a convex one), not the leg back to the centre transducer at the
    # transmitter; the tracer sends to Embree those crossing a box of an object without face
    # planes (events.embree_legs of them), the "same work" OCCLUDED call tests as many
    points = events.points_m
    normals = raycaster.face_normals[raycaster.first_hit_triangles32(origins32[: points.shape[0]],
                                                                     directions32[: points.shape[0]])]
    to_rx = context.receivers_m[None, :, :] - points[:, None, :]
    tested = np.einsum("ijk,ik->ij", to_rx, normals) > 0
    screen = ObjectScreen.create(scene, context.receivers_m)
    tested &= np.stack([screen.near(points, j, events.surface) for j in range(context.receivers_m.shape[0])],
                       axis=1)
    tested[:, np.all(context.receivers_m == context.transmitter_m, axis=1)] = False
    box_legs = int(tested.sum())
    # (a tracer without the face-plane test, before this counter, sent every such leg to Embree)
    embree_legs, convex_legs = getattr(events, "embree_legs", box_legs), getattr(events, "convex_legs", 0)
    hi, ri = np.nonzero(tested)
    hi, ri = hi[:embree_legs], ri[:embree_legs]
    seg = to_rx[hi, ri]
    length = np.linalg.norm(seg, axis=1)
    unit = seg / length[:, None]
    seg_o32 = np.ascontiguousarray(points[hi] + DEFAULT_EPS_M * unit - shift, dtype=np.float32)
    seg_d32 = np.ascontiguousarray(unit, dtype=np.float32)
    seg_t32 = np.ascontiguousarray(length - 2 * DEFAULT_EPS_M, dtype=np.float32)
    ray_chunks, leg_chunks = chunked(n), chunked(seg_t32.size)

    def raw_intersect() -> None:
        embree.run(origins32, directions32, query="INTERSECT")

    def raw_intersect_threaded() -> None:
        run_in_order(lambda s: embree.run(origins32[s], directions32[s], query="INTERSECT"), ray_chunks, threads)

    def raw_same_work() -> None:
        embree.run(origins32, directions32, query="INTERSECT")
        if seg_t32.size:
            embree.run(seg_o32, seg_d32, dists=seg_t32, query="OCCLUDED")

    def raw_same_work_threaded() -> None:
        raw_intersect_threaded()
        run_in_order(lambda s: embree.run(seg_o32[s], seg_d32[s], dists=seg_t32[s], query="OCCLUDED"),
                     leg_chunks, threads)

    t = threads
    stages = {
        "raw intersect x1": raw_intersect,
        f"raw intersect x{t}": raw_intersect_threaded,
        "raw same work x1": raw_same_work,
        f"raw same work x{t}": raw_same_work_threaded,
        "tracer x1": lambda: trace_diffuse(context, config, threads=1),
        f"tracer x{t}": lambda: trace_diffuse(context, config, threads=t),
        f"tracer centre x{t}": lambda: trace_diffuse(context, config, threads=t, visibility="centre"),
        "tracer embree x1": lambda: trace_diffuse(context, config, threads=1, first_hits="embree"),
        f"tracer embree x{t}": lambda: trace_diffuse(context, config, threads=t, first_hits="embree"),
        f"diffuse_paths x{t}": lambda: diffuse_paths(context, config, threads=t),
        f"+ columns x{t}": lambda: complete_columns(diffuse_paths(context, config, threads=t), context),
    }
    # round-robin: each repeat times every stage once, so that the per-repeat ratios compare
    # stages measured under the same load (this machine is shared)
    samples: dict[str, list[tuple[float, float]]] = {name: [] for name in stages}
    for _ in range(args.repeats):
        for name, function in stages.items():
            samples[name].append(median_time(function, 1))
    results = {name: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v))
               for name, v in samples.items()}

    def ratio(a: str, b: str, index: int) -> float:
        """Median over the repeats of stage a's time over stage b's (wall: 0, CPU: 1)."""
        return statistics.median(x[index] / y[index] for x, y in zip(samples[a], samples[b]))
    before_note = None
    if args.before:
        import importlib.util

        spec = importlib.util.spec_from_file_location("diffuse_before", args.before)
        module = importlib.util.module_from_spec(spec)
        sys.modules["diffuse_before"] = module  # dataclasses look their module up
        spec.loader.exec_module(module)
        now_cpu, before_cpu = [], []
        for _ in range(args.repeats):  # interleaved: the same load for both
            now_cpu.append(median_time(lambda: trace_diffuse(context, config, threads=1), 1)[1])
            before_cpu.append(median_time(lambda: module.trace_diffuse(context, config), 1)[1])
        now, then = statistics.median(now_cpu), statistics.median(before_cpu)
        before_note = (
            f"  one thread: tracer now {now * 1e3:.2f} ms CPU ({n / now / 1e6:.3f} M rays/s), {args.before} "
            f"{then * 1e3:.2f} ms ({n / then / 1e6:.3f} M rays/s): now / before median of per-repeat ratios "
            f"{statistics.median([a / b for a, b in zip(now_cpu, before_cpu)]):.2f}"
        )
    exact = trace_diffuse(context, config, threads=t)
    centre = trace_diffuse(context, config, threads=t, visibility="centre")

    def energy(ev) -> np.ndarray:
        return np.bincount(ev.channel, weights=ev.gain**2, minlength=3)

    change = energy(centre) / energy(exact) - 1.0
    print(f"thesis tank: {raycaster.triangle_count} triangles, {n} rays, {args.bounces} bounce(s), {t} thread(s), "
          f"{exact.event.size} rows; medians of {args.repeats}")
    print(f"  legs hit -> receiver crossing an object's box (first bounce): {box_legs}; decided by the convex "
          f"objects' face planes: {convex_legs}; sent to Embree: {embree_legs} "
          f"({getattr(exact, 'embree_legs', '?')} over {args.bounces} bounce(s))")
    print(f"  rays whose first hit the tracer asked Embree for: {getattr(exact, 'embree_rays', n)} of {n} x "
          f"{args.bounces} bounce(s) (the others: the tank's exit face and the convex objects' face planes, "
          f"acoustisim.propagation.diffuse_hits)")
    print("  wall-clock medians; CPU-time medians (process, all threads) in brackets")
    for name, (wall, cpu) in results.items():
        print(f"  {name:20s} {wall * 1e3:9.2f} ms [{cpu * 1e3:8.2f}]   {n / wall / 1e6:7.3f} M rays/s "
              f"[{n / cpu / 1e6:7.3f}]")
    print("  ratios: medians over the repeats of the per-repeat ratios")
    for index, label in ((0, "wall"), (1, "CPU")):
        r = {name: value[index] for name, value in results.items()}
        print(f"  {label}: tracer x{t} {n / r[f'tracer x{t}'] / 1e6:.2f} M rays/s (goal >= 5); tracer x{t} / raw "
              f"intersect x{t} = {ratio(f'tracer x{t}', f'raw intersect x{t}', index):.2f}x (goal <= 2x), / raw "
              f"same work x{t} = {ratio(f'tracer x{t}', f'raw same work x{t}', index):.2f}x; tracer x1 / raw "
              f"intersect x1 = {ratio('tracer x1', 'raw intersect x1', index):.2f}x; "
              + (f"tracer x1 / tracer x{t} = {ratio('tracer x1', f'tracer x{t}', index):.2f} (the threads' speed-up)"
                 if index == 0 else
                 f"tracer x{t} / tracer x1 = {ratio(f'tracer x{t}', 'tracer x1', index):.2f} (the threads' CPU cost)")
              + f"; with every first hit from Embree (the general-mesh path): tracer embree x{t} "
              f"{n / r[f'tracer embree x{t}'] / 1e6:.2f} M rays/s, tracer embree x1 / raw intersect x1 = "
              f"{ratio('tracer embree x1', 'raw intersect x1', index):.2f}x"
              + f"; centre visibility x{t} / raw "
              f"intersect x{t} = {ratio(f'tracer centre x{t}', f'raw intersect x{t}', index):.2f}x; diffuse_paths / "
              f"tracer = {ratio(f'diffuse_paths x{t}', f'tracer x{t}', index):.2f}x")
    print("  diffuse energy change with visibility='centre' per channel (left, centre, right): "
          + ", ".join(f"{100 * c:+.3f} %" for c in change))
    if before_note:
        print(before_note)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
