"""Dataset generation on Dask: worker-count independence, SIGKILL then resume.

One ``LocalCluster`` (2 worker processes) is started for the whole module; the killed run
uses it through ``--scheduler ADDRESS``, as a run on a real cluster would.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from acoustisim.datasets.generate import generate
from acoustisim.datasets.spec import loads_spec
from acoustisim.datasets.store import SAMPLE_ARRAYS, DatasetStore
from support.dataset_specs import small_spec

SPEC = small_spec(name="tiny-dask", n_samples=16, seed=5)


@pytest.fixture(scope="module")
def client():
    from distributed import Client

    from acoustisim.datasets.generate import local_cluster

    cluster = local_cluster(2)  # as `generate --workers 2` starts it
    with Client(cluster) as c:
        yield c
    cluster.close()


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An uninterrupted run, in this process (one worker, in order)."""
    out = tmp_path_factory.mktemp("ref") / "ref.zarr"
    generate(loads_spec(SPEC), out, workers=0, progress=False)
    return out


def assert_same_samples(a: Path, b: Path) -> None:
    sa, sb = DatasetStore(a), DatasetStore(b)
    assert sa.complete_mask().all() and sb.complete_mask().all()
    np.testing.assert_array_equal(sa.checksums(), sb.checksums())
    for k in range(sa.n_samples):
        va, vb = sa.read_sample(k), sb.read_sample(k)
        for name in SAMPLE_ARRAYS:
            np.testing.assert_array_equal(vb[name], va[name], err_msg=f"sample {k} {name}")


def test_two_workers_give_the_same_arrays_as_one(client, reference: Path, tmp_path: Path) -> None:
    out = tmp_path / "two.zarr"
    report = generate(loads_spec(SPEC), out, client=client, progress=False)
    assert report.workers == 2 and report.n_generated == 16
    # 4 chunks: 2 chunk tasks, then 2 chunks split into 4 sample tasks and a write each.
    assert len(report.task_cpu_list_s) == 2 + 2 * 5
    assert sum(busy["n_samples"] for busy in report.worker_busy_s.values()) == 16
    assert_same_samples(reference, out)


def test_sigkill_mid_run_then_resume_equals_an_uninterrupted_run(client, reference: Path, tmp_path: Path) -> None:
    import zarr

    spec_file = tmp_path / "spec.toml"
    spec_file.write_text(SPEC)
    out = tmp_path / "killed.zarr"
    command = [sys.executable, "-m", "acoustisim.cli.main", "dataset", "generate", str(spec_file), "--out", str(out),
               "--workers", "2", "--no-progress"]
    process = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    n_done = 0
    deadline = time.monotonic() + 120.0
    try:
        while time.monotonic() < deadline and process.poll() is None:
            if (out / "complete" / "zarr.json").exists():
                n_done = int(np.asarray(zarr.open_array(str(out / "complete"), mode="r")[:]).sum())
                if n_done >= 1:
                    break
            time.sleep(0.05)
    finally:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    assert process.returncode == -signal.SIGKILL, process.stderr.read().decode()
    # The command runs its own LocalCluster in its process group, so the kill takes the workers
    # too (a worker writes its chunk's data, then checksum, then completion flag, each
    # atomically). Count only once no flag has changed for 3 s (a task takes ~0.5 s here), so a
    # worker still dying cannot change the store after it was counted.
    killed = DatasetStore(out)
    n_killed, stable_since, settle_deadline = -1, time.monotonic(), time.monotonic() + 60.0
    while time.monotonic() < settle_deadline:
        n_now = int(killed.complete_mask().sum())
        if n_now != n_killed:
            n_killed, stable_since = n_now, time.monotonic()
        elif time.monotonic() - stable_since >= 3.0:
            break
        time.sleep(0.2)
    assert 1 <= n_killed < 16, "the kill must land mid-run"

    report = generate(loads_spec(SPEC), out, client=client, progress=False)
    assert report.n_skipped == n_killed and report.n_generated == 16 - n_killed
    assert_same_samples(reference, out)
    from acoustisim.datasets.verify import verify

    assert verify(out).ok


