"""Generate a dataset: plan every sample, simulate them on Dask, write them, record completion.

Order of work
-------------
1. Every sample is drawn (:func:`~acoustisim.datasets.sampling.plan_samples`) before anything
   runs: a spec whose placements cannot be satisfied fails here, naming the key.
2. The store is created, or, if it exists, checked to come from the same spec; chunks whose
   samples are all recorded complete are skipped (resume).
3. One task per missing chunk of samples (``spec.samples_per_chunk``, see
   :mod:`~acoustisim.datasets.store`): draw its samples again from their seeds (a task's
   arguments are its sample range, not the samples), build and simulate each, then write the
   chunk of every data array, then its checksums, then its completion flags (each chunk
   file atomically). The workers write their own chunks: the driver only schedules tasks and
   counts their results, so it is no serial bottleneck. With several workers the last chunks
   (one per worker, :func:`split_tail`) run as one task per sample and one writing the chunk,
   so that the workers finish together. Tasks run on a
   ``distributed.LocalCluster`` of ``workers`` single-threaded processes (default), on the
   scheduler at ``scheduler`` (its workers must see the store's path), or, with
   ``workers=0``, in this process without Dask.
4. A run killed at any moment leaves no sample flagged complete that is not fully written;
   running the same command again redoes the unfinished chunks only, identically.

At most ``2 x workers`` chunks are in flight, each future is released once its result is
counted, and what the scheduler logs per task is about a kilobyte (100 batches per stream), so
the driver's memory stays flat however many samples; the workers keep no Python objects from
one task to the next (``benchmarks/bench_dataset.py --memory N --tiny``).
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
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np
from numpy.typing import NDArray

from acoustisim.datasets.labels import Vocabularies, sample_arrays, vocabularies
from acoustisim.datasets.sampling import SampleDescription, build_scene, draw_sample, plan_samples
from acoustisim.datasets.spec import DatasetSpec
from acoustisim.datasets.store import (
    LAYOUT_VERSION,
    SAMPLE_FIELDS,
    ChunkWriter,
    SampleArrays,
    DatasetStore,
    DatasetStoreError,
    StoreShape,
    create_store,
    store_seen_here,
)
from acoustisim.errors import InputError

GATHER_BATCH = 16
"""Finished tasks whose (small) results the driver fetches in one go. The workers record
completion in the store themselves: the results only feed the run's report."""


@dataclass(frozen=True)
class TaskCost:
    """CPU and wall time of one task, and the process that ran it.

    Attributes
    ----------
    cpu_s : float
        CPU time (s) of the process during the task (all its threads: Embree's, Zarr's I/O).
    elapsed_s : float
        Wall time (s) of the task.
    worker : int
        Process id.
    """

    cpu_s: float
    elapsed_s: float
    worker: int


@dataclass(frozen=True)
class SampleResult:
    """One simulated sample: its rows for the store and its costs (what a sample task returns).

    Attributes
    ----------
    arrays : SampleArrays
    simulate_cpu_s : float
        CPU time (s) of the process while it built and simulated the sample (the plain
        simulator's cost, helper threads such as Embree's included: the reference of the
        overhead figures of ``benchmarks/bench_dataset.py``). A worker runs one task at a
        time, so the only other CPU in that interval is the Dask worker's idle background,
        small next to a sample's (:data:`LOCAL_CLUSTER_CONFIG` keeps it so).
    cost : TaskCost
        The whole task: simulate and labels.
    """

    arrays: SampleArrays
    simulate_cpu_s: float
    cost: TaskCost


