"""Dataset generation in-process (no cluster): store layout, labels, verify, loader, CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from acoustisim.datasets.generate import generate, simulate_sample
from acoustisim.datasets.sampling import draw_sample
from acoustisim.datasets.spec import loads_spec
from acoustisim.datasets.store import ARRIVAL_FIELDS, OBJECT_FIELDS, SAMPLE_FIELDS, DatasetStore
from support.dataset_specs import small_spec

# Chunks [0, 1], [2, 3], [4]: a short last chunk too.
SPEC = small_spec(name="tiny", n_samples=5, seed=11, samples_per_chunk=2)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> tuple[object, Path]:
    spec = loads_spec(SPEC, "tiny.toml")
    out = tmp_path_factory.mktemp("ds") / "tiny.zarr"
    report = generate(spec, out, workers=0, progress=False)
    assert report.n_complete == report.n_generated == spec.n_samples
    return spec, out


def test_xarray_opens_the_store_and_labels_line_up_with_waveforms(dataset: tuple[object, Path]) -> None:
    """Sample k's waveforms and labels in the store are those of simulating sample k alone."""
    import xarray as xr

    spec, out = dataset
    ds = xr.open_zarr(out)
    assert ds.waveforms.dims == ("sample", "ping", "channel", "time")
    assert ds.waveforms.dtype == np.int16 and ds.sizes["sample"] == spec.n_samples
    assert list(ds.channel.values) == ["left", "centre", "right"]
    assert list(ds.arrival_field.values) == list(ARRIVAL_FIELDS)
    assert ds.complete.values.all()
    # Every array indexed by sample is chunked alike, so chunk k of each holds the same samples.
    assert {ds[name].encoding["chunks"][0] for name in ds.data_vars if ds[name].dims[0] == "sample"} == {2}
    field = {name: k for k, name in enumerate(SAMPLE_FIELDS)}
    for k in (1, 3):  # not in order, as a worker might see them
        sample = draw_sample(spec, k)
        scene, sim, _ = simulate_sample(spec, sample)
        np.testing.assert_array_equal(ds.waveforms.isel(sample=k).values, sim.codes)
        np.testing.assert_array_equal(ds.pose.isel(sample=k).values, sample.pose)
        values = ds.sample_values.isel(sample=k).values
        n = int(values[field["n_arrivals"]])
        arrivals = sim.paths.arrivals()
        assert n == min(arrivals.size, spec.max_arrivals) and n > 0
        stored = ds.arrivals.isel(sample=k).sel(arrival_field="delay_s").values
        np.testing.assert_array_equal(stored[:n], arrivals["delay_s"][:n])
        assert np.isnan(stored[n:]).all()
        assert values[field["n_objects"]] == len(sample.objects)
        assert values[field["temperature_c"]] == sample.temperature_c
        assert json.loads(ds.scene_json.isel(sample=k).values.item())["index"] == k
        objects = ds.objects.isel(sample=k).values
        names = ds.objects.attrs["classes"]
        labels = [names[int(c)] for c in objects[: len(sample.objects), OBJECT_FIELDS.index("class")]]
        assert labels == [o.label for o in sample.objects]
        np.testing.assert_array_equal(objects[: len(sample.objects), 3:6], [o.reference_m for o in sample.objects])


