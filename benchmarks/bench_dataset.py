"""Dataset generation throughput, Dask + Zarr overhead and memory over a long run.

Usage
-----
    python benchmarks/bench_dataset.py [--samples 24] [--spec examples/dataset_spec.toml]
    python benchmarks/bench_dataset.py --memory 10000      # slow: RSS over a long tiny-sample run

Default mode, all measured in this run on the same samples of the spec:
  - baseline: build + simulate each sample in a plain Python loop (no Dask, no Zarr);
  - the in-process task's stages (simulate, labels, write + checksum): median CPU per sample;
  - in-process generate (``--workers 0``): the baseline plus the Zarr writes and completion;
  - Dask LocalCluster with 1 and 2 worker processes, each warmed up first on a 2-sample run
    (imports and caches; cluster start-up is not per-sample cost).
Printed: the baseline's median wall time per sample; for each mode samples per second (wall)
and CPU seconds per sample (driver + workers), and its overhead against the baseline in CPU
and in wall time, and against the CPU its own tasks spent building and simulating
(``GenerateReport.simulate_cpu_s``, same run, same machine state: the most robust figure, as
the CPU cost of the same work drifts by 10-20 % from one phase to the next when other
processes share the cores); the 2-worker speed-up
over 1 worker (goal: >= 1.8x; impossible when fewer than 2 cores are free).

Memory mode: generates N tiny samples on a LocalCluster of 2 workers and samples the
resident set size (driver + workers) every second; prints it at each tenth of the run.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from acoustisim.datasets.generate import _local_cluster, generate, simulate_sample  # noqa: E402
from acoustisim.datasets.sampling import plan_samples  # noqa: E402
from acoustisim.datasets.spec import load_spec, loads_spec  # noqa: E402

TINY_SPEC = """
[dataset]
name = "tiny-memory"
n_samples = {n}
seed = 1
max_arrivals = 32
[sonar]
record_length_s = 0.001
[snr]
snr_db = [10.0, 30.0]
[solver]
max_order = 1
mechanisms = ["direct", "specular"]
diffuse_rays = 0
amplitude_floor_db = -40.0
[placement]
min_range_m = 0.3
max_range_m = 0.7
half_angle_deg = 10.0
[[objects]]
kind = "sphere"
count = 1
radius_m = [0.02, 0.05]
"""


def _worker_cpu_s(client) -> float:
    import psutil

    def cpu() -> float:
        t = psutil.Process().cpu_times()
        return t.user + t.system

    return sum(client.run(cpu).values())


def stage_breakdown(spec, samples, workdir: Path) -> None:
    """Median CPU per sample of each stage of the in-process task: simulate, labels, write."""
    from acoustisim.datasets.generate import open_or_create
    from acoustisim.datasets.labels import sample_arrays, vocabularies

    vocab = vocabularies(spec)
    writer = open_or_create(spec, workdir / "stages.zarr", vocab).writer()
    cpu: dict[str, list[float]] = {"simulate": [], "labels": [], "write + checksum": []}
    for sample in samples:
        c0 = time.process_time()
        scene, simulation, snr_reference = simulate_sample(spec, sample)
        c1 = time.process_time()
        arrays = sample_arrays(spec, sample, scene, simulation, vocab, snr_reference)
        c2 = time.process_time()
        writer.write(arrays)
        c3 = time.process_time()
        for name, value in zip(cpu, (c1 - c0, c2 - c1, c3 - c2)):
            cpu[name].append(value)
    print("in-process task stages, median CPU per sample: " + ", ".join(
        f"{name} {statistics.median(values) * 1e3:.1f} ms" for name, values in cpu.items()))


def throughput(spec_path: Path, n: int, workdir: Path) -> None:
    from distributed import Client

    spec = dataclasses.replace(load_spec(spec_path), n_samples=n)
    samples = plan_samples(spec)
    simulate_sample(spec, samples[0])  # warm-up: imports, caches
    times = []
    t0, c0 = time.perf_counter(), time.process_time()
    for sample in samples:
        t = time.perf_counter()
        simulate_sample(spec, sample)
        times.append(time.perf_counter() - t)
    loop_s, loop_cpu = time.perf_counter() - t0, time.process_time() - c0
    base_rate = n / loop_s
    print(f"spec {spec_path.name}, {n} samples, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} "
          "(other processes share the CPUs: wall-clock rates are noisy, CPU seconds are not)")
    print(f"baseline plain loop (build + simulate): median {statistics.median(times) * 1e3:.1f} ms/sample, "
          f"{base_rate:.3f} samples/s, {loop_cpu / n * 1e3:.1f} ms CPU/sample")

    stage_breakdown(spec, samples, workdir)
    generate(dataclasses.replace(spec, n_samples=2), workdir / "warm0.zarr", workers=0, progress=False)
    out = workdir / "w0.zarr"
    t0, c0 = time.perf_counter(), time.process_time()
    report = generate(spec, out, workers=0, progress=False)
    cpu = time.process_time() - c0
    print(f"{'in-process (Zarr, no Dask)':27s}: {report.samples_per_s:.3f} samples/s, {cpu / n * 1e3:.1f} ms CPU/sample, "
          f"CPU overhead vs baseline {(cpu / loop_cpu - 1) * 100:+.1f} %, wall {(base_rate / report.samples_per_s - 1) * 100:+.1f} %, "
          f"vs its own simulate CPU {(cpu / report.simulate_cpu_s - 1) * 100:+.1f} %")
    rates, overheads, own = {}, {}, {}
    for workers in (1, 2):
        cluster = _local_cluster(workers)  # the one generate() starts by default
        with Client(cluster) as client:
            warm = dataclasses.replace(spec, n_samples=2 * workers)
            generate(warm, workdir / f"warm{workers}.zarr", client=client, progress=False)  # imports, caches
            c0, w0 = time.process_time(), _worker_cpu_s(client)
            report = generate(spec, workdir / f"w{workers}.zarr", client=client, progress=False)
            cpu = time.process_time() - c0 + _worker_cpu_s(client) - w0
        cluster.close()
        rates[workers] = report.samples_per_s
        overheads[workers] = cpu / loop_cpu - 1
        own[workers] = cpu / report.simulate_cpu_s - 1
        print(f"{'LocalCluster %d worker(s)' % workers:27s}: {report.samples_per_s:.3f} samples/s, {cpu / n * 1e3:.1f} ms "
              f"CPU/sample (driver + workers), CPU overhead vs baseline {overheads[workers] * 100:+.1f} %, wall "
              f"{(base_rate / report.samples_per_s - 1) * 100:+.1f} %, vs its own simulate CPU {own[workers] * 100:+.1f} %")
    print(f"speed-up 2 workers / 1 worker (wall): {rates[2] / rates[1]:.2f}x (goal >= 1.8x)")
    print(f"overhead Dask+Zarr (1 worker) vs plain loop, CPU: {overheads[1] * 100:+.1f} % (goal < 10 %); vs the "
          f"simulate CPU of the same run: {own[1] * 100:+.1f} % (1 worker), {own[2] * 100:+.1f} % (2 workers)")


def memory(n: int, workdir: Path, workers: int) -> None:
    import psutil

    spec = loads_spec(TINY_SPEC.format(n=n))
    out = workdir / "memory.zarr"
    shutil.rmtree(out, ignore_errors=True)
    me = psutil.Process()
    samples: list[tuple[float, float, int]] = []
    stop = threading.Event()
    print("completed samples -> resident memory of driver + workers (MiB)", flush=True)

    def watch() -> None:
        import zarr

        next_tenth = 1
        while not stop.is_set():
            rss = 0
            for p in [me] + me.children(recursive=True):
                try:
                    rss += p.memory_info().rss
                except psutil.Error:
                    pass
            try:
                done = int(zarr.open_array(str(out / "complete"), mode="r")[:].sum())
            except Exception:  # noqa: BLE001 - store not there yet
                done = 0
            samples.append((time.perf_counter(), rss / 2**20, done))
            while next_tenth <= 10 and done >= next_tenth * n // 10:
                print(f"  {done:6d}  {rss / 2**20:8.1f}", flush=True)
                next_tenth += 1
            stop.wait(1.0)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    report = generate(spec, out, workers=workers, progress=False)
    stop.set()
    thread.join()
    print(f"{n} tiny samples on {report.workers} worker(s): {report.samples_per_s:.2f} samples/s, "
          f"{report.elapsed_s:.0f} s")
    running = [s[1] for s in samples if 0 < s[2] < n]
    if len(running) >= 8:
        q = len(running) // 4
        print(f"median RSS (driver + workers) over the first quarter of the run {statistics.median(running[:q]):.1f} MiB, "
              f"last quarter {statistics.median(running[-q:]):.1f} MiB, max {max(running):.1f} MiB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spec", type=Path, default=ROOT / "examples" / "dataset_spec.toml")
    parser.add_argument("--samples", type=int, default=24)
    parser.add_argument("--memory", type=int, default=0, metavar="N", help="memory mode with N tiny samples")
    parser.add_argument("--workers", type=int, default=2, help="workers of the memory mode")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_dataset_") as tmp:
        if args.memory:
            memory(args.memory, Path(tmp), args.workers)
        else:
            throughput(args.spec, args.samples, Path(tmp))


if __name__ == "__main__":
    main()