@pytest.mark.slow
def test_cli_local_cluster_one_and_two_workers_identical(reference: Path, tmp_path: Path) -> None:
    spec_file = tmp_path / "spec.toml"
    spec_file.write_text(SPEC)
    for n in (1, 2):
        out = tmp_path / f"w{n}.zarr"
        result = subprocess.run([sys.executable, "-m", "acoustisim.cli.main", "dataset", "generate", str(spec_file),
                                 "--out", str(out), "--workers", str(n), "--json", "--no-progress"],
                                capture_output=True, text=True, check=True)
        assert f'"workers": {n}' in result.stdout
        assert_same_samples(reference, out)


@pytest.mark.parametrize("n_workers", [1, 2])  # 1: a chunk task; 2: the chunk split into sample tasks + a write
def test_a_failing_task_on_a_worker_stops_the_run_naming_its_samples(client, tmp_path: Path, n_workers: int) -> None:
    """A task that fails on a worker (here: labels outside the vocabulary) is reported with
    its samples, and nothing of its chunk is recorded complete."""
    import dataclasses

    from acoustisim.datasets.generate import run_on_client, Tally, open_or_create, split_tail
    from acoustisim.datasets.labels import vocabularies

    spec = loads_spec(SPEC)
    vocab = vocabularies(spec)
    store = open_or_create(spec, tmp_path / "fail.zarr", vocab)
    chunks = store.chunks_to_do()[:1]
    assert split_tail(len(chunks), n_workers) == n_workers - 1
    bad = dataclasses.replace(vocab, classes=("nothing",))

    class Bar:
        def update(self, n: int) -> None:
            pass

    # Every sample fails; a split chunk reports the first of its sample tasks to fail.
    match = r"^task of samples 0-3 failed: RuntimeError: sample [0-3]: ValueError"
    with pytest.raises(RuntimeError, match=match):
        run_on_client(client, spec, chunks, store.writer(), bad, Tally(Bar()), n_workers)
    assert not store.complete_mask().any()
    assert not (tmp_path / "fail.zarr" / "waveforms" / "c").exists()


@pytest.mark.parametrize(("n_chunks", "n_workers", "expected"), [(10, 1, 0), (10, 2, 2), (1, 2, 1), (10, 4, 4)])
def test_only_the_last_chunks_are_split_and_only_with_several_workers(n_chunks: int, n_workers: int,
                                                                      expected: int) -> None:
    from acoustisim.datasets.generate import split_tail

    assert split_tail(n_chunks, n_workers) == expected


def test_the_scheduler_logs_no_samples_per_task(client, tmp_path: Path) -> None:
    """The driver does not grow over long runs: the scheduler (in the driver's process with a
    LocalCluster) keeps the last batches it sent to each worker, so a task carries only its
    sample range (the worker draws the samples again), never the drawn samples, and those logs
    keep 100 batches, not the default 1000."""
    import pickle

    generate(loads_spec(SPEC), tmp_path / "logs.zarr", client=client, progress=False)
    logs = [stream.recent_message_log for stream in client.cluster.scheduler.stream_comms.values()]
    assert logs and all(log.maxlen == 100 for log in logs)
    tasks = [message for log in logs for batch in log if isinstance(batch, list) for message in batch
             if isinstance(message, dict) and message.get("op") == "compute-task"]
    sizes = [len(pickle.dumps(message)) for message in tasks]
    # A task's message is ~1.1 kB with its sample range; with its 4 drawn samples instead, as
    # before, 2.9-3.5 kB with this spec (checked).
    assert sizes and max(sizes) < 2000, sizes


def test_workers_check_they_see_the_store_before_any_task(client, tmp_path: Path) -> None:
    """Every worker is asked whether it sees the store at its absolute path; one that does not
    is named in one line (here the store moved after it was opened)."""
    from acoustisim.datasets.generate import check_workers_see_store
    from acoustisim.datasets.store import DatasetStoreError

    out = tmp_path / "seen.zarr"
    generate(loads_spec(small_spec(name="seen", n_samples=1, seed=3)), out, workers=0, progress=False)
    store = DatasetStore(out)
    check_workers_see_store(client, store)  # all see it: no error
    out.rename(tmp_path / "elsewhere.zarr")
    with pytest.raises(DatasetStoreError, match=r"^worker tcp://[^ ]+: .*seen\.zarr: no dataset store here as seen by "
                                                r"the process \d+ on host") as caught:
        check_workers_see_store(client, store)
    assert len(str(caught.value).splitlines()) == 1


