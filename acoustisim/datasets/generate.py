"""Generate a dataset: plan every sample, simulate them on Dask, write them, record completion.

Order of work
-------------
1. Every sample is drawn (:func:`~acoustisim.datasets.sampling.plan_samples`) before anything
   runs: a spec whose placements cannot be satisfied fails here, naming the key.
2. The store is created, or, if it exists, checked to come from the same spec; samples
   already recorded complete are skipped (resume).
3. One task per few missing samples (:func:`samples_per_task`): for each, build the scene,
   simulate, write the sample's own chunks (each chunk file atomically); return the
   checksums. Tasks run on a
   ``distributed.LocalCluster`` of ``workers`` single-threaded processes (default), on the
   scheduler at ``scheduler`` (its workers must see the store's path), or, with
   ``workers=0``, in this process without Dask.
4. The driver alone writes ``complete`` and ``checksum``, in batches, only for tasks that have
   returned. A run killed at any moment leaves no sample marked complete that is not fully
   written; running the same command again does the rest.

At most ``2 x workers`` tasks (each of at most :data:`MAX_SAMPLES_PER_TASK` samples) are in
flight, so memory stays flat however many samples.
"""

from __future__ import annotations

import dataclasses
import logging
import subprocess
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from acoustisim.datasets.labels import Vocabularies, sample_arrays, vocabularies
from acoustisim.datasets.sampling import SampleDescription, build_scene, plan_samples
from acoustisim.datasets.spec import DatasetSpec, SpecError
from acoustisim.datasets.store import (
    LAYOUT_VERSION,
    SAMPLE_FIELDS,
    DatasetStore,
    DatasetStoreError,
    SampleWriter,
    StoreShape,
    create_store,
)
from acoustisim.errors import InputError

FLUSH_INTERVAL_S = 1.0
"""Longest time completed samples wait before the driver records them."""
FLUSH_BATCH = 256
"""Most completed samples recorded in one write."""
MAX_SAMPLES_PER_TASK = 4
"""Samples one Dask task makes in turn. The driver (which hosts a LocalCluster's scheduler)
spends ~10-20 ms of CPU per task whatever its size (measured with 0.25 s sleeping tasks on
this machine), ~5-10 % of a default-spec sample; four samples per task divide that by four."""


@dataclass(frozen=True)
class SampleResult:
    """What a task returns: the sample it wrote and that sample's checksum."""

    index: int
    checksum: int
    elapsed_s: float
    simulate_cpu_s: float = 0.0
    """CPU time (s) of the thread that built and simulated the sample (the plain simulator's
    cost: the reference of the overhead figures in ``benchmarks/bench_dataset.py``)."""


