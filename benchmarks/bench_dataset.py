"""Dataset generation throughput, Dask + Zarr overhead and memory over a long run.

Usage
-----
    python benchmarks/bench_dataset.py [--samples 24] [--spec examples/dataset_spec.toml]
    python benchmarks/bench_dataset.py --memory 10000 --tiny   # driver/worker RSS over 10k samples, ~5 min
    python benchmarks/bench_dataset.py --memory 10000 --csv /tmp/rss.csv   # the default spec: ~75 min
    python benchmarks/bench_dataset.py --crossover [--sizes 4 8 16 32 64] [--repeats 3]   # ~10 min

Default mode, all measured in this run on the same samples of the spec:
  - baseline: build + simulate each sample in a plain Python loop (no Dask, no Zarr), run
    twice, first and last, and averaged (the CPU cost of the same work drifts by 10-20 %
    between phases when other processes share the cores);
  - in-process generate (``--workers 0``): the baseline plus labels, checksums, Zarr writes;
  - Dask LocalCluster with 1 and 2 worker processes (as ``generate --workers N`` starts it),
    each warmed up first on one chunk per worker (imports, caches: cluster start-up is not
    per-sample cost). With 2 workers the last 2 chunks run as one task per sample plus a write
    (``acoustisim.datasets.generate.split_tail``): 24 samples are 6 chunks, and whole-chunk
    tasks alone would leave one worker idle for up to a chunk's time at the end.
For each mode: samples per second (wall); CPU per sample of the driver (client, scheduler,
nannies: one process) plus the workers, during the run; its overhead against the baseline's
CPU and against the simulate CPU its own tasks reported (same run, same machine state: the
most robust figure); samples per worker-CPU-second; how busy the workers were (task wall
time / run wall time) and how much of a core the OS gave them while busy (task CPU / task
wall).

Speed-up of 2 workers over 1 (goal >= 1.8x), two ways:
  - wall: the ratio of the measured samples/s (needs two idle cores to mean anything);
  - CPU projection for an idle 2-core machine: each run's wall time is taken as the
    makespan of its tasks' measured CPU times (plus their share of the workers' CPU outside
    tasks) handed in submission order to the worker free first, or all CPU (driver +
    workers) / min(2, workers + 1) if larger (the driver sharing the cores). It is what the
    wall ratio becomes when nothing else runs, as long as the workers never wait for the
    driver: the "workers busy" column shows whether they did. (On a loaded machine the
    measured assignment of tasks to workers follows the CPU share the OS gave each, so it
    is replayed rather than taken as measured.)

Crossover mode: when does a cluster pay for its start-up? For each dataset size N, the wall
time of the whole ``generate`` call as a user sees it (first line to return) in three modes:
in this process (``--workers 0``); a LocalCluster of 2 workers started and closed by the call
(``--workers 2``, the default on a 2-core machine); and a running ``dask scheduler`` with two
``dask worker`` processes on this machine (``--scheduler ADDRESS``), started once by the
benchmark beforehand (its start-up, and the first run on cold workers that imports the
simulator in each, are printed apart). Medians of ``--repeats`` runs; a straight line
T = a + b N fitted to each mode's medians gives its fixed cost a and its cost per sample b, and
the crossover N* = (a_cluster - a_in_process) / (b_in_process - b_cluster): below N* samples the
plain in-process run finishes first.

Memory mode: generates N samples of the spec on a LocalCluster of ``--workers`` workers (as
``generate --workers N`` starts it) and samples the resident set size of the driver and of
each worker every ``--interval`` seconds into ``--csv``; prints it at 1,000, 3,000 and N
samples (the last poll before the cluster closes) and at each tenth of the run. ``--tiny``
uses :data:`TINY_SPEC` instead of ``--spec``: a 0.5 ms record, direct path only, at most one
object (~50 ms a sample), in chunks of 4 like the default spec, so that the run has as many
tasks (what the driver handles) as a default-spec run of the same N, in minutes instead of an
hour.
"""

from __future__ import annotations

import argparse
import csv
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

from acoustisim.datasets.generate import local_cluster, generate, simulate_sample, split_tail  # noqa: E402
from acoustisim.datasets.sampling import plan_samples  # noqa: E402
from acoustisim.datasets.spec import load_spec  # noqa: E402

