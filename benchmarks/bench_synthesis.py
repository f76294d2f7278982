"""Synthesis speed of one thesis-tank ping against a floor measured in the same run.

Usage
-----
    python benchmarks/bench_synthesis.py [--repeats 9] [--scene thesis-tank] [--before FILE]
                                         [--save-rows FILE.npy | --rows FILE.npy]

``--save-rows`` stores the traced path rows (``numpy.save``); ``--rows`` times synthesis on such a
stored set instead of the solver's current rows (the scene still gives the sonar and medium), so
that synthesis figures can be compared while the propagation engine's row counts change.

``--before FILE``: an older ``acoustisim/synthesis/synthesiser.py`` (e.g. from ``git show
REV:acoustisim/synthesis/synthesiser.py > /tmp/synthesiser_before.py``), whose
``PathSynthesiser.decimated_record`` is timed interleaved with the current one on the same rows
(and its output compared), for a before/after ratio under the same load.

Times are CPU-time medians (``time.process_time``: every stage is single-threaded, and on a
shared machine the wall clock mostly measures the other processes), wall-clock medians in
brackets.

Measured (medians over ``--repeats``), on the traced paths of the scene (the solver runs once,
untimed):
  - floor: drawing the noise of the three-channel record (3 x n normal deviates) plus one real
    FFT of that record: the least any synthesis with noise must do;
  - ping: ``PingSynthesiser.render`` of one ping with every mechanism on (all path rows with
    per-bin directivity and absorption, main bang and cross-talk, band-pass, TVG, thermal and
    electrical noise with lines, ADC), the paths' elastic transfer functions already computed;
  - the first ping of newly solved paths, which computes the elastic echoes' transfer functions
    (``acoustisim.propagation.elastic_responses``; kept for later pings of the same paths), against
    the same paths solved without elastic echoes;
  - extra ping: the marginal cost of one more ping in a multi-ping render (the paths'
    deterministic part is computed once per render);
  - planning: ``PingSynthesiser.create`` (once per sonar, medium and chain);
  - the compiled loops (numba, ``acoustisim/synthesis/row_kernels.py`` and ``ping_loops.py``):
    first renders in a fresh process with an empty cache (compilation, once per checkout) and
    with the cache filled (what each new process, e.g. a Dask worker, pays once); the timed
    renders above come after an untimed warm-up render.
Printed: the medians, the ratio ping / floor (goal <= 3) and the peak traced memory (Python and
numba allocations, ``tracemalloc``) of one ping at the record length and at twice it (memory per
ping must scale with the record length).

``--before-tree DIR [--rounds R] [--like-for-like]``: a same-run A/B with an older checkout (its
``acoustisim`` and ``scenes``): the floor and one ping are timed, interleaved, in this tree and in
DIR in alternating subprocesses (:mod:`same_work`); printed are the medians over the rounds, the
ping / floor ratio of each tree, now / before, and whether the two trees' path rows agree (in
the fields both have) and their recordings (the int16 codes and volts of one ping, seed 1) are
byte-identical. ``--like-for-like`` solves what an older tree solves: the new mechanisms off,
the built-in solids on the ``fluid`` reflection model, and the record 12.5 ms long (the thesis
tank's before it was lengthened).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
import warnings
from pathlib import Path

from same_work import (PRE_SESSION_RECORD_S, alternating_runs, common_fields_verdict, field_digests,
                       fluid_reflection_scene, solver_config, tree_root, with_record_length)

ROOT = tree_root(__file__)
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from acoustisim.propagation import solve  # noqa: E402
from acoustisim.synthesis import PingSynthesiser, ReceiverChain, TimeVaryingGain  # noqa: E402
from scenes.builtin import builtin_scene  # noqa: E402


def cpu_and_wall(function) -> tuple[float, float]:
    """CPU (process) and wall-clock seconds of one call."""
    start, start_cpu = time.perf_counter(), time.process_time()
    function()
    return time.process_time() - start_cpu, time.perf_counter() - start


def median_time(function, repeats: int) -> float:
    """Median CPU seconds of ``repeats`` calls."""
    return statistics.median(cpu_and_wall(function)[0] for _ in range(repeats))


def load_module(path: str, name: str):
    """Import a module from a file (an older version of one of ours) under another name."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up while the class is built
    spec.loader.exec_module(module)
    return module


def peak_memory(function) -> int:
    tracemalloc.start()
    function()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


