"""How generation splits samples into Dask tasks, and what a task reports."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from acoustisim.datasets.generate import MAX_SAMPLES_PER_TASK, generate, make_samples, samples_per_task
from acoustisim.datasets.labels import vocabularies
from acoustisim.datasets.sampling import plan_samples
from acoustisim.datasets.spec import loads_spec
from acoustisim.datasets.store import DatasetStore

SPEC = """
[dataset]
name = "tiny-tasks"
n_samples = 3
seed = 11
max_arrivals = 16
[sonar]
record_length_s = 0.001
[solver]
max_order = 1
mechanisms = ["direct", "specular"]
diffuse_rays = 0
[placement]
min_range_m = 0.3
max_range_m = 0.7
half_angle_deg = 10.0
[[objects]]
kind = "sphere"
count = 1
radius_m = [0.02, 0.05]
"""


@pytest.mark.parametrize(("n_todo", "n_workers", "expected"), [
    (1, 1, 1),  # a single sample: one task of one
    (8, 2, 1),  # too few samples for 4 tasks per worker of more than one sample
    (24, 1, 4),  # 6 tasks of 4
    (24, 2, 3),  # 8 tasks of 3: 4 per worker
    (10_000, 2, MAX_SAMPLES_PER_TASK),  # long runs: capped
    (5, 0, 2),  # no worker count known: treated as one
])
def test_samples_per_task(n_todo: int, n_workers: int, expected: int) -> None:
    assert samples_per_task(n_todo, n_workers) == expected


def test_make_samples_writes_each_sample_and_reports_its_simulation_cpu(tmp_path: Path) -> None:
    spec = loads_spec(SPEC)
    out = tmp_path / "ref.zarr"
    report = generate(spec, out, workers=0, progress=False)  # one sample per call, in order
    assert report.n_generated == 3 and report.simulate_cpu_s > 0
    ref = DatasetStore(out)

    # The same samples through the batched task, into a second store: same checksums, in order.
    other = tmp_path / "batched.zarr"
    generate(dataclasses.replace(spec, n_samples=3), other, workers=0, progress=False)
    store = DatasetStore(other, mode="r+")
    results = make_samples(spec, plan_samples(spec), store.writer(), vocabularies(spec))
    assert [r.index for r in results] == [0, 1, 2]
    assert [r.checksum for r in results] == ref.checksums().tolist()
    assert all(0 < r.simulate_cpu_s for r in results)


def test_make_samples_names_the_sample_that_failed(tmp_path: Path) -> None:
    spec = loads_spec(SPEC)
    generate(spec, tmp_path / "s.zarr", workers=0, progress=False)
    store = DatasetStore(tmp_path / "s.zarr", mode="r+")
    samples = plan_samples(spec)
    bad = dataclasses.replace(samples[1], index=spec.n_samples + 5)  # beyond the store: its write fails
    with pytest.raises(RuntimeError, match=rf"^sample {spec.n_samples + 5}: "):
        make_samples(spec, [samples[0], bad], store.writer(), vocabularies(spec))