N_CORES = 2
"""Cores of the machine the CPU projection is for (the issue's 2-core machine)."""
IDLE_S = 2.0
"""Seconds the warmed-up cluster is left idle to measure its background CPU."""
MEMORY_CHECKPOINTS = (1000, 3000)
"""Completed-sample counts (and N) at which the memory mode prints the resident memory."""
TINY_SPEC = """
[dataset]
name = "memory-tiny"
n_samples = 10000
seed = 1
max_arrivals = 8
samples_per_chunk = 4
[sonar]
x_m = [0.8, 1.2]
y_m = [1.2, 1.8]
record_length_s = 0.0005
[solver]
max_order = 1
mechanisms = ["direct"]
diffuse_rays = 0
[placement]
min_range_m = 0.3
max_range_m = 1.2
half_angle_deg = 15.0
[[objects]]
kind = "sphere"
count = [0, 1]
radius_m = [0.02, 0.05]
"""
"""The memory mode's cheap spec (``--tiny``): the driver's work per task is the same as with the
default spec; the simulator's is ~5x less."""


def _worker_cpu_s(client) -> dict[str, float]:
    """CPU time (s) of each worker process, by worker address."""
    import psutil

    def cpu() -> float:
        t = psutil.Process().cpu_times()
        return t.user + t.system

    return client.run(cpu)


def plain_loop(spec, samples) -> tuple[float, float, list[float], list[float]]:
    """Wall (s), CPU (s), per-sample wall times and per-sample CPU times of building +
    simulating every sample."""
    times, cpu_times = [], []
    t0, c0 = time.perf_counter(), time.process_time()
    for sample in samples:
        t, c = time.perf_counter(), time.process_time()
        simulate_sample(spec, sample)
        times.append(time.perf_counter() - t)
        cpu_times.append(time.process_time() - c)
    return time.perf_counter() - t0, time.process_time() - c0, times, cpu_times


def balance_bound(costs: list[float], chunk: int, workers: int, split: int) -> float:
    """Speed-up over one worker that the task granularity alone allows ``workers`` workers.

    ``costs`` are the samples' CPU times in order; the tasks are whole chunks of ``chunk``
    samples except the last ``split`` chunks, one task per sample (writes neglected), handed
    in order to the worker free first, as the scheduler does.
    """
    starts = list(range(0, len(costs), chunk))
    whole = starts[:len(starts) - split] if split else starts
    tasks = [sum(costs[a:a + chunk]) for a in whole] + costs[len(whole) * chunk:]
    free = [0.0] * workers
    for cost in tasks:
        free[free.index(min(free))] += cost
    return sum(costs) / max(free)


def _loop_part(spec_path: str, n: int, part: int, parts: int, barrier) -> tuple[float, float, int]:
    """In a fresh process: warm up, wait for the other parts (so that they overlap), then
    build and simulate every ``parts``-th sample from ``part``; CPU (s), wall (s) and count."""
    spec = dataclasses.replace(load_spec(spec_path), n_samples=n)
    samples = plan_samples(spec)
    simulate_sample(spec, samples[0])  # imports, caches
    barrier.wait()
    wall, cpu, _, _ = plain_loop(spec, samples[part::parts])
    return cpu, wall, len(samples[part::parts])