FIRST_RENDER = """
import sys, time
sys.path.insert(0, {root!r})
from acoustisim.medium import Medium
from acoustisim.propagation.paths import empty_paths_array
from acoustisim.sonar import SonarHead
from acoustisim.synthesis import PingSynthesiser, ReceiverChain, TimeVaryingGain
synth = PingSynthesiser.create(SonarHead(record_length_s=1e-3), Medium(), ReceiverChain(tvg=TimeVaryingGain()))
rows = empty_paths_array(3)
rows["channel"] = [0, 1, 2]
rows["delay_s"] = 2e-4
rows["geometric_gain"] = 1.0
start, start_wall = time.process_time(), time.perf_counter()
synth.render(rows, seed=1)
synth.render(rows, seed=1, snr_db=10.0, snr_rows=tuple(rows[c : c + 1] for c in range(3)))
print(time.process_time() - start, time.perf_counter() - start_wall)
"""


def first_render_cost(cache_dir: str) -> tuple[float, float]:
    """CPU and wall seconds of the first renders (both noise paths) in a fresh process whose
    numba cache is ``cache_dir``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    result = subprocess.run(
        [sys.executable, "-c", FIRST_RENDER.format(root=str(ROOT))], env=env, capture_output=True, text=True,
        check=True,
    )
    cpu, wall = (float(v) for v in result.stdout.split()[-2:])
    return cpu, wall


def ab_figures(args) -> dict:
    """One side of the ``--before-tree`` A/B, in whichever tree is imported: CPU and wall medians of
    the floor and of one ping (interleaved), the median of the per-repeat ratios, the digests of
    the rows and of one ping's recording."""
    scene = builtin_scene(args.scene)
    if args.like_for_like:
        scene = with_record_length(fluid_reflection_scene(scene), PRE_SESSION_RECORD_S)
    paths = solve(scene, scene.sonar, solver_config(args.like_for_like))
    rows, responses = paths.rows, tuple(getattr(paths, "responses", ()))
    synth = PingSynthesiser.create(scene.sonar, scene.medium, ReceiverChain(tvg=TimeVaryingGain()))

    def render(seed: int):
        # an older synthesiser takes no responses (a like-for-like solve has none)
        return synth.render(rows, seed=seed, responses=responses) if responses else synth.render(rows, seed=seed)

    n = scene.sonar.n_samples
    rng = np.random.default_rng(0)

    def floor() -> None:
        noise = rng.standard_normal((3, n))
        np.fft.rfft(noise, axis=1)

    first = render(1)  # also the warm-up
    counter = iter(range(2, 10**9))
    samples: dict[str, list[tuple[float, float]]] = {"floor": [], "ping": []}
    for _ in range(args.repeats):
        samples["floor"].append(cpu_and_wall(floor))
        samples["ping"].append(cpu_and_wall(lambda: render(next(counter))))
    out: dict = {name: [statistics.median(c for c, _ in v), statistics.median(w for _, w in v)]
                 for name, v in samples.items()}
    out["ratio"] = statistics.median(p[0] / f[0] for p, f in zip(samples["ping"], samples["floor"]))
    out["rows"] = int(rows.size)
    out["samples"] = int(n)
    out["digests"] = field_digests(rows)
    out["recording"] = hashlib.sha1(np.ascontiguousarray(first.codes).tobytes()
                                    + np.ascontiguousarray(first.volts).tobytes()).hexdigest()[:16]
    return out


