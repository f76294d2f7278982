"""``binsonar import`` and ``--array``: a simulated recording exported to WAV, .npz and .mat (v5,
v7.3) with its array description gives the same detections, read directly or imported back."""

from __future__ import annotations

import json
import os
import warnings

import numpy as np
import pytest

from binsonar.cli.main import main
from binsonar.recording import read_recording
from support.foreign_files import array_toml, write_mat73, write_wav


@pytest.fixture(scope="module")
def simulated(tmp_path_factory, thesis_tank):
    """Two thesis-tank pings at 30 dB (int16 codes) and their exports, with one array TOML."""
    from dataclasses import replace

    from acoustisim.propagation.config import SolverConfig
    from acoustisim.simulation import simulate, write_simulation

    folder = tmp_path_factory.mktemp("import")
    sonar = replace(thesis_tank.sonar, record_length_s=2.5e-3)  # the posts and the prism within 1.8 m
    with warnings.catch_warnings():  # the record leaves out the far walls' arrivals, as intended
        warnings.simplefilter("ignore", UserWarning)
        sim = simulate(thesis_tank, sonar, seed=5, n_pings=2, snr_db=30.0, solver_config=SolverConfig(max_order=1))
    ping = write_simulation(folder / "ping.h5", sim)
    recording = read_recording(ping, keep_codes=True)
    np.save(folder / "pulse.npy", recording.template.samples)
    (folder / "array.toml").write_text(array_toml(recording.array, {
        "t0_s": recording.t0_s, "samples_per_ping": recording.n_samples, "template": "pulse.npy",
        "template_t0_s": recording.template.t0_s, "sound_speed_m_s": recording.sound_speed_m_s}))
    import scipy.io

    codes = recording.codes
    write_wav(folder / "ping.wav", codes, recording.sample_rate_hz, "PCM_16")
    np.savez(folder / "ping.npz", waveforms=codes)
    scipy.io.savemat(folder / "ping.mat", {"waveforms": codes})
    write_mat73(folder / "ping73.mat", {"waveforms": codes})
    return folder


def _detect(capsys, *argv):
    assert main(["detect", *argv, "--method", "matched", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    return [[c["echoes"] for c in p["channels"]] for p in report["pings"]]


@pytest.mark.parametrize("name", ["ping.wav", "ping.npz", "ping.mat", "ping73.mat"])
def test_exports_give_the_same_detections_directly_and_imported(simulated, capsys, name):
    reference = _detect(capsys, str(simulated / "ping.h5"))
    assert all(all(channel for channel in ping) for ping in reference)  # an echo on every channel
    direct = _detect(capsys, str(simulated / name), "--array", str(simulated / "array.toml"))
    out = simulated / f"imported-{name}.h5"
    assert main(["import", str(simulated / name), "--array", str(simulated / "array.toml"), "-o", str(out),
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["n_pings"] == 2 and summary["stored_as"] == "codes"
    imported = _detect(capsys, str(out))
    # The same int16 codes, template and times: the same numbers, not merely close ones.
    assert direct == reference and imported == reference
    assert read_recording(out).array.matches(read_recording(simulated / "ping.h5").array)


def test_localize_reads_an_export_directly(simulated, capsys):
    assert main(["localize", str(simulated / "ping.h5"), "--json"]) == 0
    reference = json.loads(capsys.readouterr().out)
    assert main(["localize", str(simulated / "ping.wav"), "--array", str(simulated / "array.toml"), "--json"]) == 0
    direct = json.loads(capsys.readouterr().out)
    # The export carries no poses: the same targets in the head frame, none in the tank frame.
    head_frame = ("class", "status", "range_m", "range_std_m", "bearing_deg", "bearing_std_deg", "position_head_m",
                  "tof_s")
    for ours, theirs in zip(direct["pings"], reference["pings"], strict=True):
        assert [{k: t[k] for k in head_frame} for t in ours["targets"]] == \
            [{k: t[k] for k in head_frame} for t in theirs["targets"]]
        assert all(t["position_tank_m"] is None for t in ours["targets"])
    assert direct["sound_speed_source"] == "recording"
    assert sum(len(p["targets"]) for p in direct["pings"]) >= 2


@pytest.mark.parametrize("target, message", [
    ("link", "symbolic link"), ("/dev/null", "device"), ("missing/x.h5", "does not exist"), ("", "empty"),
    ("input", "is the input"),
])
def test_bad_outputs_are_refused_before_reading(simulated, tmp_path, capsys, target, message):
    real = tmp_path / "real.h5"
    real.write_bytes(b"keep")
    (tmp_path / "link").symlink_to(real)
    paths = {"link": str(tmp_path / "link"), "missing/x.h5": str(tmp_path / "missing" / "x.h5"),
             "input": str(simulated / "ping.wav")}
    assert main(["import", str(simulated / "ping.wav"), "--array", str(simulated / "array.toml"), "-o",
                 paths.get(target, target)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and ".tmp" not in err[0]
    assert real.read_bytes() == b"keep" and (tmp_path / "link").is_symlink()


def test_imported_files_get_the_umask_mode(simulated, tmp_path, capsys):
    out = tmp_path / "mode.h5"
    assert main(["import", str(simulated / "ping.npz"), "--array", str(simulated / "array.toml"), "-o", str(out)]) == 0
    umask = os.umask(0)
    os.umask(umask)
    assert (out.stat().st_mode & 0o777) == 0o666 & ~umask
    assert "2 ping(s)" in capsys.readouterr().out