def parallel_plain_loops(spec_path: Path, n: int, parts: int = 2) -> tuple[float, float]:
    """Two plain loops side by side in two processes: (CPU s per sample, samples/s).

    The ceiling of any 2-process speed-up on this machine: the per-sample CPU of the
    simulator itself rises when two run at once (shared caches and memory bandwidth, other
    tenants), whatever schedules them.
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    context = multiprocessing.get_context("spawn")
    with context.Manager() as manager, ProcessPoolExecutor(parts, mp_context=context) as pool:
        barrier = manager.Barrier(parts)
        results = list(pool.map(_loop_part, [str(spec_path)] * parts, [n] * parts, range(parts), [parts] * parts,
                                [barrier] * parts))
    cpu = sum(r[0] for r in results)
    return cpu / n, n / max(r[1] for r in results)


@dataclasses.dataclass(frozen=True)
class ModeRun:
    """One generate run's figures."""

    label: str
    workers: int
    n: int
    wall_s: float
    samples_per_s: float
    driver_cpu_s: float
    worker_cpu_s: tuple[float, ...]  # per worker process (empty in-process)
    simulate_cpu_s: float
    task_cpu_s: float
    task_wall_s: float
    task_cpu_list_s: tuple[float, ...] = ()
    idle_cores: float = 0.0
    """CPU (cores) the driver and workers of this mode burn while idle (measured before the run)."""

    @property
    def cpu_s(self) -> float:
        return self.driver_cpu_s + sum(self.worker_cpu_s)

    def projected_wall_s(self) -> float:
        """Wall time on an idle N_CORES machine (see the module docstring)."""
        if not self.worker_cpu_s:
            return self.cpu_s
        # Each task costs its measured CPU plus its share of the workers' CPU outside tasks;
        # tasks go, in submission order, to the worker free first (what the scheduler does
        # with every worker busy and one task queued each).
        outside = (sum(self.worker_cpu_s) - self.task_cpu_s) / max(len(self.task_cpu_list_s), 1)
        free = [0.0] * self.workers
        for cost in self.task_cpu_list_s:
            k = free.index(min(free))
            free[k] += cost + outside
        return max(max(free), self.cpu_s / min(N_CORES, self.workers + 1))

    def idle_machine_cpu_s(self) -> float:
        """CPU of the run with the idle background CPU rescaled to the projected wall time."""
        return self.cpu_s - self.idle_cores * (self.wall_s - self.projected_wall_s())

    def line(self, baseline_cpu_s: float) -> str:
        workers_cpu = sum(self.worker_cpu_s) or self.task_cpu_s
        busy = self.task_wall_s / (self.wall_s * max(self.workers, 1))
        share = self.task_cpu_s / self.task_wall_s
        return (f"{self.label:26s}: {self.samples_per_s:6.3f} samples/s, {self.cpu_s / self.n * 1e3:6.1f} ms CPU/sample; "
                f"overhead vs baseline CPU {(self.cpu_s / baseline_cpu_s - 1) * 100:+5.1f} %, vs own simulate CPU "
                f"{(self.cpu_s / self.simulate_cpu_s - 1) * 100:+5.1f} %; {self.n / workers_cpu:.3f} samples per "
                f"worker-CPU-s; workers busy {busy * 100:3.0f} % of the run, getting {share:.2f} core while busy")

    def breakdown(self) -> str:
        """Where the CPU went, ms per sample."""
        per = 1e3 / self.n
        parts = [f"simulate {self.simulate_cpu_s * per:.1f}", f"rest of the tasks (labels, checksums, Zarr "
                 f"writes) {(self.task_cpu_s - self.simulate_cpu_s) * per:.1f}"]
        if self.worker_cpu_s:
            outside = sum(self.worker_cpu_s) - self.task_cpu_s
            parts += [f"workers outside tasks (Dask worker) {outside * per:.1f}",
                      f"driver (client, scheduler, nannies) {self.driver_cpu_s * per:.1f}",
                      f"idle background of both {self.idle_cores * self.wall_s * per:.1f} "
                      f"({self.idle_cores * 100:.2f} % of a core x {self.wall_s:.1f} s)"]
        else:
            parts += [f"driver outside tasks {(self.driver_cpu_s - self.task_cpu_s) * per:.1f}"]
        return f"  {self.label} CPU, ms/sample: " + ", ".join(parts)


def run_mode(spec, workdir: Path, workers: int) -> ModeRun:
    """Generate the spec into a fresh store with ``workers`` (0: in-process) and measure it."""
    from distributed import Client

    if workers == 0:
        generate(dataclasses.replace(spec, n_samples=spec.samples_per_chunk), workdir / "warm0.zarr", workers=0,
                 progress=False)
        report = generate(spec, workdir / "w0.zarr", workers=0, progress=False)
        worker_cpu: tuple[float, ...] = ()
        idle_cores = 0.0
    else:
        cluster = local_cluster(workers)  # the one generate() starts by default
        with Client(cluster) as client:
            warm = dataclasses.replace(spec, n_samples=spec.samples_per_chunk * workers)
            generate(warm, workdir / f"warm{workers}.zarr", client=client, progress=False)  # imports, caches
            idle = _worker_cpu_s(client), time.process_time(), time.perf_counter()
            time.sleep(IDLE_S)
            before = _worker_cpu_s(client)
            idle_cores = (sum(before.values()) - sum(idle[0].values()) + time.process_time() - idle[1]) / (
                time.perf_counter() - idle[2])
            report = generate(spec, workdir / f"w{workers}.zarr", client=client, progress=False)
            after = _worker_cpu_s(client)
        cluster.close()
        worker_cpu = tuple(after[k] - before[k] for k in before)
    busy = report.worker_busy_s.values()
    label = "in-process (Zarr, no Dask)" if workers == 0 else f"LocalCluster {workers} worker(s)"
    return ModeRun(label, workers, report.n_generated, report.elapsed_s, report.samples_per_s, report.driver_cpu_s,
                   worker_cpu, report.simulate_cpu_s, report.task_cpu_s, sum(b["elapsed_s"] for b in busy),
                   report.task_cpu_list_s, idle_cores if workers else 0.0)