@dataclass(frozen=True)
class ChunkResult:
    """What making one chunk returns: the chunk it wrote, its checksums and its costs.

    Attributes
    ----------
    start : int
        First sample of the chunk.
    checksums : tuple of int
        One per sample of the chunk, in order.
    simulate_cpu_s : float
        Sum of the samples' :attr:`SampleResult.simulate_cpu_s`.
    task_cpu_s : float
        CPU time (s) of the whole chunk: simulate, labels, checksums and the Zarr writes
        (with Zarr's I/O threads).
    elapsed_s : float
        Wall time (s) of its tasks, summed.
    worker : int
        Process id of the worker that wrote the chunk.
    costs : tuple of TaskCost
        Each task of the chunk, in the order they were submitted: one (simulate and write)
        or, for a chunk split into sample tasks, one per sample and then the write.
    kept : tuple of int
        Samples of the chunk that were already complete and verified, read back and
        rewritten unchanged (a chunk being repaired); the others were simulated.
    """

    start: int
    checksums: tuple[int, ...]
    simulate_cpu_s: float
    task_cpu_s: float
    elapsed_s: float
    worker: int
    costs: tuple[TaskCost, ...] = ()
    kept: tuple[int, ...] = ()

    @property
    def n_made(self) -> int:
        """Samples simulated for this chunk."""
        return len(self.checksums) - len(self.kept)


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
        Worker processes that ran tasks of this run (0: in-process). A worker that died and
        was restarted counts twice: it is two processes.
    scheduler : str
        "in-process", "local-cluster" or the scheduler address.
    workers_at_start, workers_at_end : int
        Workers connected to the scheduler when the run started and when it ended.
    workers_lost : int
        Workers present at the start and gone at the end (died or removed during the run).
    n_repaired : int
        Samples found corrupt by ``repair=True`` and made again (they are part of
        ``n_generated``).
    simulate_cpu_s : float
        Sum over the samples made by this run of the CPU time (s) their worker process spent
        building and simulating them (the rest of the run's CPU is the dataset machinery).
    task_cpu_s : float
        Sum of the tasks' CPU time (s): simulate plus labels, checksums and writes.
    driver_cpu_s : float
        CPU time (s) of this process during the run phase (with a LocalCluster: the client,
        the scheduler and the nannies, which all live here).
    worker_busy_s : dict
        Per worker (process id as a string; "in-process" without Dask): ``task_cpu_s`` and
        ``elapsed_s`` summed over its tasks, and ``n_samples``.
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
    workers_at_start: int = 0
    workers_at_end: int = 0
    workers_lost: int = 0
    n_repaired: int = 0
    simulate_cpu_s: float = 0.0
    task_cpu_s: float = 0.0
    driver_cpu_s: float = 0.0
    worker_busy_s: dict[str, dict[str, float]] = dataclasses.field(default_factory=dict)
    task_cpu_list_s: tuple[float, ...] = ()
    """Each task's CPU time (s), in the order the tasks were submitted (a split chunk's sample
    tasks, then its write)."""

    def as_dict(self) -> dict[str, Any]:
        """The report as JSON-ready values (without the per-task list)."""
        data = dataclasses.asdict(self)
        data.pop("task_cpu_list_s")
        return data

    def workers_text(self) -> str:
        """How many workers did the work, said honestly: e.g. "on 1 worker (2 at the start,
        1 lost during the run)"."""
        if self.scheduler == "in-process":
            return "in this process (no Dask)"
        text = f"on {self.workers} worker process{'es' if self.workers != 1 else ''}"
        notes = []
        if self.workers_at_start != self.workers or self.workers_lost or self.workers_at_end != self.workers_at_start:
            notes.append(f"{self.workers_at_start} at the start, {self.workers_at_end} at the end")
        if self.workers_lost:
            notes.append(f"{self.workers_lost} lost during the run")
        return text + (f" ({'; '.join(notes)})" if notes else "")


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
    # Samples run in parallel on the Dask workers, so each solve traces its diffuse rays on one
    # thread (rows do not depend on the thread count); a spec's [solver] threads overrides it.
    solver_options = {"threads": 1, **dict(spec.solver)}
    config = SolverConfig(**solver_options, seed=sample.simulation_seed % (2**31))
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


def simulate_rows(spec: DatasetSpec, sample: SampleDescription, vocab: Vocabularies) -> SampleResult:
    """Simulate one drawn sample and turn it into its rows for the store.

    Raises
    ------
    RuntimeError
        Naming the sample, whatever failed.
    """
    import os

    start, cpu_start = time.perf_counter(), time.process_time()
    try:
        scene, simulation, snr_reference = simulate_sample(spec, sample)
        simulate_cpu = time.process_time() - cpu_start
        arrays = sample_arrays(spec, sample, scene, simulation, vocab, snr_reference)
    except Exception as exc:
        raise RuntimeError(f"sample {sample.index}: {type(exc).__name__}: {exc}") from exc
    cost = TaskCost(time.process_time() - cpu_start, time.perf_counter() - start, os.getpid())
    return SampleResult(arrays, simulate_cpu, cost)


def make_sample(spec: DatasetSpec, index: int, vocab: Vocabularies) -> SampleResult:
    """The Dask task of one sample of a split chunk: draw sample ``index`` again from its own
    seed (the same as the driver's plan, by construction) and :func:`simulate_rows` it."""
    return simulate_rows(spec, draw_sample(spec, index), vocab)


def write_chunk(writer: ChunkWriter, results: list[SampleResult], spec: DatasetSpec | None = None,
                start: int | None = None, stop: int | None = None, vocab: Vocabularies | None = None) -> ChunkResult:
    """Write one chunk (data, then checksums, then completion flags).

    Parameters
    ----------
    writer : ChunkWriter
    results : list of SampleResult
        The simulated samples, in index order: the whole chunk, or (with ``start``/``stop``)
        the samples of chunk ``[start, stop)`` that were not complete.
    spec, start, stop, vocab : optional
        Given for a chunk being completed or repaired: its other samples are read back when
        they are complete and still match their checksum, else simulated here.
    """
    import os

    t0, cpu_start = time.perf_counter(), time.process_time()
    made = {r.arrays.index: r for r in results}
    kept: dict[int, SampleArrays] = {}
    if start is not None and stop is not None:
        others = [i for i in range(start, stop) if i not in made]
        kept = writer.read_verified(others)
        missing = [i for i in others if i not in kept]
        if missing:
            if spec is None or vocab is None:
                raise ValueError(f"samples {missing}: neither simulated nor stored (no spec to make them)")
            for sample in plan_samples(spec, missing):
                made[sample.index] = simulate_rows(spec, sample, vocab)
    order = sorted([*made, *kept])
    arrays = [made[i].arrays if i in made else kept[i] for i in order]
    checksums = writer.write_chunk(arrays)
    own = TaskCost(time.process_time() - cpu_start, time.perf_counter() - t0, os.getpid())
    simulated = [made[i] for i in order if i in made]
    costs = tuple(r.cost for r in simulated) + (own,)
    return ChunkResult(order[0], tuple(int(c) for c in checksums),
                       sum(r.simulate_cpu_s for r in simulated), sum(c.cpu_s for c in costs),
                       sum(c.elapsed_s for c in costs), own.worker, costs, tuple(sorted(kept)))


def make_chunk(spec: DatasetSpec, samples: list[SampleDescription], writer: ChunkWriter,
               vocab: Vocabularies) -> ChunkResult:
    """Simulate the samples of one chunk, write the chunk, return its checksums (one task).

    Parameters
    ----------
    spec : DatasetSpec
    samples : list of SampleDescription
        Exactly the samples of one chunk of the store, in index order.
    writer : ChunkWriter
    vocab : Vocabularies

    Raises
    ------
    RuntimeError
        Naming the sample that failed (nothing of its chunk is then written).
    """
    import os

    start, cpu_start = time.perf_counter(), time.process_time()
    results = [simulate_rows(spec, sample, vocab) for sample in samples]
    result = write_chunk(writer, results)
    # One task: its cost is the whole of it, not the sum of its parts.
    cost = TaskCost(time.process_time() - cpu_start, time.perf_counter() - start, os.getpid())
    return dataclasses.replace(result, task_cpu_s=cost.cpu_s, elapsed_s=cost.elapsed_s, costs=(cost,))


def make_chunk_range(spec: DatasetSpec, start: int, stop: int, writer: ChunkWriter, vocab: Vocabularies,
                     partial: bool = False) -> ChunkResult:
    """The Dask task of one chunk: draw samples ``start`` to ``stop - 1`` again from their own
    seeds (the same as the driver's plan, by construction) and run :func:`make_chunk` on them.

    With ``partial`` (a chunk some of whose samples are complete: a repair), the complete
    samples that still match their checksum are read back and rewritten unchanged; only the
    others are simulated.

    The task's arguments are then two integers besides the scattered spec, writer and
    vocabularies: nothing per sample goes through the scheduler. (Shipping the drawn samples
    instead, ~10 kB per chunk, grows the driver: the scheduler keeps the last 1000 batches
    sent to each worker, ``distributed.admin.low-level-log-length``, and every such batch then
    holds a chunk's samples.) Drawing a sample again is cheap next to simulating it.
    """
    if not partial:
        return make_chunk(spec, plan_samples(spec, range(start, stop)), writer, vocab)
    import os

    t0, cpu_start = time.perf_counter(), time.process_time()
    result = write_chunk(writer, [], spec, start, stop, vocab)
    cost = TaskCost(time.process_time() - cpu_start, time.perf_counter() - t0, os.getpid())
    return dataclasses.replace(result, task_cpu_s=cost.cpu_s, elapsed_s=cost.elapsed_s, costs=(cost,))


def store_shape(spec: DatasetSpec) -> StoreShape:
    """Array sizes of a spec's store."""
    from scenes.builders import default_sonar

    sonar = dataclasses.replace(default_sonar(), **dict(spec.sonar.overrides))
    return StoreShape(spec.n_samples, spec.n_pings, sonar.n_samples, spec.max_objects, spec.max_arrivals,
                      spec.samples_per_chunk)


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


class Tally:
    """Counts finished chunks (the workers have already recorded them in the store): samples,
    CPU time, per-worker busy time; ``bar`` (a tqdm progress bar, or anything with
    ``update(n)``) advances as samples finish."""

    def __init__(self, bar: Any) -> None:
        self.bar = bar
        self.n_samples = 0
        self.simulate_cpu_s = 0.0
        self.task_cpu_s = 0.0
        self.by_worker: dict[str, dict[str, float]] = {}
        self.task_cpu: dict[int, tuple[float, ...]] = {}

    def add(self, result: ChunkResult, worker: str | None = None, *, update_bar: bool = True) -> None:
        """Count a chunk; its tasks' costs go to the worker that ran each (all to ``worker`` if given)."""
        n = result.n_made
        self.n_samples += n
        self.simulate_cpu_s += result.simulate_cpu_s
        self.task_cpu_s += result.task_cpu_s
        self.task_cpu[result.start] = tuple(c.cpu_s for c in result.costs)
        # A split chunk (its sample tasks, then the write) counts its samples for the workers
        # that simulated them; a chunk task's for its worker.
        split = len(result.costs) == n + 1
        simulated_by = [c.worker for c in result.costs[:n]] if split else [result.worker] * n
        for cost in result.costs:
            self._busy(worker or str(cost.worker), cost.cpu_s, cost.elapsed_s, 0)
        for pid in simulated_by:
            self._busy(worker or str(pid), 0.0, 0.0, 1)
        if update_bar:
            self.bar.update(n)

    def _busy(self, worker: str, cpu_s: float, elapsed_s: float, n_samples: int) -> None:
        busy = self.by_worker.setdefault(worker, {"task_cpu_s": 0.0, "elapsed_s": 0.0, "n_samples": 0})
        busy["task_cpu_s"] += cpu_s
        busy["elapsed_s"] += elapsed_s
        busy["n_samples"] += n_samples


def _run_in_process(spec: DatasetSpec, chunks: list[tuple[int, int]], writer: ChunkWriter,
                    vocab: Vocabularies, tally: Tally, complete: NDArray[np.bool_] | None = None) -> None:
    for start, stop in chunks:
        partial = complete is not None and bool(complete[start:stop].any())
        tally.add(make_chunk_range(spec, start, stop, writer, vocab, partial), "in-process")


def split_tail(n_chunks: int, n_workers: int) -> int:
    """How many of the last chunks run as one task per sample (plus one writing the chunk).

    A chunk task is the unit of work, so the run ends when the worker with the most chunk
    work left finishes: with few chunks per worker the others wait for up to a chunk's time.
    Splitting the last ``n_workers`` chunks into sample tasks brings the imbalance down to
    about one sample, at the cost of the extra tasks (each is a submit, a result and a
    transition for the driver), so only the tail is split. One worker has no imbalance:
    nothing is split. ``benchmarks/bench_dataset.py`` prints the speed-up of 2 workers over 1.
    """
    return 0 if n_workers < 2 else min(n_chunks, n_workers)


def run_on_client(client: Any, spec: DatasetSpec, chunks: list[tuple[int, int]], writer: ChunkWriter,
                   vocab: Vocabularies, tally: Tally, n_workers: int,
                   complete: NDArray[np.bool_] | None = None) -> None:
    """Run the tasks of ``chunks`` (``(start, stop)`` sample ranges), at most ``2 x n_workers``
    chunks in flight; each future is released as soon as it has finished and its result is
    counted. The last :func:`split_tail` chunks run as one task per sample and one writing
    the chunk. ``complete`` (the store's flags) marks chunks being repaired: only their
    incomplete samples are simulated, the others are read back by the task that writes.

    The scheduler then holds a few tasks per worker, and everything it logs per task
    (transitions, messages to the workers, one event per submit: all bounded deques of
    ``distributed.admin.low-level-log-length`` entries) is about a kilobyte: the driver's
    memory does not grow with the number of samples.
    """
    from distributed import as_completed

    # hash=False: keys unique to this run, so that the release of a previous run's scattered
    # copies (same content, same hashed key) cannot race with this run's scatter.
    spec_f, writer_f, vocab_f = client.scatter([spec, writer, vocab], broadcast=True, hash=False)
    window = 2 * max(n_workers, 1)  # about one chunk running and one queued per worker
    first_split = len(chunks) - split_tail(len(chunks), n_workers)
    queue = iter(enumerate(chunks))
    futures = as_completed()
    range_of: dict[str, tuple[int, int]] = {}

    def submit_next() -> None:
        k, chunk = next(queue, (None, None))
        if chunk is None:
            return
        start, stop = chunk
        stamp = time.monotonic_ns()
        partial = complete is not None and bool(complete[start:stop].any())
        if k < first_split:
            future = client.submit(make_chunk_range, spec_f, start, stop, writer_f, vocab_f, partial, pure=False,
                                   key=f"dataset-chunk-{start}-{stamp}")
        else:
            todo = [i for i in range(start, stop) if not (partial and complete[i])]
            samples = client.map(make_sample, [spec_f] * len(todo), todo, [vocab_f] * len(todo),
                                 pure=False, key=[f"dataset-sample-{i}-{stamp}" for i in todo])
            if partial:
                future = client.submit(write_chunk, writer_f, samples, spec_f, start, stop, vocab_f, pure=False,
                                       key=f"dataset-write-{start}-{stamp}")
            else:
                future = client.submit(write_chunk, writer_f, samples, pure=False, key=f"dataset-write-{start}-{stamp}")
            del samples  # the scheduler keeps them until the write has run, then forgets them
        range_of[future.key] = chunk
        futures.add(future)

    def collect(finished: list[Any]) -> None:
        # One gather for several small results: a fetch per task costs the driver more CPU.
        for result in client.gather(finished):
            tally.add(result, update_bar=False)
        for future in finished:
            future.release()
        finished.clear()

    for _ in range(window):
        submit_next()
    finished: list[Any] = []
    try:
        for future in futures:  # as_completed: yields finished futures without fetching results
            if future.status != "finished":
                exc = future.exception()
                start, stop = range_of.get(future.key, (0, 0))
                if isinstance(exc, InputError):  # e.g. a worker that cannot see the store: one line, exit 2
                    raise type(exc)(f"samples {start}-{stop - 1}: {exc}") from None
                raise RuntimeError(f"task of samples {start}-{stop - 1} failed: {type(exc).__name__}: {exc} "
                                   "(chunks completed so far are recorded; rerun to resume)") from exc
            start, stop = range_of.pop(future.key, (0, 0))
            tally.bar.update(stop - start if complete is None else int((~complete[start:stop]).sum()))
            finished.append(future)
            submit_next()
            if len(finished) >= GATHER_BATCH:
                collect(finished)
        collect(finished)
    finally:
        for future in list(futures.futures):
            future.cancel()
        for future in (spec_f, writer_f, vocab_f):
            future.release()


def warm_up_worker() -> None:
    """Import the simulator's modules in a worker (start-up cost, not per-sample cost)."""
    import acoustisim.propagation.solver  # noqa: F401
    import acoustisim.simulation  # noqa: F401
    import scenes.builders  # noqa: F401
    import zarr  # noqa: F401


LOCAL_CLUSTER_CONFIG: Mapping[str, Any] = MappingProxyType({
    # Equal-sized tasks need no work stealing, and a system monitor every 2 s (not 0.5 s) is
    # enough for them: both only cost the scheduler CPU here.
    "distributed.scheduler.work-stealing": False,
    "distributed.admin.system-monitor.interval": "2s",
    # distributed starts workers with MALLOC_TRIM_THRESHOLD_=65536, which also turns off
    # glibc's dynamic mmap threshold: every large FFT buffer of the synthesis is then mmapped
    # and faulted in afresh, in system time. Keep glibc's default.
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
    # Every server (scheduler, nannies: all in the driver process; workers) checks every 20 ms
    # that its event loop is not blocked, and each nanny polls its worker's memory every
    # 100 ms. Once a second is plenty for tasks of ~0.1-1 s, and leaves the idle driver's CPU
    # to the workers.
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
    # The workers' statistical profiler (dashboard only) samples every thread's stack every
    # 10 ms, most of an idle worker's CPU; nothing here reads it.
    "distributed.worker.profile.enabled": False,
    # Developer logs (the scheduler's transitions and events, the last batches each stream
    # sent) keep 1000 entries each by default; a batch to a worker holds its tasks, so the
    # driver grows until they fill. 100 is plenty to debug with and keeps them small
    # (``benchmarks/bench_dataset.py --memory N --tiny`` follows the driver's memory).
    "distributed.admin.low-level-log-length": 100,
})


def local_cluster(workers: int) -> Any:
    """The ``distributed.LocalCluster`` that :func:`generate` starts: ``workers`` single-threaded
    processes, configured by :data:`LOCAL_CLUSTER_CONFIG`."""
    import dask
    from distributed import LocalCluster

    with dask.config.set(LOCAL_CLUSTER_CONFIG):
        return LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
            silence_logs=logging.ERROR,
        )