def test_object_range_and_bearing_labels_match_the_echo_delays(dataset: tuple[object, Path]) -> None:
    """Physical check of the labels: a sphere's centre-channel specular echo arrives at
    2 (range - radius) / c, range measured from the transmitter to the centre."""
    import xarray as xr

    spec, out = dataset
    ds = xr.open_zarr(out)
    checked = 0
    for k in range(spec.n_samples):
        objects = ds.objects.isel(sample=k).values
        arrivals = ds.arrivals.isel(sample=k).values
        c = float(ds.sample_values.isel(sample=k).sel(sample_field="sound_speed_m_s").values)
        surfaces = ds.arrivals.attrs["surfaces"]
        for slot, row in enumerate(objects):
            if not np.isfinite(row[0]) or ds.objects.attrs["kinds"][int(row[0])] != "sphere":
                continue
            surface = surfaces.index(f"object-{slot}")
            col = {name: i for i, name in enumerate(ARRIVAL_FIELDS)}
            hit = (arrivals[:, col["surface_0"]] == surface) & (arrivals[:, col["order"]] == 1) & (
                arrivals[:, col["channel"]] == 1)
            if not hit.any():
                continue  # dropped by the amplitude floor
            radius = json.loads(ds.scene_json.isel(sample=k).values.item())["objects"][slot]["parameters"][1][1]
            expected = 2.0 * (row[OBJECT_FIELDS.index("range_m")] - radius) / c
            # Exact geometry for a monostatic sphere echo; 1e-9 s covers float rounding only.
            assert arrivals[hit, col["delay_s"]][0] == pytest.approx(expected, abs=1e-9)
            checked += 1
    assert checked >= 2


