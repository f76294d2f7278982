"""Rendering time of the 3-D view: the thesis tank with 10,000 drawn paths (goal: under 5 s).

Usage
-----
    python benchmarks/bench_view.py [--repeats 5] [--paths 10000] [--size 1200x800]

Measured in this run, each the median of ``--repeats`` runs after one warm-up (the warm-up's
time, which includes creating the first OpenGL context, is printed apart):
  - baseline: the tank, objects, sonar and beam with no paths, off-screen to a PNG picture
    (the VTK render and the matplotlib composition: labels, axes, legend panel);
  - with paths: the same plus the ``--paths`` strongest rows of the solver's output for the
    thesis tank drawn one by one (edge-diffraction elements not collapsed and no cap on the
    diffuse rows, so the count is the number of polylines on screen), off-screen to PNG;
  - the layer building alone (NumPy/VTK geometry, no rendering);
  - the standalone HTML export of the same view.
Printed: the medians, the paths' cost as a ratio to the baseline, and whether the 5 s goal
holds. The solve itself is timed once and is not part of the rendering time.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from acoustisim.propagation import solve  # noqa: E402
from acoustisim.viz.render import ViewOptions, build_layers, export_html  # noqa: E402
from acoustisim.viz.snapshot import render_png  # noqa: E402
from scenes.builtin import builtin_scene  # noqa: E402

GOAL_S = 5.0


def _median_time(function, repeats: int) -> tuple[float, float, float]:
    """(warm-up wall time, median wall time, median CPU time of this process, all threads
    including Mesa's rasteriser threads) of ``repeats`` runs after the warm-up, in seconds. The
    CPU time is the fairer figure on a shared, loaded machine."""
    start = time.perf_counter()
    function()
    warm = time.perf_counter() - start
    walls, cpus = [], []
    for _ in range(repeats):
        start, cpu = time.perf_counter(), time.process_time()
        function()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu)
    return warm, statistics.median(walls), statistics.median(cpus)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--paths", type=int, default=10_000)
    parser.add_argument("--size", default="1200x800")
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))

    scene = builtin_scene("thesis-tank")
    start = time.perf_counter()
    paths = solve(scene)
    solve_s = time.perf_counter() - start
    if len(paths) < args.paths:
        print(f"the solver gave only {len(paths)} rows (< {args.paths}); drawing all of them")
    options = ViewOptions(max_paths=args.paths, max_diffuse=None, edge_elements=True)
    drawn = sum(
        int(layer.label.split("(")[-1].rstrip(")").replace(",", ""))
        for layer in build_layers(scene, paths, options=options)
        if layer.group == "paths"
    )
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        warm_base, base, base_cpu = _median_time(
            lambda: render_png(scene, out / "base.png", None, window_size=size, camera="top"), args.repeats)
        warm_full, full, full_cpu = _median_time(
            lambda: render_png(scene, out / "full.png", paths, options=options, window_size=size, camera="top"),
            args.repeats)
        _, layers_s, layers_cpu = _median_time(lambda: build_layers(scene, paths, options=options), args.repeats)
        _, html_s, html_cpu = _median_time(
            lambda: export_html(scene, out / "full.html", paths, options=options), args.repeats)
        html_mb = (out / "full.html").stat().st_size / 1e6

    print(f"thesis tank: solver rows {len(paths)} (solve {solve_s:.2f} s, not counted); drawn paths {drawn}")
    try:
        load = Path("/proc/loadavg").read_text().split()[0]
    except OSError:
        load = "?"
    print(f"window {size[0]}x{size[1]}, medians of {args.repeats} runs after one warm-up; load average {load}")
    print("                               wall      CPU")
    print(f"  baseline, no paths, PNG      {base:6.2f} s  {base_cpu:6.2f} s   (warm-up {warm_base:.2f} s)")
    print(f"  with {drawn} paths, PNG     {full:6.2f} s  {full_cpu:6.2f} s   (warm-up {warm_full:.2f} s)   "
          f"ratio {full / base:.2f}x")
    print(f"  layers only (geometry)       {layers_s:6.2f} s  {layers_cpu:6.2f} s")
    print(f"  HTML export                  {html_s:6.2f} s  {html_cpu:6.2f} s   ({html_mb:.1f} MB)")
    verdict = "PASS" if full < GOAL_S else "FAIL"
    print(f"goal: {drawn} paths rendered in < {GOAL_S:.0f} s: {verdict} (median {full:.2f} s)")
    return 0 if full < GOAL_S else 1


if __name__ == "__main__":
    sys.exit(main())