def test_a_relative_out_reaches_workers_in_another_directory(client, tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """The workers run in another working directory than the driver; a relative --out still
    lands in the driver's directory (it is sent to them as an absolute path)."""
    worker_dirs = set(client.run(os.getcwd).values())
    monkeypatch.chdir(tmp_path)
    assert str(tmp_path) not in worker_dirs  # the situation of the bug: the paths differ
    spec = loads_spec(small_spec(name="rel", n_samples=4, seed=2))
    report = generate(spec, "rel.zarr", client=client, progress=False)
    assert report.n_complete == 4 and report.path == str(tmp_path / "rel.zarr")
    assert all(not Path(d, "rel.zarr").exists() for d in worker_dirs)


@pytest.mark.slow
def test_real_scheduler_relative_out_and_a_killed_worker(tmp_path: Path) -> None:
    """As a user runs it: ``dask scheduler`` and two ``dask worker`` processes (no nanny, in
    their own directory), ``generate --scheduler`` from another directory with a relative
    --out; then a second dataset during which one worker is killed (SIGKILL): the run still
    completes on the other, and the report says how many workers there were at the start and
    at the end."""
    import json

    scheduler_file = tmp_path / "scheduler.json"
    worker_dir = tmp_path / "workers"
    driver_dir = tmp_path / "driver"
    worker_dir.mkdir()
    driver_dir.mkdir()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    processes = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--port", "0",
                                   "--dashboard-address", ":0", "--scheduler-file", str(scheduler_file)],
                                  cwd=worker_dir, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  start_new_session=True)]
    try:
        deadline = time.monotonic() + 60
        while not scheduler_file.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(scheduler_file.read_text())["address"]
        for _ in range(2):
            processes.append(subprocess.Popen(
                [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--no-nanny",
                 "--dashboard-address", ":0"], cwd=worker_dir, env=env, stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL, start_new_session=True))
        from distributed import Client

        with Client(address, timeout="30s") as probe:
            probe.wait_for_workers(2, timeout=60)
        spec_file = driver_dir / "spec.toml"
        spec_file.write_text(SPEC)
        command = [sys.executable, "-m", "acoustisim.cli.main", "dataset", "generate", "spec.toml", "--out",
                   "rel.zarr", "--scheduler", address, "--no-progress"]
        done = subprocess.run(command, cwd=driver_dir, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        assert "16 / 16 samples complete" in done.stdout and "on 2 worker processes" in done.stdout
        assert not (worker_dir / "rel.zarr").exists()

        # Kill one worker once the second run has made a chunk.
        spec_file.write_text(SPEC.replace('name = "tiny-dask"', 'name = "kill"'))
        run = subprocess.Popen(command[:-4] + ["kill.zarr", "--scheduler", address, "--no-progress", "--json"],
                               cwd=driver_dir, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        flags = driver_dir / "kill.zarr" / "complete" / "c"
        deadline = time.monotonic() + 120
        while not (flags.exists() and any(flags.iterdir())) and time.monotonic() < deadline and run.poll() is None:
            time.sleep(0.05)
        assert run.poll() is None, "the run ended before the kill"
        os.killpg(processes[1].pid, signal.SIGKILL)
        out, err = run.communicate(timeout=300)
        assert run.returncode == 0, err
        report = json.loads(out)
        assert report["n_complete"] == 16
        assert (report["workers_at_start"], report["workers_at_end"], report["workers_lost"]) == (2, 1, 1)
    finally:
        for process in reversed(processes):
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def test_a_scheduler_without_workers_is_refused_in_one_line(client, tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """Tasks on a scheduler with no worker would wait for ever: the run stops first (the
    scheduler's worker list is emptied here; a real empty one gives the same set)."""
    import acoustisim.datasets.generate as generation
    from acoustisim.errors import InputError

    monkeypatch.setattr(generation, "worker_addresses", lambda c: set())
    with pytest.raises(InputError, match="no worker is connected to this scheduler"):
        generate(loads_spec(small_spec(name="none", n_samples=1, seed=1)), tmp_path / "n.zarr", client=client,
                 progress=False)