def throughput(spec_path: Path, n: int, workdir: Path) -> None:
    t_start = time.perf_counter()
    spec = dataclasses.replace(load_spec(spec_path), n_samples=n)
    samples = plan_samples(spec)
    simulate_sample(spec, samples[0])  # warm-up: imports, caches
    print(f"spec {spec_path.name}, {n} samples in chunks of {spec.samples_per_chunk}, {os.cpu_count()} CPUs, load "
          f"average {os.getloadavg()[0]:.2f} (other processes share the CPUs: wall-clock rates are noisy, CPU "
          "seconds much less so)", flush=True)
    first = plain_loop(spec, samples)
    runs = {workers: run_mode(spec, workdir, workers) for workers in (0, 1, 2)}
    pair_cpu, pair_rate = parallel_plain_loops(spec_path, n)
    last = plain_loop(spec, samples)
    loop_wall, loop_cpu = (first[0] + last[0]) / 2, (first[1] + last[1]) / 2
    base_rate = n / loop_wall
    print(f"{'baseline plain loop':26s}: {base_rate:6.3f} samples/s, {loop_cpu / n * 1e3:6.1f} ms CPU/sample "
          f"(first {first[1] / n * 1e3:.1f}, last {last[1] / n * 1e3:.1f}; median wall "
          f"{statistics.median(first[2] + last[2]) * 1e3:.1f} ms/sample)")
    for run in runs.values():
        print(run.line(loop_cpu))
        print(run.breakdown())
    print(f"{'2 plain loops side by side':26s}: {pair_rate:6.3f} samples/s, {pair_cpu * 1e3:6.1f} ms CPU/sample "
          f"({(pair_cpu * n / loop_cpu - 1) * 100:+.1f} % vs one loop: the machine's own cost of running two at once)")
    r1, r2 = runs[1], runs[2]
    n_chunks = -(-n // spec.samples_per_chunk)
    print(f"ceiling of a 2-process speed-up here (2 x one loop's CPU per sample / two loops' CPU per sample): "
          f"{2 * loop_cpu / n / pair_cpu:.2f}x; 2 plain loops / 1 plain loop, wall: {pair_rate / base_rate:.2f}x")
    sim1, sim2 = r1.simulate_cpu_s / r1.n, r2.simulate_cpu_s / r2.n
    print(f"simulator's own CPU per sample (inside the tasks): {sim1 * 1e3:.1f} ms (1 worker), {sim2 * 1e3:.1f} ms "
          f"(2 workers, {(sim2 / sim1 - 1) * 100:+.1f} % vs 1 worker); two plain loops side by side "
          f"{(pair_cpu * n / loop_cpu - 1) * 100:+.1f} % vs one loop")
    wall_ratio = r2.samples_per_s / r1.samples_per_s
    print(f"speed-up 2 workers / 1 worker: wall {wall_ratio:.2f}x ({wall_ratio / (pair_rate / base_rate) * 100:.0f} % "
          f"of the 2-plain-loop wall ratio), CPU projection for an idle {N_CORES}-core machine "
          f"{r1.projected_wall_s() / r2.projected_wall_s():.2f}x (goal >= 1.8x); samples "
          f"per worker-CPU-s {r1.n / sum(r1.worker_cpu_s):.3f} (1 worker) vs {r2.n / sum(r2.worker_cpu_s):.3f} "
          "(2 workers)")
    costs = [min(a, b) for a, b in zip(first[3], last[3])]  # the baseline's per-sample CPU, less noisy of two
    print(f"bound from the task granularity alone (the baseline's per-sample CPU, tasks to the worker free first): "
          f"2 workers / 1 worker {balance_bound(costs, spec.samples_per_chunk, 2, split_tail(n_chunks, 2)):.2f}x with "
          f"the last {split_tail(n_chunks, 2)} chunks split into sample tasks (as generate does), "
          f"{balance_bound(costs, spec.samples_per_chunk, 2, 0):.2f}x with whole-chunk tasks only")
    print(f"overhead Dask+Zarr vs plain loop, CPU: {(r1.cpu_s / loop_cpu - 1) * 100:+.1f} % (1 worker), "
          f"{(r2.cpu_s / loop_cpu - 1) * 100:+.1f} % (2 workers) (goal < 10 %); vs the simulate CPU of the same run: "
          f"{(r1.cpu_s / r1.simulate_cpu_s - 1) * 100:+.1f} % (1 worker), {(r2.cpu_s / r2.simulate_cpu_s - 1) * 100:+.1f} % "
          f"(2 workers)")
    print("projected to an idle machine (the servers' idle background CPU, measured, scaled to the projected wall "
          f"time): {(r1.idle_machine_cpu_s() / r1.simulate_cpu_s - 1) * 100:+.1f} % (1 worker), "
          f"{(r2.idle_machine_cpu_s() / r2.simulate_cpu_s - 1) * 100:+.1f} % (2 workers) vs the simulate CPU of the same "
          "run")
    print(f"benchmark wall time {time.perf_counter() - t_start:.0f} s")


def _start_dask_cluster(workdir: Path, n_workers: int) -> tuple[str, list, float]:
    """A ``dask scheduler`` and ``n_workers`` ``dask worker`` processes (one thread each, with
    their nannies, as a user starts them), in their own directory.

    Returns
    -------
    address : str
    processes : list of subprocess.Popen
    startup_s : float
        From launching the scheduler until every worker is connected.
    """
    import json
    import subprocess

    from distributed import Client

    home = workdir / "cluster"
    home.mkdir()
    scheduler_file = home / "scheduler.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    quiet = dict(cwd=home, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    t0 = time.perf_counter()
    processes = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--port", "0",
                                   "--dashboard-address", ":0", "--scheduler-file", str(scheduler_file)], **quiet)]
    try:
        address = None
        while address is None:  # the file appears before it is written whole
            time.sleep(0.05)
            try:
                address = json.loads(scheduler_file.read_text())["address"]
            except (OSError, ValueError, KeyError):
                address = None
        for _ in range(n_workers):
            processes.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                               "--nthreads", "1", "--dashboard-address", ":0"], **quiet))
        with Client(address) as client:
            client.wait_for_workers(n_workers, timeout=120)
    except BaseException:
        _stop(processes)
        raise
    return address, processes, time.perf_counter() - t0


