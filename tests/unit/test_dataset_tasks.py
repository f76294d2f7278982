"""How generation splits samples into chunks (one Dask task each), and what a task reports."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from acoustisim.datasets.generate import generate, make_chunk
from acoustisim.datasets.labels import vocabularies
from acoustisim.datasets.sampling import plan_samples
from acoustisim.datasets.spec import loads_spec
from acoustisim.datasets.store import DatasetStore, StoreShape
from support.dataset_specs import small_spec

SPEC = small_spec(name="tiny-tasks", n_samples=3, seed=11, samples_per_chunk=2)


@pytest.mark.parametrize(("n", "chunk", "index", "expected"), [
    (5, 2, 0, (0, 2)),
    (5, 2, 3, (2, 4)),
    (5, 2, 4, (4, 5)),  # the short last chunk
    (4, 4, 2, (0, 4)),
    (3, 8, 2, (0, 3)),  # a chunk larger than the store
])
def test_chunk_of_a_sample(n: int, chunk: int, index: int, expected: tuple[int, int]) -> None:
    shape = StoreShape(n, 1, 10, 1, 4, chunk)
    assert shape.chunk_of(index) == expected
    starts = list(shape.chunk_starts())
    assert starts == list(range(0, n, chunk)) and expected[0] in starts


def test_a_chunk_task_writes_its_samples_and_reports_their_costs(tmp_path: Path) -> None:
    spec = loads_spec(SPEC)
    out = tmp_path / "ref.zarr"
    report = generate(spec, out, workers=0, progress=False)
    assert report.n_generated == 3 and 0 < report.simulate_cpu_s < report.task_cpu_s
    assert report.worker_busy_s["in-process"]["n_samples"] == 3
    ref = DatasetStore(out)

    # Chunk [0, 1] again, into a fresh store: same checksums, flagged complete, the rest untouched.
    other = tmp_path / "again.zarr"
    from acoustisim.datasets.generate import open_or_create

    store = open_or_create(spec, other, vocabularies(spec))
    result = make_chunk(spec, plan_samples(spec)[:2], store.writer(), vocabularies(spec))
    assert result.start == 0 and list(result.checksums) == ref.checksums()[:2].tolist()
    assert 0 < result.simulate_cpu_s <= result.task_cpu_s
    assert store.complete_mask().tolist() == [True, True, False]
    assert store.checksums()[:2].tolist() == ref.checksums()[:2].tolist()
    assert store.chunks_to_do() == [(2, 3)]


def test_a_failing_sample_is_named_and_its_chunk_left_unwritten(tmp_path: Path) -> None:
    spec = loads_spec(SPEC)
    from acoustisim.datasets.generate import open_or_create

    store = open_or_create(spec, tmp_path / "s.zarr", vocabularies(spec))
    samples = plan_samples(spec)
    # A class label outside the dataset's vocabulary: sample 1 fails when labelled, after
    # sample 0 has been simulated.
    bad = dataclasses.replace(samples[1], objects=tuple(dataclasses.replace(o, label="unknown")
                                                        for o in samples[1].objects))
    with pytest.raises(RuntimeError, match=r"^sample 1: "):
        make_chunk(spec, [samples[0], bad], store.writer(), vocabularies(spec))
    assert not store.complete_mask().any()
    assert not (tmp_path / "s.zarr" / "waveforms" / "c").exists()


def test_the_report_counts_workers_honestly() -> None:
    from acoustisim.datasets.generate import GenerateReport

    base = dict(path="d.zarr", n_samples=4, n_skipped=0, n_generated=4, n_complete=4, elapsed_s=1.0,
                startup_s=1.0, samples_per_s=4.0)
    steady = GenerateReport(**base, workers=2, scheduler="local-cluster", workers_at_start=2, workers_at_end=2)
    assert steady.workers_text() == "on 2 worker processes"
    lost = GenerateReport(**base, workers=2, scheduler="tcp://h:8786", workers_at_start=2, workers_at_end=1,
                          workers_lost=1)
    assert lost.workers_text() == "on 2 worker processes (2 at the start, 1 at the end; 1 lost during the run)"
    one = GenerateReport(**base, workers=1, scheduler="tcp://h:8786", workers_at_start=2, workers_at_end=2)
    assert one.workers_text() == "on 1 worker process (2 at the start, 2 at the end)"
    assert GenerateReport(**base, workers=0, scheduler="in-process").workers_text() == "in this process (no Dask)"