def before_and_after(args) -> None:
    """:func:`ab_figures` in ``args.before_tree`` and in this tree, alternating subprocesses."""
    trees = {"before": str(Path(args.before_tree).resolve()), "now": str(tree_root(__file__))}
    arguments = ["--json", "--repeats", str(args.repeats), "--scene", args.scene]
    arguments += ["--like-for-like"] if args.like_for_like else []
    runs = alternating_runs(__file__, trees, arguments, args.rounds)
    first = {name: run[0] for name, run in runs.items()}
    same_recording = "byte-identical" if first["before"]["recording"] == first["now"]["recording"] else "different"
    setup = " like for like" if args.like_for_like else ""
    same_rows = common_fields_verdict(first["before"]["digests"], first["now"]["digests"])
    print(f"A/B against {trees['before']}{setup}: {args.scene}, {first['now']['rows']} path rows, 3 x "
          f"{first['now']['samples']} samples; medians over {args.rounds} alternating subprocess rounds of "
          f"{args.repeats} interleaved repeats; {same_rows}; one ping's recording (seed 1) {same_recording}")
    for key in ("floor", "ping"):
        before = [statistics.median(run[key][i] for run in runs["before"]) for i in (0, 1)]
        now = [statistics.median(run[key][i] for run in runs["now"]) for i in (0, 1)]
        print(f"  {key:6s} CPU before {before[0] * 1e3:7.1f} ms, now {now[0] * 1e3:7.1f} ms (now / before "
              f"{now[0] / before[0]:.2f}); wall before {before[1] * 1e3:7.1f} ms, now {now[1] * 1e3:7.1f} ms")
    ratios = {name: statistics.median(run["ratio"] for run in run_list) for name, run_list in runs.items()}
    print(f"  ping / floor (CPU, median of per-repeat ratios): before {ratios['before']:.2f}, now {ratios['now']:.2f}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--scene", default="thesis-tank")
    parser.add_argument("--before", default=None, help="an older synthesiser.py to compare with")
    parser.add_argument("--save-rows", default=None, help="save the solver's path rows to this .npy file")
    parser.add_argument("--rows", default=None, help="time these stored path rows (.npy) instead of solving")
    parser.add_argument("--before-tree", default=None, help="an older checkout: same-run A/B (see the docstring)")
    parser.add_argument("--rounds", type=int, default=3, help="alternating subprocess rounds of --before-tree")
    parser.add_argument("--like-for-like", action="store_true",
                        help="the A/B without the newer mechanisms, on the fluid reflection model, 12.5 ms record")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    warnings.simplefilter("ignore", UserWarning)  # arrivals past the record's end
    if args.json:  # one side of the --before-tree A/B
        print(json.dumps(ab_figures(args)))
        return 0
    if args.before_tree:
        before_and_after(args)
        return 0

    scene = builtin_scene(args.scene)
    sonar = scene.sonar
    start = time.perf_counter()
    responses: tuple = ()
    if args.rows:
        rows = np.load(args.rows)
        if "response_id" in rows.dtype.names:
            rows = rows.copy()
            rows["response_id"] = -1  # stored rows carry no transfer functions
        origin = f"{rows.size} path rows from {args.rows}"
    else:
        paths = solve(scene, sonar)
        rows, responses = paths.rows, paths.responses
        origin = (f"{len(paths)} path rows ({paths.arrivals().size} arrivals, {len(responses)} with elastic transfer"
                  f" functions), solve {time.perf_counter() - start:.2f} s")
        if args.save_rows:
            np.save(args.save_rows, rows)
    chain = ReceiverChain(tvg=TimeVaryingGain())  # every mechanism on
    n = sonar.n_samples

    rng = np.random.default_rng(0)

    def floor() -> None:
        noise = rng.standard_normal((3, n))
        np.fft.rfft(noise, axis=1)

    planning = median_time(lambda: PingSynthesiser.create(sonar, scene.medium, chain), max(3, args.repeats // 3))
    synth = PingSynthesiser.create(sonar, scene.medium, chain)
    synth.render(rows, seed=0, responses=responses)  # untimed warm-up: numba loops, elastic transfer functions
    counter = iter(range(10**9))
    before = None
    if args.before:
        padding = chain.bandpass_settle_s() + 8.0 * chain.main_bang_decay_s  # as PingSynthesiser.create
        before = load_module(args.before, "synthesiser_before").PathSynthesiser.create(sonar, scene.medium, padding)
    # Interleaved so that the floor and the pings see the same load on a shared machine.
    samples: dict[str, list[tuple[float, float]]] = {k: [] for k in ("floor", "ping", "paths", "ten", "before")}
    for _ in range(args.repeats):
        samples["floor"].append(cpu_and_wall(floor))
        samples["ping"].append(cpu_and_wall(lambda: synth.render(rows, seed=next(counter), responses=responses)))
        samples["paths"].append(cpu_and_wall(lambda: synth.paths.decimated_record(rows, responses=responses)))
        if before is not None:
            samples["before"].append(cpu_and_wall(lambda: before.decimated_record(rows)))
        samples["ten"].append(cpu_and_wall(lambda: synth.render(rows, seed=next(counter), n_pings=10,
                                                                responses=responses)))
    cpu = {k: statistics.median(c for c, _ in v) for k, v in samples.items() if v}
    wall = {k: statistics.median(w for _, w in v) for k, v in samples.items() if v}
    floor_s, ping_s, ten_s, paths_s = cpu["floor"], cpu["ping"], cpu["ten"], cpu["paths"]
    extra_s = (ten_s - ping_s) / 9.0
    ratios = sorted(p / f for (p, _), (f, _) in zip(samples["ping"], samples["floor"]))

    memory = peak_memory(lambda: synth.render(rows, seed=1, responses=responses))
    long_sonar = dataclasses.replace(sonar, record_length_s=2 * sonar.record_length_s)
    long_synth = PingSynthesiser.create(long_sonar, scene.medium, chain)
    memory_long = peak_memory(lambda: long_synth.render(rows, seed=1, responses=responses))

    elastic = None
    if not args.rows:  # the elastic echoes' transfer functions: computed by the first render of new paths
        from acoustisim.propagation import SolverConfig, prepare

        prepared = prepare(scene)
        fresh, plain = [], []
        for _ in range(max(3, args.repeats // 3)):
            new = solve(prepared, sonar)
            fresh.append(cpu_and_wall(lambda: synth.render(new.rows, seed=1, responses=new.responses)))
            off = solve(prepared, sonar, SolverConfig(elastic_echoes=False))
            plain.append(cpu_and_wall(lambda: synth.render(off.rows, seed=1)))
        elastic = (statistics.median(c for c, _ in fresh), statistics.median(c for c, _ in plain))

    with tempfile.TemporaryDirectory() as cache_dir:
        cold = first_render_cost(cache_dir)
        cached = first_render_cost(cache_dir)

    print(f"scene {scene.name}: {origin}")
    print(f"record: 3 x {n} samples at {sonar.sample_rate_hz / 1e6:g} MS/s ({sonar.record_length_s * 1e3:g} ms)")
    print("CPU-time medians [wall-clock medians]")
    print(f"floor (noise + one rfft)      median {floor_s * 1e3:8.1f} ms [{wall['floor'] * 1e3:8.1f}]")
    print(
        f"one ping, every mechanism on  median {ping_s * 1e3:8.1f} ms [{wall['ping'] * 1e3:8.1f}]"
        f"   ratio {ping_s / floor_s:5.2f} x floor (goal <= 3)"
    )
    print(f"  ratio per repeat (same load): min {ratios[0]:.2f}, median {statistics.median(ratios):.2f}, max {ratios[-1]:.2f}")
    print(
        f"  of which the paths (kernels + overlap-add){paths_s * 1e3:8.1f} ms [{wall['paths'] * 1e3:8.1f}]"
        f" ({paths_s / max(rows.size, 1) * 1e7:.1f} ms per 10^4 rows)"
    )
    if before is not None:
        same = np.array_equal(before.decimated_record(rows), synth.paths.decimated_record(rows))
        pairs = [a / b for (a, _), (b, _) in zip(samples["paths"], samples["before"])]
        print(
            f"  the paths with {args.before}: {cpu['before'] * 1e3:8.1f} ms [{wall['before'] * 1e3:8.1f}];"
            f" now / before median of per-repeat ratios {statistics.median(pairs):.2f}"
            f" (output {'identical' if same else 'different'})"
        )
    print(f"each extra ping (of 10)              {extra_s * 1e3:8.1f} ms   ratio {extra_s / floor_s:5.2f} x floor")
    if elastic is not None:
        print(f"first ping of newly solved paths (elastic transfer functions computed) median {elastic[0] * 1e3:8.1f} ms;"
              f" the same paths without elastic echoes {elastic[1] * 1e3:8.1f} ms (ratio {elastic[0] / elastic[1]:.1f})")
    print(f"planning (create, once)       median {planning * 1e3:8.1f} ms")
    print(
        f"compiled loops, first renders in a new process: {cold[0]:.2f} s CPU [{cold[1]:.2f}] with an empty"
        f" numba cache (once per checkout), {cached[0]:.2f} s CPU [{cached[1]:.2f}] with it filled"
    )
    print(
        f"peak memory per ping: {memory / 2**20:.1f} MiB at {n} samples, {memory_long / 2**20:.1f} MiB at {2 * n}"
        f" (ratio {memory_long / memory:.2f}; {memory / (3 * n):.0f} bytes per channel-sample)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