def _stop(processes: list) -> None:
    import signal

    for process in reversed(processes):
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=20)
        except Exception:  # noqa: BLE001 - a process that ignores SIGTERM
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def _fit_line(sizes: list[int], times: list[float]) -> tuple[float, float]:
    """Least-squares a, b of T = a + b N."""
    import numpy as np

    b, a = np.polyfit(np.asarray(sizes, float), np.asarray(times, float), 1)
    return float(a), float(b)


def crossover(spec_path: Path, sizes: list[int], repeats: int, workdir: Path) -> None:
    """Wall time of whole generate calls per mode and size; the fitted fixed and per-sample
    costs and the crossover sizes (see the module docstring)."""
    import signal

    # A kill (SIGTERM) still stops the cluster started below (the finally clause).
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    base = load_spec(spec_path)
    # This process's own first run: imports and numba's cache loads, not a per-run cost.
    generate(dataclasses.replace(base, n_samples=2), workdir / "warm.zarr", workers=0, progress=False)
    address, processes, cluster_startup = _start_dask_cluster(workdir, 2)
    print(f"spec {spec_path.name}, chunks of {base.samples_per_chunk}, sizes {sizes}, {repeats} repeat(s); "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at the start", flush=True)
    print(f"dask scheduler + 2 dask workers: {cluster_startup:.1f} s from launch until both workers are connected",
          flush=True)
    modes = {"in-process": dict(workers=0), "LocalCluster(2)": dict(workers=2), "scheduler+2 workers": {}}
    times: dict[str, dict[int, list[float]]] = {mode: {n: [] for n in sizes} for mode in modes}
    startups: dict[str, list[float]] = {mode: [] for mode in modes}
    run = 0
    try:
        # The first run on the fresh workers imports the simulator in each (once per worker life).
        t0 = time.perf_counter()
        generate(dataclasses.replace(base, n_samples=2), workdir / "cold.zarr", scheduler=address, progress=False)
        print(f"first run on the cold workers (2 samples, imports in each worker): {time.perf_counter() - t0:.1f} s",
              flush=True)
        for _ in range(repeats):
            for n in sizes:
                spec = dataclasses.replace(base, n_samples=n)
                for mode, kwargs in modes.items():
                    run += 1
                    out = workdir / f"run{run}.zarr"
                    t0 = time.perf_counter()
                    report = generate(spec, out, scheduler=address if not kwargs else None, progress=False, **kwargs)
                    times[mode][n].append(time.perf_counter() - t0)
                    startups[mode].append(report.startup_s)
                    assert report.n_complete == n
                    shutil.rmtree(out)
    finally:
        _stop(processes)
    print(f"\n{'samples':>8s} " + " ".join(f"{mode:>20s}" for mode in modes) + "   (median wall s of the whole call)")
    medians = {mode: [statistics.median(times[mode][n]) for n in sizes] for mode in modes}
    for k, n in enumerate(sizes):
        print(f"{n:8d} " + " ".join(f"{medians[mode][k]:20.2f}" for mode in modes))
    fits = {mode: _fit_line(sizes, medians[mode]) for mode in modes}
    for mode, (a, b) in fits.items():
        print(f"{mode:>20s}: T = {a:5.2f} s + {b * 1e3:6.1f} ms x N (fit); start-up (planning, store, cluster, "
              f"warm-up) median {statistics.median(startups[mode]):.2f} s")
    a0, b0 = fits["in-process"]
    for mode in list(modes)[1:]:
        a, b = fits[mode]
        if b >= b0:
            print(f"{mode}: no crossover (no faster per sample than in-process here)")
        else:
            print(f"{mode}: faster than in-process above N* = {(a - a0) / (b0 - b):.0f} samples "
                  f"({(a - a0):.1f} s more fixed cost, {(b0 - b) * 1e3:.0f} ms less per sample)")
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


def memory(spec_path: Path | None, n: int, workdir: Path, workers: int, csv_path: Path | None,
           interval_s: float) -> None:
    """RSS over an ``n``-sample run of the spec at ``spec_path`` (None: :data:`TINY_SPEC`)."""
    import psutil

    from acoustisim.datasets.spec import loads_spec

    base = loads_spec(TINY_SPEC, "TINY_SPEC") if spec_path is None else load_spec(spec_path)
    spec = dataclasses.replace(base, n_samples=n)
    out = workdir / "memory.zarr"
    shutil.rmtree(out, ignore_errors=True)
    me = psutil.Process()
    rows: list[tuple[float, int, float, float, float]] = []  # elapsed, done, driver, max worker, total (MiB)
    stop = threading.Event()
    handle = open(csv_path, "w", newline="") if csv_path else None  # noqa: SIM115 - closed below
    writer = csv.writer(handle) if handle else None
    if writer:
        writer.writerow(["elapsed_s", "n_complete", "rss_driver_mib", "rss_worker_max_mib", "rss_workers_mib",
                         "rss_total_mib"])
    print(f"spec {'TINY_SPEC' if spec_path is None else spec_path.name}, {n} samples in chunks of "
          f"{spec.samples_per_chunk}, {workers} workers: completed samples -> resident memory (MiB) of the driver "
          "(client, scheduler, nannies), the largest worker, all processes", flush=True)
    checkpoints = sorted(c for c in MEMORY_CHECKPOINTS if c < n)
    at_checkpoint: dict[int, tuple[float, int, float, float, float]] = {}
    t0 = time.perf_counter()

    def watch() -> None:
        next_tenth = 1
        while not stop.is_set():
            driver = me.memory_info().rss
            worker_rss = []
            for p in me.children(recursive=True):
                try:
                    if "spawn_main" in " ".join(p.cmdline()):
                        worker_rss.append(p.memory_info().rss)
                except psutil.Error:
                    pass
            try:  # a chunk file of `complete` exists once its chunk is complete: count the files, read none
                done = min(n, sum(1 for _ in os.scandir(out / "complete" / "c")) * spec.samples_per_chunk)
            except OSError:  # store or first chunk not there yet
                done = 0
            mib = 2.0**20
            row = (time.perf_counter() - t0, done, driver / mib, max(worker_rss, default=0) / mib,
                   (driver + sum(worker_rss)) / mib)
            rows.append(row)
            if writer:
                writer.writerow([f"{row[0]:.0f}", done, f"{row[2]:.1f}", f"{row[3]:.1f}", f"{sum(worker_rss) / mib:.1f}",
                                 f"{row[4]:.1f}"])
                handle.flush()
            printed = False
            while next_tenth <= 10 and done >= next_tenth * n // 10:
                next_tenth += 1
                printed = True
            for c in checkpoints:
                if done >= c and c not in at_checkpoint and worker_rss:
                    at_checkpoint[c] = row
                    printed = True
            if printed:
                print(f"  {done:6d}  driver {row[2]:7.1f}  worker max {row[3]:7.1f}  total {row[4]:7.1f}", flush=True)
            stop.wait(interval_s)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    try:
        report = generate(spec, out, workers=workers, progress=False)
    finally:
        stop.set()
        thread.join()
        if handle:
            handle.close()
    print(f"{n} samples on {report.workers} worker(s): {report.samples_per_s:.2f} samples/s, {report.elapsed_s:.0f} s")
    alive = [r for r in rows if r[3] > 0]  # polls while the workers ran (not the card's final read-back)
    if alive and alive[-1][1] > max(at_checkpoint, default=0):
        at_checkpoint[alive[-1][1]] = alive[-1]  # the last poll before the cluster closed, ~N samples
    if at_checkpoint:
        first = at_checkpoint[min(at_checkpoint)]
        print("RSS (MiB) at completed samples: " + "; ".join(
            f"{c}: driver {r[2]:.1f}, largest worker {r[3]:.1f}, total {r[4]:.1f}"
            for c, r in sorted(at_checkpoint.items())))
        last_c = max(at_checkpoint)
        if last_c > min(at_checkpoint):
            last = at_checkpoint[last_c]
            per = 1000.0 / (last[1] - first[1]) if last[1] > first[1] else float("nan")
            print(f"driver growth from {first[1]} to {last[1]} samples: {(last[2] - first[2]) * per:+.2f} MiB per 1000 "
                  f"samples; largest worker {(last[3] - first[3]) * per:+.2f} MiB per 1000 samples")
    running = [r for r in rows if 0 < r[1] < n]
    if len(running) >= 8:
        q = len(running) // 4
        for k, name in ((2, "driver"), (3, "largest worker"), (4, "total")):
            print(f"RSS {name}: median {statistics.median(r[k] for r in running[:q]):.1f} MiB over the first quarter "
                  f"of the run, {statistics.median(r[k] for r in running[-q:]):.1f} MiB over the last, max "
                  f"{max(r[k] for r in running):.1f} MiB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spec", type=Path, default=ROOT / "examples" / "dataset_spec.toml")
    parser.add_argument("--samples", type=int, default=24)
    parser.add_argument("--memory", type=int, default=0, metavar="N", help="memory mode with N samples of the spec")
    parser.add_argument("--workers", type=int, default=2, help="workers of the memory mode")
    parser.add_argument("--tiny", action="store_true", help="memory mode: the cheap TINY_SPEC instead of --spec")
    parser.add_argument("--csv", type=Path, default=None, help="memory mode: write the RSS samples to this CSV")
    parser.add_argument("--interval", type=float, default=5.0, help="memory mode: seconds between RSS samples")
    parser.add_argument("--crossover", action="store_true", help="crossover mode: in-process vs clusters by size")
    parser.add_argument("--sizes", type=int, nargs="+", default=[4, 8, 16, 32, 64], help="crossover mode: sizes")
    parser.add_argument("--repeats", type=int, default=3, help="crossover mode: runs per size and mode")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_dataset_") as tmp:
        if args.crossover:
            crossover(args.spec, args.sizes, args.repeats, Path(tmp))
        elif args.memory:
            memory(None if args.tiny else args.spec, args.memory, Path(tmp), args.workers, args.csv, args.interval)
        else:
            throughput(args.spec, args.samples, Path(tmp))


if __name__ == "__main__":
    main()
