"""Throughput of the diffuse reverberation tracer against raw Embree queries on the same rays.

Usage
-----
    python benchmarks/bench_diffuse.py [--rays 200000] [--repeats 7] [--bounces 1] [--before FILE]

``--before FILE``: an older ``acoustisim/propagation/diffuse.py`` (e.g. from ``git show
REV:acoustisim/propagation/diffuse.py > /tmp/diffuse_before.py``) whose ``trace_diffuse`` is
timed interleaved with the current one (same context, config and load), its rows compared.

All measured in this run, on the thesis tank (``scenes.builtin.builtin_scene("thesis-tank")``)
at its default sonar pose, with the same ray directions (the tracer's own draw for the seed):

* ``raw intersect``: one embreex INTERSECT call on those rays (float32 buffers prepared
  beforehand), on an Embree scene built here from the ray caster's triangles: the baseline
  the issue names;
* ``raw same work``: the raw Embree calls the tracer makes (that INTERSECT, plus one OCCLUDED
  call on the hit -> receiver segments of every hit facing a receiver);
* ``tracer``: :func:`acoustisim.propagation.diffuse.trace_diffuse` (sampling, intersect,
  Lambert next-event estimation with occlusion to the three receivers, speckle);
* ``diffuse_paths``: the tracer plus packing into ``PATH_DTYPE`` rows;
* ``+ columns``: that plus :func:`~acoustisim.propagation.columns.complete_columns` (what
  :func:`~acoustisim.propagation.solve` adds to every mechanism's rows).

Printed: the median seconds and rays per second of each, and the ratios of the tracer to the
two baselines (goals: >= 5 million rays/s; within 2x of raw intersect).
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

from acoustisim.propagation.columns import complete_columns  # noqa: E402
from acoustisim.propagation.config import SolverConfig  # noqa: E402
from acoustisim.propagation.context import SolveContext  # noqa: E402
from acoustisim.propagation.diffuse import diffuse_paths, sample_directions, trace_diffuse  # noqa: E402
from acoustisim.propagation.raycast import RayCaster  # noqa: E402
from scenes.builtin import builtin_scene  # noqa: E402


def median_time(function, repeats: int) -> tuple[float, float]:
    """Median wall-clock and CPU (process) seconds of ``repeats`` calls."""
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        function()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return statistics.median(wall), statistics.median(cpu)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--bounces", type=int, default=1)
    parser.add_argument("--before", default=None, help="an older diffuse.py to compare with")
    args = parser.parse_args()

    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    scene = builtin_scene("thesis-tank")
    raycaster = RayCaster.from_scene(scene)
    context = SolveContext.build(scene, scene.sonar, raycaster)
    config = SolverConfig(diffuse_rays=args.rays, diffuse_bounces=args.bounces, seed=0)
    n = args.rays

    # the tracer's rays: same generator, same first draw
    directions, _ = sample_directions(n, context.boresight, context, np.random.default_rng(config.seed))
    shift = 0.5 * (raycaster.vertices.min(axis=0) + raycaster.vertices.max(axis=0))
    vertices32 = np.ascontiguousarray(raycaster.vertices - shift, dtype=np.float32)
    faces32 = np.ascontiguousarray(raycaster.faces, dtype=np.int32)
    embree = rtcore_scene.EmbreeScene()
    TriangleMesh(embree, vertices32, faces32)
    origins32 = np.ascontiguousarray(np.broadcast_to(context.transmitter_m - shift, (n, 3)), dtype=np.float32)
    directions32 = np.ascontiguousarray(directions, dtype=np.float32)

    # the NEE segments the tracer tests (every first hit facing a receiver)
    out = embree.run(origins32, directions32, query="INTERSECT", output=1)
    hit = np.asarray(out["primID"]) >= 0
    points = context.transmitter_m + directions[hit] * np.asarray(out["tfar"], dtype=float)[hit, None]
    normals = raycaster.face_normals[np.asarray(out["primID"])[hit]]
    to_rx = context.receivers_m[None, :, :] - points[:, None, :]
    facing = np.einsum("ijk,ik->ij", to_rx, normals) > 0
    hi, ri = np.nonzero(facing)
    seg = to_rx[hi, ri]
    length = np.linalg.norm(seg, axis=1)
    seg_o32 = np.ascontiguousarray(points[hi] - shift, dtype=np.float32)
    seg_d32 = np.ascontiguousarray(seg / length[:, None], dtype=np.float32)
    seg_t32 = np.ascontiguousarray(length, dtype=np.float32)

    def raw_intersect() -> None:
        embree.run(origins32, directions32, query="INTERSECT", output=1)

    def raw_same_work() -> None:
        embree.run(origins32, directions32, query="INTERSECT", output=1)
        embree.run(seg_o32, seg_d32, dists=seg_t32, query="OCCLUDED")

    results = {
        "raw intersect": median_time(raw_intersect, args.repeats),
        "raw same work": median_time(raw_same_work, args.repeats),
        "tracer": median_time(lambda: trace_diffuse(context, config), args.repeats),
        "diffuse_paths": median_time(lambda: diffuse_paths(context, config), args.repeats),
        "+ columns": median_time(lambda: complete_columns(diffuse_paths(context, config), context), args.repeats),
    }
    before_note = None
    if args.before:
        import importlib.util

        spec = importlib.util.spec_from_file_location("diffuse_before", args.before)
        module = importlib.util.module_from_spec(spec)
        sys.modules["diffuse_before"] = module  # dataclasses look their module up
        spec.loader.exec_module(module)
        now_cpu, before_cpu = [], []
        for _ in range(args.repeats):  # interleaved: the same load for both
            now_cpu.append(median_time(lambda: trace_diffuse(context, config), 1)[1])
            before_cpu.append(median_time(lambda: module.trace_diffuse(context, config), 1)[1])
        same = diffuse_paths(context, config).tobytes() == module.diffuse_paths(context, config).tobytes()
        now, then = statistics.median(now_cpu), statistics.median(before_cpu)
        before_note = (
            f"  tracer now {now * 1e3:.2f} ms CPU ({n / now / 1e6:.3f} M rays/s), {args.before} {then * 1e3:.2f} ms "
            f"({n / then / 1e6:.3f} M rays/s): now / before median of per-repeat ratios "
            f"{statistics.median([a / b for a, b in zip(now_cpu, before_cpu)]):.2f}, rows "
            f"{'byte-identical' if same else 'different'}"
        )
    events = trace_diffuse(context, config)
    print(f"thesis tank: {raycaster.triangle_count} triangles, {n} rays, {args.bounces} bounce(s), "
          f"{int(hit.sum())} first hits, {seg_t32.size} NEE segments, {events.event.size} rows; "
          f"medians of {args.repeats}")
    print("  (wall-clock medians; CPU-time medians in brackets: on a shared machine the CPU time is the")
    print("   fairer comparison, every stage being single-threaded)")
    for name, (wall, cpu) in results.items():
        print(f"  {name:14s} {wall * 1e3:9.2f} ms [{cpu * 1e3:8.2f}]   {n / wall / 1e6:7.3f} M rays/s "
              f"[{n / cpu / 1e6:7.3f}]")
    queries = n + seg_t32.size
    for index, label in ((0, "wall"), (1, "CPU")):
        tracer = results["tracer"][index]
        print(f"  {label}: tracer Embree queries (rays + NEE segments) {queries / tracer / 1e6:.3f} M/s, raw "
              f"{queries / results['raw same work'][index] / 1e6:.3f} M/s; tracer / raw intersect = "
              f"{tracer / results['raw intersect'][index]:.2f}x (goal <= 2x), tracer / raw same work = "
              f"{tracer / results['raw same work'][index]:.2f}x, diffuse_paths / tracer = "
              f"{results['diffuse_paths'][index] / tracer:.2f}x")
    if before_note:
        print(before_note)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
