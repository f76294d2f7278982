"""Synthesis speed of one thesis-tank ping against a floor measured in the same run.

Usage
-----
    python benchmarks/bench_synthesis.py [--repeats 9] [--scene thesis-tank]

Measured (medians over ``--repeats``), on the traced paths of the scene (the solver runs once,
untimed):
  - floor: drawing the noise of the three-channel record (3 x n normal deviates) plus one real
    FFT of that record: the least any synthesis with noise must do;
  - ping: ``PingSynthesiser.render`` of one ping with every mechanism on (all path rows with
    per-bin directivity and absorption, main bang and cross-talk, band-pass, TVG, thermal and
    electrical noise with lines, ADC);
  - extra ping: the marginal cost of one more ping in a multi-ping render (the paths'
    deterministic part is computed once per render);
  - planning: ``PingSynthesiser.create`` (once per sonar, medium and chain).
Printed: the medians, the ratio ping / floor (goal <= 3) and the peak traced memory (Python
allocations, ``tracemalloc``) of one ping at the record length and at twice it (memory per ping
must scale with the record length).
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
import tracemalloc
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from acoustisim.propagation import solve  # noqa: E402
from acoustisim.synthesis import PingSynthesiser, ReceiverChain, TimeVaryingGain  # noqa: E402
from scenes.builtin import builtin_scene  # noqa: E402


def median_time(function, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def peak_memory(function) -> int:
    tracemalloc.start()
    function()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--scene", default="thesis-tank")
    args = parser.parse_args()
    warnings.simplefilter("ignore", UserWarning)  # arrivals past the record's end

    scene = builtin_scene(args.scene)
    sonar = scene.sonar
    start = time.perf_counter()
    paths = solve(scene, sonar)
    solve_s = time.perf_counter() - start
    chain = ReceiverChain(tvg=TimeVaryingGain())  # every mechanism on
    n = sonar.n_samples

    rng = np.random.default_rng(0)

    def floor() -> None:
        noise = rng.standard_normal((3, n))
        np.fft.rfft(noise, axis=1)

    planning = median_time(lambda: PingSynthesiser.create(sonar, scene.medium, chain), max(3, args.repeats // 3))
    synth = PingSynthesiser.create(sonar, scene.medium, chain)
    counter = iter(range(10**9))
    # Interleaved so that the floor and the pings see the same load on a shared machine.
    floors, pings, tens, paths_only = [], [], [], []
    for _ in range(args.repeats):
        floors.append(median_time(floor, 1))
        pings.append(median_time(lambda: synth.render(paths.rows, seed=next(counter)), 1))
        paths_only.append(median_time(lambda: synth.paths.decimated_record(paths.rows), 1))
        tens.append(median_time(lambda: synth.render(paths.rows, seed=next(counter), n_pings=10), 1))
    floor_s, ping_s = statistics.median(floors), statistics.median(pings)
    ten_s, paths_s = statistics.median(tens), statistics.median(paths_only)
    extra_s = (ten_s - ping_s) / 9.0
    ratios = sorted(p / f for p, f in zip(pings, floors))

    memory = peak_memory(lambda: synth.render(paths.rows, seed=1))
    long_sonar = dataclasses.replace(sonar, record_length_s=2 * sonar.record_length_s)
    long_synth = PingSynthesiser.create(long_sonar, scene.medium, chain)
    memory_long = peak_memory(lambda: long_synth.render(paths.rows, seed=1))

    print(f"scene {scene.name}: {len(paths)} path rows ({paths.arrivals().size} arrivals), solve {solve_s:.2f} s")
    print(f"record: 3 x {n} samples at {sonar.sample_rate_hz / 1e6:g} MS/s ({sonar.record_length_s * 1e3:g} ms)")
    print(f"floor (noise + one rfft)      median {floor_s * 1e3:8.1f} ms")
    print(f"one ping, every mechanism on  median {ping_s * 1e3:8.1f} ms   ratio {ping_s / floor_s:5.2f} x floor (goal <= 3)")
    print(f"  ratio per repeat (same load): min {ratios[0]:.2f}, median {statistics.median(ratios):.2f}, max {ratios[-1]:.2f}")
    print(
        f"  of which the paths (kernels + scatter)  {paths_s * 1e3:8.1f} ms"
        f" ({paths_s / len(paths) * 1e7:.1f} ms per 10^4 rows)"
    )
    print(f"each extra ping (of 10)              {extra_s * 1e3:8.1f} ms   ratio {extra_s / floor_s:5.2f} x floor")
    print(f"planning (create, once)       median {planning * 1e3:8.1f} ms")
    print(
        f"peak memory per ping: {memory / 2**20:.1f} MiB at {n} samples, {memory_long / 2**20:.1f} MiB at {2 * n}"
        f" (ratio {memory_long / memory:.2f}; {memory / (3 * n):.0f} bytes per channel-sample)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