def check_workers_see_store(client: Any, store: DatasetStore) -> None:
    """Ask every worker of ``client`` whether it sees ``store`` at its absolute path.

    Raises
    ------
    DatasetStoreError
        One line naming the first worker that does not, and what it sees instead, before any
        task runs (a worker with another working directory or on another machine would
        otherwise write its chunks somewhere else and the run would never complete).
    """
    seen = client.run(store_seen_here, str(store.root), store.store_id)
    for address, problem in sorted(seen.items()):
        if problem:
            raise DatasetStoreError(f"worker {address}: {problem}")


def worker_addresses(client: Any) -> set[str]:
    """The addresses of the workers connected to ``client``'s scheduler now."""
    return set(client.scheduler_info()["workers"])


def repair_store(store: DatasetStore) -> tuple[int, ...]:
    """Find the samples of ``store`` that fail :func:`~acoustisim.datasets.verify.verify`
    (unreadable or not matching their checksum), clear their completion flags so that the
    next run makes them again, and remove stray ``*.partial`` files of interrupted writes.

    Returns
    -------
    tuple of int
        The samples marked for remaking.
    """
    from acoustisim.datasets.verify import verify

    report = verify(store.path)
    bad = tuple(sorted({i for i, _ in report.corrupt}))
    store.mark_incomplete(bad)
    for stray in report.stray_files:
        (store.root / stray).unlink(missing_ok=True)
    return bad