def test_verify_passes_then_catches_a_corrupted_chunk(dataset: tuple[object, Path], tmp_path: Path) -> None:
    import shutil

    from acoustisim.datasets.verify import verify

    _, out = dataset
    copy = tmp_path / "copy.zarr"
    shutil.copytree(out, copy)
    report = verify(copy)
    assert report.ok and report.n_complete == 5 and not report.missing
    # Flip bytes in the middle of the waveform chunk file of samples 2 and 3.
    chunk = copy / "waveforms" / "c" / "1" / "0" / "0" / "0"
    data = bytearray(chunk.read_bytes())
    data[len(data) // 2] ^= 0xFF
    data[len(data) // 2 + 1] ^= 0x55
    chunk.write_bytes(bytes(data))
    # Rewrite sample 4's pose with valid but different data (decodes fine, checksum differs).
    store = DatasetStore(copy, mode="r+")
    store.array("pose")[4] = np.zeros(6)
    report = verify(copy)
    assert not report.ok
    corrupt = [i for i, _ in report.corrupt]
    # Either the chunk no longer decodes (both its samples unreadable) or it decodes to
    # different codes in one or both samples: only samples of that chunk, and sample 4.
    assert corrupt[-1] == 4 and corrupt[:-1] and set(corrupt[:-1]) <= {2, 3}
    assert "checksum" in report.corrupt[-1][1]


def test_resume_skips_complete_chunks_and_redoes_unrecorded_ones(dataset: tuple[object, Path], tmp_path: Path) -> None:
    """Clear the completion of samples 3 and 4 and scramble sample 3's waveforms (as a kill
    after the data write but before the flags would leave them): resuming rewrites their
    chunks, [2, 3] and [4], simulating exactly samples 3 and 4 (sample 2, complete and
    matching its checksum, is read back), and the store then equals the uninterrupted one."""
    import shutil

    spec, out = dataset
    copy = tmp_path / "resume.zarr"
    shutil.copytree(out, copy)
    store = DatasetStore(copy, mode="r+")
    store.array("complete")[3:5] = 0
    store.array("waveforms")[3] = np.ones_like(store.array("waveforms")[3])
    assert store.chunks_to_do() == [(2, 4), (4, 5)]
    report = generate(spec, copy, workers=0, progress=False)
    assert (report.n_skipped, report.n_generated, report.n_complete) == (3, 2, 5)
    a, b = DatasetStore(out), DatasetStore(copy)
    for k in range(spec.n_samples):
        for name, value in a.read_sample(k).items():
            np.testing.assert_array_equal(b.read_sample(k)[name], value)
    np.testing.assert_array_equal(a.checksums(), b.checksums())


def test_a_store_of_the_old_layout_is_refused_with_a_clear_message(dataset: tuple[object, Path],
                                                                   tmp_path: Path) -> None:
    import shutil

    from acoustisim.datasets.store import DatasetStoreError

    _, out = dataset
    copy = tmp_path / "old.zarr"
    shutil.copytree(out, copy)
    DatasetStore(copy, mode="r+").update_card(layout_version=1)
    with pytest.raises(DatasetStoreError, match=r"layout version 1, this acoustisim reads version 2"):
        DatasetStore(copy)


def test_a_chunk_is_written_whole_or_not_at_all(dataset: tuple[object, Path], tmp_path: Path) -> None:
    """The writer refuses anything but exactly one chunk's samples (no partial chunk file)."""
    import shutil

    _, out = dataset
    copy = tmp_path / "w.zarr"
    shutil.copytree(out, copy)
    store = DatasetStore(copy, mode="r+")
    writer = store.writer()
    from acoustisim.datasets.store import SampleArrays

    def row(i: int) -> SampleArrays:
        stored = store.read_sample(i)
        return SampleArrays(index=i, **stored)

    for bad in ([row(1), row(2)], [row(2)], [row(2), row(4)], []):
        with pytest.raises(ValueError, match="not the whole chunk"):
            writer.write_chunk(bad)
    checksums = writer.write_chunk([row(4)])  # the short last chunk, rewritten identically
    assert checksums.tolist() == [DatasetStore(out).checksums()[4]]


def test_resume_refuses_a_different_spec(dataset: tuple[object, Path]) -> None:
    from acoustisim.datasets.store import DatasetStoreError

    _, out = dataset
    other = loads_spec(SPEC.replace("seed = 11", "seed = 12"))
    with pytest.raises(DatasetStoreError, match="seed"):
        generate(other, out, workers=0, progress=False)


def test_loader_batches_and_torch_free_dataset(dataset: tuple[object, Path]) -> None:
    import sys

    import xarray as xr

    from acoustisim.datasets.loader import DatasetReader, WaveformDataset

    spec, out = dataset
    ds = xr.open_zarr(out)
    reader = DatasetReader(out)
    batches = list(reader.batches(2, shuffle=True, seed=0))
    assert [len(b["index"]) for b in batches] == [2, 2, 1]
    seen = np.concatenate([b["index"] for b in batches])
    assert sorted(seen) == list(range(spec.n_samples)) and list(seen) != list(range(spec.n_samples))
    for batch in batches:
        np.testing.assert_array_equal(batch["waveforms"], ds.waveforms.values[batch["index"]])
        np.testing.assert_array_equal(batch["objects"], ds.objects.values[batch["index"]])
        assert batch["n_objects"].tolist() == [len(draw_sample(spec, int(i)).objects) for i in batch["index"]]

    data = WaveformDataset(out, volts=True)
    assert len(data) == spec.n_samples
    waveforms, labels = data[3]
    scale = float(ds.sample_values.isel(sample=3).sel(sample_field="volts_per_code").values)
    np.testing.assert_allclose(waveforms, ds.waveforms.values[3] * scale, rtol=1e-6)
    assert waveforms.dtype == np.float32 and labels["index"] == 3
    assert (labels["object_class"] >= 0).sum() == labels["n_objects"]
    with pytest.raises(IndexError):
        data[spec.n_samples]
    assert "torch" not in sys.modules


def test_dataset_card_counts_and_snr_histogram(dataset: tuple[object, Path]) -> None:
    spec, out = dataset
    card = DatasetStore(out).card
    assert card["status"] == "complete" and card["spec"] == spec.to_dict()
    assert card["code_version"].startswith("acoustisim ")
    values = DatasetStore(out).array("sample_values")[:]
    snr = values[:, SAMPLE_FIELDS.index("snr_db")]
    assert sum(card["snr_histogram"]["counts"]) == np.isfinite(snr).sum()
    assert card["counts"]["n_complete"] == spec.n_samples
    assert sum(card["counts"]["objects_per_class"].values()) == card["counts"]["n_objects"]


def test_cli_info_verify_and_bad_spec(dataset: tuple[object, Path], tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    from acoustisim.cli.main import main

    _, out = dataset
    assert main(["dataset", "info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["n_complete"] == 5 and info["status"] == "complete"
    assert (info["samples_per_chunk"], info["layout_version"]) == (2, 2)
    assert main(["dataset", "verify", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ok"] is True
    bad = tmp_path / "bad.toml"
    bad.write_text(SPEC.replace('kind = "post"', 'kind = "donut"'))
    assert main(["dataset", "generate", str(bad), "--out", str(tmp_path / "x.zarr"), "--workers", "0"]) == 2
    err = capsys.readouterr().err
    assert "objects[1].kind" in err and "'donut'" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.zarr").exists()
    assert main(["dataset", "info", str(tmp_path)]) == 2  # not a store


def _assert_same_store(a: Path, b: Path, n: int) -> None:
    sa, sb = DatasetStore(a), DatasetStore(b)
    for k in range(n):
        for name, value in sa.read_sample(k).items():
            np.testing.assert_array_equal(sb.read_sample(k)[name], value, err_msg=f"sample {k} {name}")
    np.testing.assert_array_equal(sa.checksums(), sb.checksums())


def _damage_chunk_file(path: Path) -> None:
    """Cut a chunk file in half: its Zstandard frame no longer decodes (a flipped byte may
    decode to other values instead, which the checksum catches; see the pose edits)."""
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def test_repair_remakes_exactly_the_samples_that_fail_verification(dataset: tuple[object, Path], tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """Damage the waveform chunk of samples 0 and 1 (undecodable: both fail) and change
    sample 3's pose (decodes, checksum differs: only sample 3 fails, sample 2 of the same
    chunk is fine). A plain rerun sees a complete store and changes nothing; ``--repair``
    simulates exactly samples 0, 1 and 3, and the store equals the undamaged one."""
    import shutil

    from acoustisim.cli.main import main
    from acoustisim.datasets.verify import verify

    spec, out = dataset
    copy = tmp_path / "repair.zarr"
    shutil.copytree(out, copy)
    _damage_chunk_file(copy / "waveforms" / "c" / "0" / "0" / "0" / "0")
    DatasetStore(copy, mode="r+").array("pose")[3] = np.zeros(6)
    (copy / "pose" / "c" / "stray.partial").write_bytes(b"x")  # what a killed write leaves
    before = verify(copy)
    assert sorted(i for i, _ in before.corrupt) == [0, 1, 3] and before.stray_files
    assert generate(spec, copy, workers=0, progress=False).n_generated == 0  # resume alone does not look

    spec_file = tmp_path / "tiny.toml"
    spec_file.write_text(SPEC)
    assert main(["dataset", "generate", str(spec_file), "--out", str(copy), "--workers", "0", "--repair",
                 "--no-progress", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert (report["n_repaired"], report["n_generated"], report["n_complete"]) == (3, 3, 5)
    after = verify(copy)
    assert after.ok and not after.stray_files
    _assert_same_store(out, copy, spec.n_samples)


def test_repair_remakes_samples_whose_completion_record_is_damaged(dataset: tuple[object, Path],
                                                                   tmp_path: Path) -> None:
    """An undecodable chunk of ``complete`` counts its samples as not complete (verify says
    which), and the next run makes them again."""
    import shutil

    from acoustisim.datasets.verify import verify

    spec, out = dataset
    copy = tmp_path / "flags.zarr"
    shutil.copytree(out, copy)
    (copy / "complete" / "c" / "1").write_bytes(b"\x00not zstd")
    report = verify(copy)
    assert report.missing == (2, 3) and report.damaged_records == (2, 3) and not report.ok
    again = generate(spec, copy, workers=0, progress=False)
    assert (again.n_generated, again.n_complete) == (2, 5)
    assert verify(copy).ok
    _assert_same_store(out, copy, spec.n_samples)


def test_verify_cli_names_the_repair_command(dataset: tuple[object, Path], tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    import shutil

    from acoustisim.cli.main import main

    _, out = dataset
    copy = tmp_path / "v.zarr"
    shutil.copytree(out, copy)
    _damage_chunk_file(copy / "arrivals" / "c" / "2" / "0" / "0")
    assert main(["dataset", "verify", str(copy)]) == 1
    text = capsys.readouterr().out
    assert "sample 4: unreadable: the 'arrivals' chunk cannot be read" in text
    assert f"--out {copy.resolve()} --repair" in text


def test_reader_raises_a_typed_error_naming_the_damaged_samples(dataset: tuple[object, Path], tmp_path: Path) -> None:
    import shutil

    from acoustisim.datasets.loader import DatasetReader, WaveformDataset
    from acoustisim.datasets.store import DatasetCorruptError, DatasetStoreError

    _, out = dataset
    copy = tmp_path / "r.zarr"
    shutil.copytree(out, copy)
    _damage_chunk_file(copy / "waveforms" / "c" / "1" / "0" / "0" / "0")
    reader = DatasetReader(copy)
    reader.read([0, 1])  # other chunks still read
    with pytest.raises(DatasetCorruptError, match=r"sample\(s\) 2, 3: the 'waveforms' chunk cannot be read") as caught:
        reader.read([3, 2])
    assert isinstance(caught.value, DatasetStoreError) and isinstance(caught.value, ValueError)
    assert "--repair" in str(caught.value) and len(str(caught.value).splitlines()) == 1
    with pytest.raises(DatasetCorruptError, match="sample"):
        WaveformDataset(copy)[2]
    with pytest.raises(DatasetCorruptError, match=r"sample\(s\) 2: the 'waveforms'"):
        DatasetStore(copy).read_sample(2)


def test_open_dataset_gives_complete_samples_only(dataset: tuple[object, Path], tmp_path: Path) -> None:
    """Raw ``xr.open_zarr`` shows unfinished samples with placeholder values (zeros, NaN) and
    ``complete == 0``; :func:`open_dataset` keeps the complete samples, with their indices."""
    import shutil

    import xarray as xr

    from acoustisim.datasets import open_dataset

    spec, out = dataset
    copy = tmp_path / "partial.zarr"
    shutil.copytree(out, copy)
    store = DatasetStore(copy, mode="r+")
    store.array("complete")[2:4] = 0
    raw = xr.open_zarr(copy)
    assert raw.sizes["sample"] == 5 and raw.complete.values.tolist() == [1, 1, 0, 0, 1]
    ds = open_dataset(copy)
    assert ds.sample.values.tolist() == [0, 1, 4] and ds.attrs["n_samples_in_store"] == 5
    assert ds.complete.values.all()
    np.testing.assert_array_equal(ds.waveforms.sel(sample=4).values, raw.waveforms.isel(sample=4).values)
    assert "dataset_card" in ds.attrs
    from acoustisim.datasets.store import DatasetStoreError

    with pytest.raises(DatasetStoreError, match="not a dataset store"):
        open_dataset(tmp_path)


def test_a_relative_out_is_made_absolute(dataset: tuple[object, Path], tmp_path: Path,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """The store's arrays are opened (and pickled to workers) at its absolute path."""
    spec, _ = dataset
    monkeypatch.chdir(tmp_path)
    small = loads_spec(small_spec(name="tiny", n_samples=2, seed=11, samples_per_chunk=2))
    report = generate(small, "rel.zarr", workers=0, progress=False)
    assert report.path == str(tmp_path / "rel.zarr") and report.n_complete == 2
    writer = DatasetStore("rel.zarr").writer()
    assert writer.root == str(tmp_path / "rel.zarr")
    assert all(str(arr.store.root).startswith(str(tmp_path)) for arr in writer.arrays)


def test_a_writer_that_cannot_see_the_store_refuses_in_one_line(dataset: tuple[object, Path], tmp_path: Path) -> None:
    import shutil

    from acoustisim.datasets.store import DatasetStoreError, SampleArrays, store_seen_here

    _, out = dataset
    copy = tmp_path / "gone.zarr"
    shutil.copytree(out, copy)
    store = DatasetStore(copy, mode="r+")
    writer = store.writer()
    rows = [SampleArrays(index=i, **store.read_sample(i)) for i in (0, 1)]
    assert store_seen_here(writer.root, store.store_id) == ""
    assert "another dataset store" in store_seen_here(writer.root, "other-id")
    copy.rename(tmp_path / "moved.zarr")
    with pytest.raises(DatasetStoreError, match="no dataset store here as seen by the process") as caught:
        writer.write_chunk(rows)
    assert len(str(caught.value).splitlines()) == 1
    assert not copy.exists()  # nothing was written at the missing path