@dataclass(frozen=True)
class GenerateReport:
    """Outcome of :func:`generate`.

    Attributes
    ----------
    path : str
    n_samples : int
    n_skipped : int
        Samples already complete before this run (resume).
    n_generated : int
        Samples made by this run.
    n_complete : int
        Samples complete now.
    elapsed_s : float
        Wall time of the simulation phase (s), cluster start-up excluded.
    startup_s : float
        Planning, store creation and cluster start-up (s).
    samples_per_s : float
        ``n_generated / elapsed_s``.
    workers : int
        Worker processes used (0: in-process; the cluster's count with a scheduler).
    scheduler : str
        "in-process", "local-cluster" or the scheduler address.
    simulate_cpu_s : float
        Sum over the samples made by this run of the CPU time (s) their task's thread spent
        building and simulating them (the rest of the run's CPU is the dataset machinery).
    """

    path: str
    n_samples: int
    n_skipped: int
    n_generated: int
    n_complete: int
    elapsed_s: float
    startup_s: float
    samples_per_s: float
    workers: int
    scheduler: str
    simulate_cpu_s: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def code_version() -> str:
    """``acoustisim <version>`` plus the git commit of the source tree when there is one."""
    import acoustisim

    version = f"acoustisim {acoustisim.__version__}"
    try:
        commit = subprocess.run(
            ["git", "describe", "--always", "--dirty", "--abbrev=12"],
            cwd=Path(acoustisim.__file__).parent, capture_output=True, text=True, timeout=5, check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = ""
    return f"{version} ({commit})" if commit else version


SNR_TARGET, SNR_STRONGEST_ECHO, SNR_NOT_SET = 0, 1, -1
"""``sample_values[snr_reference]``: what the drawn SNR refers to."""


def strongest_echo_path(paths: Any, record_length_s: float) -> int | None:
    """``path_id`` of the strongest non-direct arrival seen inside the record on all three
    channels (ranked by its weakest channel), or None."""
    from acoustisim.propagation.paths import PathKind

    arrivals = paths.arrivals()
    keep = (arrivals["kind"] != PathKind.DIRECT) & (arrivals["delay_s"] < record_length_s)
    arrivals = arrivals[keep]
    if arrivals.size == 0:
        return None
    ids, inverse = np.unique(arrivals["path_id"], return_inverse=True)
    amplitude = np.zeros((ids.size, 3))
    np.maximum.at(amplitude, (inverse, arrivals["channel"].astype(np.int64)), np.abs(arrivals["amplitude"]))
    weakest = amplitude.min(axis=1)
    return int(ids[np.argmax(weakest)]) if weakest.max() > 0 else None


def simulate_sample(spec: DatasetSpec, sample: SampleDescription) -> tuple[Any, Any, int]:
    """Build and simulate one drawn sample.

    The drawn SNR is set on the strongest target echo (``simulate``'s default). A sample
    without a target echo inside the record on every channel (no object, objects out of the
    beam or beyond the record) sets it on its strongest non-direct echo inside the record
    instead; a sample with no echo at all in the record keeps the receiver chain's own noise
    (its stored ``snr_db`` is then NaN).

    Returns
    -------
    scene : acoustisim.scene.Scene
    simulation : acoustisim.simulation.Simulation
    snr_reference : int
        :data:`SNR_TARGET`, :data:`SNR_STRONGEST_ECHO` or :data:`SNR_NOT_SET`.
    """
    from acoustisim.propagation import solve
    from acoustisim.propagation.config import SolverConfig
    from acoustisim.simulation import simulate

    scene = build_scene(spec, sample)
    config = SolverConfig(**dict(spec.solver), seed=sample.simulation_seed % (2**31))
    with warnings.catch_warnings():
        # "record too short for N arrivals": expected in a dataset; those arrivals stay in the truth.
        warnings.simplefilter("ignore", UserWarning)
        paths = solve(scene, None, config)
        options = dict(solver_config=config, seed=sample.simulation_seed, n_pings=spec.n_pings, paths=paths)
        if sample.snr_db is not None:
            try:
                return scene, simulate(scene, snr_db=sample.snr_db, **options), SNR_TARGET
            except InputError as exc:
                if not str(exc).startswith(("snr_echo", "snr_db")):  # anything but "no usable target echo"
                    raise
            echo = strongest_echo_path(paths, scene.sonar.record_length_s)
            if echo is not None:
                try:
                    return scene, simulate(scene, snr_db=sample.snr_db, snr_echo=echo, **options), SNR_STRONGEST_ECHO
                except InputError as exc:
                    if not str(exc).startswith(("snr_echo", "snr_db")):
                        raise
        return scene, simulate(scene, **options), SNR_NOT_SET


def make_sample(spec: DatasetSpec, sample: SampleDescription, writer: SampleWriter, vocab: Vocabularies) -> SampleResult:
    """The task: simulate one sample, write its chunks, return its checksum."""
    start, cpu_start = time.perf_counter(), time.thread_time()
    scene, simulation, snr_reference = simulate_sample(spec, sample)
    simulate_cpu = time.thread_time() - cpu_start  # the simulator is single-threaded (checked: = process time)
    arrays = sample_arrays(spec, sample, scene, simulation, vocab, snr_reference)
    checksum = writer.write(arrays)
    return SampleResult(sample.index, checksum, time.perf_counter() - start, simulate_cpu)


def make_samples(spec: DatasetSpec, samples: list[SampleDescription], writer: SampleWriter,
                 vocab: Vocabularies) -> list[SampleResult]:
    """The Dask task: :func:`make_sample` for a few samples in turn (fewer tasks, less overhead).

    Raises
    ------
    RuntimeError
        Naming the sample that failed (the batch's earlier samples are written but, as the
        task does not return, not recorded: a resume redoes them identically).
    """
    results = []
    for sample in samples:
        try:
            results.append(make_sample(spec, sample, writer, vocab))
        except Exception as exc:
            raise RuntimeError(f"sample {sample.index}: {type(exc).__name__}: {exc}") from exc
    return results


def samples_per_task(n_todo: int, n_workers: int) -> int:
    """Samples per Dask task: up to :data:`MAX_SAMPLES_PER_TASK`, while keeping at least about
    four tasks per worker (load balance at the end of a short run)."""
    return max(1, min(MAX_SAMPLES_PER_TASK, -(-n_todo // (4 * max(n_workers, 1)))))


def store_shape(spec: DatasetSpec) -> StoreShape:
    """Array sizes of a spec's store."""
    from scenes.builders import default_sonar

    sonar = dataclasses.replace(default_sonar(), **dict(spec.sonar.overrides))
    return StoreShape(spec.n_samples, spec.n_pings, sonar.n_samples, spec.max_objects, spec.max_arrivals)


def initial_card(spec: DatasetSpec, vocab: Vocabularies) -> dict[str, Any]:
    """The card written when a store is created."""
    return {
        "layout_version": LAYOUT_VERSION,
        "name": spec.name,
        "spec": spec.to_dict(),
        "code_version": code_version(),
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "status": "incomplete",
        "counts": {"n_samples": spec.n_samples, "n_complete": 0},
        "vocabularies": {k: list(v) for k, v in vocab.as_dict().items()},
    }


def open_or_create(spec: DatasetSpec, out: str | Path, vocab: Vocabularies) -> DatasetStore:
    """Create the store, or open an existing one after checking it comes from the same spec."""
    out = Path(out)
    if out.exists():
        store = DatasetStore(out, mode="r+")
        stored = store.card.get("spec")
        if stored != spec.to_dict():
            stored = stored or {}
            new = spec.to_dict()
            key = next((k for k in new if stored.get(k) != new.get(k)), "spec")
            raise DatasetStoreError(
                f"{out}: made from a different spec ({key} = {stored.get(key)!r} there, {new.get(key)!r} now); "
                "resume needs the same spec, or choose another --out"
            )
        version = code_version()
        if store.card.get("code_version") != version:
            versions = list(store.card.get("resumed_with", []))
            store.update_card(resumed_with=sorted(set(versions + [version])))
        return store
    create_store(out, store_shape(spec), initial_card(spec, vocab), vocab.as_dict())
    return DatasetStore(out, mode="r+")


def dataset_card_summary(store: DatasetStore, spec: DatasetSpec, bins: int = 10) -> dict[str, Any]:
    """Counts and the SNR histogram over the complete samples (read back from the store)."""
    mask = store.complete_mask()
    values = np.asarray(store.array("sample_values")[:])[mask]
    objects = np.asarray(store.array("objects")[:, :, 1])[mask]  # class codes
    col = {name: k for k, name in enumerate(SAMPLE_FIELDS)}
    classes = spec.class_names
    class_counts = np.bincount(objects[np.isfinite(objects)].astype(np.int64), minlength=len(classes))
    counts: dict[str, Any] = {
        "n_samples": int(mask.size),
        "n_complete": int(mask.sum()),
        "n_objects": int(np.nansum(values[:, col["n_objects"]])),
        "objects_per_class": {name: int(c) for name, c in zip(classes, class_counts)},
        "arrivals_per_kind": {k: int(np.nansum(values[:, col[f"n_{k}"]])) for k in ("direct", "specular", "edge", "diffuse")},
        "n_arrivals_stored": int(np.nansum(values[:, col["n_arrivals"]])),
        "n_arrivals_total": int(np.nansum(values[:, col["n_arrivals_total"]])),
    }
    snr = values[:, col["snr_db"]]
    snr = snr[np.isfinite(snr)]
    if spec.snr_db is None or snr.size == 0:
        histogram = {"edges_db": [], "counts": [], "note": "no SNR drawn (receiver chain noise)"}
    else:
        low, high = spec.snr_db.low, spec.snr_db.high
        if high == low:
            low, high = low - 0.5, high + 0.5
        hist, edges = np.histogram(snr, bins=bins, range=(low, high))
        histogram = {"edges_db": edges.tolist(), "counts": hist.tolist()}
    return {"counts": counts, "snr_histogram": histogram}


class _Recorder:
    """Collects task results and records them in batches (checksums, then flags)."""

    def __init__(self, store: DatasetStore, bar: Any) -> None:
        self.store = store
        self.bar = bar
        self.pending: list[SampleResult] = []
        self.last = time.monotonic()
        self.n_recorded = 0
        self.simulate_cpu_s = 0.0

    def add(self, result: SampleResult) -> None:
        self.pending.append(result)
        self.simulate_cpu_s += result.simulate_cpu_s
        self.bar.update(1)
        if len(self.pending) >= FLUSH_BATCH or time.monotonic() - self.last >= FLUSH_INTERVAL_S:
            self.flush()

    def flush(self) -> None:
        if self.pending:
            indices = np.array([r.index for r in self.pending], dtype=np.int64)
            checksums = np.array([r.checksum for r in self.pending], dtype=np.uint64)
            self.store.record_completion(indices, checksums)
            self.n_recorded += len(self.pending)
            self.pending = []
        self.last = time.monotonic()


def _run_in_process(spec: DatasetSpec, samples: list[SampleDescription], writer: SampleWriter, vocab: Vocabularies,
                    recorder: _Recorder) -> None:
    for sample in samples:
        recorder.add(make_sample(spec, sample, writer, vocab))


def _run_on_client(client: Any, spec: DatasetSpec, samples: list[SampleDescription], writer: SampleWriter,
                   vocab: Vocabularies, recorder: _Recorder, n_workers: int) -> None:
    from distributed import as_completed

    spec_f, writer_f, vocab_f = client.scatter([spec, writer, vocab], broadcast=True)
    per_task = samples_per_task(len(samples), n_workers)
    window = 2 * max(n_workers, 1)  # one task running and one queued per worker
    queue = iter([samples[k:k + per_task] for k in range(0, len(samples), per_task)])
    futures = as_completed()
    index_of: dict[str, list[int]] = {}

    def submit_next() -> None:
        batch = next(queue, None)
        if batch is not None:
            future = client.submit(make_samples, spec_f, batch, writer_f, vocab_f, pure=False,
                                   key=f"dataset-samples-{batch[0].index}-{time.monotonic_ns()}")
            index_of[future.key] = [sample.index for sample in batch]
            futures.add(future)

    for _ in range(window):
        submit_next()
    try:
        for future in futures:
            try:
                results = future.result()
            except Exception as exc:
                raise RuntimeError(f"task of samples {index_of.get(future.key)} failed: {type(exc).__name__}: {exc} "
                                   "(samples completed so far are recorded; rerun to resume)") from exc
            index_of.pop(future.key, None)
            future.release()
            for result in results:
                recorder.add(result)
            submit_next()
    finally:
        for future in list(futures.futures):
            future.cancel()


def warm_up_worker() -> None:
    """Import the simulator's modules in a worker (start-up cost, not per-sample cost)."""
    import acoustisim.propagation.solver  # noqa: F401
    import acoustisim.simulation  # noqa: F401
    import scenes.builders  # noqa: F401
    import zarr  # noqa: F401


LOCAL_CLUSTER_CONFIG = {
    # Equal-sized tasks need no work stealing; a 2 s system monitor instead of 0.5 s. Together
    # they cut the idle scheduler's CPU from ~3.5 % to ~1 % of a core (measured).
    "distributed.scheduler.work-stealing": False,
    "distributed.admin.system-monitor.interval": "2s",
    # distributed starts workers with MALLOC_TRIM_THRESHOLD_=65536, which also turns off
    # glibc's dynamic mmap threshold: every large FFT buffer of the synthesis is then mmapped
    # and faulted in afresh. Measured on 10 default-spec samples in one worker: 1.08 s of
    # system time with it, 0.02 s without (user time 2.0 s either way). Keep glibc's default.
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
    # Every server (scheduler, nannies: all in the driver process; workers) checks every 20 ms
    # that its event loop is not blocked, and each nanny polls its worker's memory every
    # 100 ms. Once a second is plenty for tasks of ~0.1-1 s: the idle driver's CPU falls from
    # 2.7 % to 0.6 % of a core with one worker (measured, same run).
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
    # The workers' statistical profiler (dashboard only) samples every thread's stack every
    # 10 ms: idle worker CPU 3.3 % -> 0.3 % of a core without it (measured, consecutive runs).
    "distributed.worker.profile.enabled": False,
}


def _local_cluster(workers: int) -> Any:
    import dask
    from distributed import LocalCluster

    with dask.config.set(LOCAL_CLUSTER_CONFIG):
        return LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
            silence_logs=logging.ERROR,
        )


def generate(
    spec: DatasetSpec,
    out: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    progress: bool = True,
) -> GenerateReport:
    """Generate (or resume) a dataset.

    Parameters
    ----------
    spec : DatasetSpec
    out : path
        The Zarr store directory (created, or resumed when it exists).
    workers : int, optional
        Worker processes of the local cluster (default: the machine's CPU count); 0 runs the
        tasks in this process without Dask. Ignored with ``scheduler`` or ``client``.
    scheduler : str, optional
        Address of a running ``dask.distributed`` scheduler (``tcp://host:8786``).
    client : distributed.Client, optional
        An existing client (takes precedence over ``scheduler``).
    progress : bool
        Show a progress bar with rate and ETA on stderr.

    Raises
    ------
    SpecError
        Before any work, for an impossible spec (e.g. placements).
    DatasetStoreError
        If ``out`` exists and is not a store of this spec.
    """
    from tqdm import tqdm

    t_start = time.perf_counter()
    if workers is not None and workers < 0:
        raise InputError(f"--workers = {workers}: must be >= 0")
    samples = plan_samples(spec)  # raises SpecError before any work
    vocab = vocabularies(spec)
    store = open_or_create(spec, out, vocab)
    done = store.complete_mask()
    todo = [s for s in samples if not done[s.index]]
    writer = store.writer()

    own_cluster = None
    own_client = None
    mode = "in-process"
    n_workers = 0
    try:
        if client is None and todo and (scheduler is not None or workers != 0):
            from distributed import Client

            if scheduler is not None:
                try:
                    own_client = Client(scheduler, timeout="20s")
                except (OSError, TimeoutError) as exc:
                    raise InputError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
                mode = scheduler
            else:
                import os

                own_cluster = _local_cluster(workers or os.cpu_count() or 1)
                own_client = Client(own_cluster)
                mode = "local-cluster"
            client = own_client
        elif client is not None:
            mode = str(client.scheduler.address)
        if client is not None:
            n_workers = len(client.scheduler_info()["workers"])
            client.run(warm_up_worker)
        startup = time.perf_counter() - t_start
        bar = tqdm(total=spec.n_samples, initial=int(done.sum()), unit="sample", desc=spec.name,
                   disable=not progress, file=sys.stderr, dynamic_ncols=True, smoothing=0.1)
        recorder = _Recorder(store, bar)
        t_run = time.perf_counter()
        try:
            if client is None:
                _run_in_process(spec, todo, writer, vocab, recorder)
            else:
                _run_on_client(client, spec, todo, writer, vocab, recorder, n_workers)
        finally:
            recorder.flush()
            bar.close()
        elapsed = time.perf_counter() - t_run
    finally:
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()

    summary = dataset_card_summary(store, spec)
    n_complete = summary["counts"]["n_complete"]
    store.update_card(status="complete" if n_complete == spec.n_samples else "incomplete", **summary,
                      last_run={"workers": n_workers, "scheduler": mode, "n_generated": recorder.n_recorded,
                                "elapsed_s": elapsed, "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())})
    return GenerateReport(
        path=str(out),
        n_samples=spec.n_samples,
        n_skipped=len(samples) - len(todo),
        n_generated=recorder.n_recorded,
        n_complete=n_complete,
        elapsed_s=elapsed,
        startup_s=startup,
        samples_per_s=recorder.n_recorded / elapsed if elapsed > 0 else float("nan"),
        workers=n_workers,
        scheduler=mode,
        simulate_cpu_s=recorder.simulate_cpu_s,
    )


__all__ = ["GenerateReport", "SampleResult", "SpecError", "code_version", "generate", "make_sample", "make_samples",
           "simulate_sample"]