def generate(
    spec: DatasetSpec,
    out: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    progress: bool = True,
    repair: bool = False,
) -> GenerateReport:
    """Generate (or resume, or repair) a dataset.

    Parameters
    ----------
    spec : DatasetSpec
    out : path
        The Zarr store directory (created, or resumed when it exists). It is resolved to an
        absolute path here: the workers open the store at that path, and each one checks that
        it sees this store there before any task runs.
    workers : int, optional
        Worker processes of the local cluster (default: the machine's CPU count); 0 runs the
        tasks in this process without Dask. Ignored with ``scheduler`` or ``client``.
    scheduler : str, optional
        Address of a running ``dask.distributed`` scheduler (``tcp://host:8786``).
    client : distributed.Client, optional
        An existing client (takes precedence over ``scheduler``).
    progress : bool
        Show a progress bar with rate and ETA on stderr.
    repair : bool
        First verify the complete samples (:func:`~acoustisim.datasets.verify.verify`) and make
        again exactly those that fail (a damaged chunk file, a checksum mismatch); the other
        samples of their chunks are read back and rewritten unchanged.

    Raises
    ------
    SpecError
        Before any work, for an impossible spec (e.g. placements).
    DatasetStoreError
        If ``out`` exists and is not a store of this spec, or a worker cannot see the store.
    """
    from tqdm import tqdm

    t_start = time.perf_counter()
    if workers is not None and workers < 0:
        raise InputError(f"--workers = {workers}: must be >= 0")
    out = Path(out).expanduser().resolve()
    plan_samples(spec)  # raises SpecError before any work (each task draws its samples again)
    vocab = vocabularies(spec)
    store = open_or_create(spec, out, vocab)
    repaired = repair_store(store) if repair else ()
    complete = store.complete_mask()
    chunks = store.chunks_to_do()
    n_todo = int((~complete).sum())
    writer = store.writer()

    own_cluster = None
    own_client = None
    mode = "in-process"
    at_start: set[str] = set()
    at_end: set[str] = set()
    try:
        if client is None and chunks and (scheduler is not None or workers != 0):
            from distributed import Client

            if scheduler is not None:
                try:
                    own_client = Client(scheduler, timeout="20s")
                except (OSError, TimeoutError) as exc:
                    raise InputError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
                mode = scheduler
            else:
                import os

                import dask

                own_cluster = local_cluster(workers or os.cpu_count() or 1)
                with dask.config.set(LOCAL_CLUSTER_CONFIG):  # the client's own logs too
                    own_client = Client(own_cluster)
                mode = "local-cluster"
            client = own_client
        elif client is not None:
            mode = str(client.scheduler.address)
        if client is not None:
            at_start = worker_addresses(client)
            if chunks and not at_start:
                raise InputError(f"{mode}: no worker is connected to this scheduler (start `dask worker {mode}` "
                                 "processes that see --out)")
            if chunks:
                check_workers_see_store(client, store)
                client.run(warm_up_worker)
        startup = time.perf_counter() - t_start
        bar = tqdm(total=spec.n_samples, initial=spec.n_samples - n_todo, unit="sample", desc=spec.name,
                   disable=not progress, file=sys.stderr, dynamic_ncols=True, smoothing=0.1)
        tally = Tally(bar)
        t_run, cpu_run = time.perf_counter(), time.process_time()
        try:
            if client is None:
                _run_in_process(spec, chunks, writer, vocab, tally, complete)
            else:
                run_on_client(client, spec, chunks, writer, vocab, tally, len(at_start), complete)
        finally:
            bar.close()
            if client is not None:
                at_end = worker_addresses(client)
        elapsed = time.perf_counter() - t_run
        driver_cpu = time.process_time() - cpu_run
    finally:
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()

    summary = dataset_card_summary(store, spec)
    n_complete = summary["counts"]["n_complete"]
    n_workers = 0 if mode == "in-process" else len(tally.by_worker)
    store.update_card(status="complete" if n_complete == spec.n_samples else "incomplete", **summary,
                      last_run={"workers": n_workers, "workers_at_start": len(at_start), "workers_at_end": len(at_end),
                                "workers_lost": len(at_start - at_end), "scheduler": mode,
                                "n_generated": tally.n_samples, "n_repaired": len(repaired), "elapsed_s": elapsed,
                                "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())})
    return GenerateReport(
        path=str(out),
        n_samples=spec.n_samples,
        n_skipped=spec.n_samples - n_todo,
        n_generated=tally.n_samples,
        n_complete=n_complete,
        elapsed_s=elapsed,
        startup_s=startup,
        samples_per_s=tally.n_samples / elapsed if elapsed > 0 else float("nan"),
        workers=n_workers,
        scheduler=mode,
        workers_at_start=len(at_start),
        workers_at_end=len(at_end),
        workers_lost=len(at_start - at_end),
        n_repaired=len(repaired),
        simulate_cpu_s=tally.simulate_cpu_s,
        task_cpu_s=tally.task_cpu_s,
        driver_cpu_s=driver_cpu,
        worker_busy_s=tally.by_worker,
        task_cpu_list_s=tuple(cpu for start in sorted(tally.task_cpu) for cpu in tally.task_cpu[start]),
    )


__all__ = ("ChunkResult", "GenerateReport", "LOCAL_CLUSTER_CONFIG", "SampleResult", "Tally", "TaskCost",
           "check_workers_see_store", "code_version", "generate", "local_cluster", "make_chunk", "make_chunk_range",
           "make_sample", "repair_store", "run_on_client", "simulate_rows", "simulate_sample", "split_tail",
           "worker_addresses", "write_chunk")
