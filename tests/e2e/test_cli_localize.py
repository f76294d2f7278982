"""``binsonar localize PING.h5 --json``."""

import json

import numpy as np
import pytest

from binsonar.cli.main import main
from binsonar.recording import Recording, write_recording
from support.localization_signals import G, synthetic_recording


def _write(tmp_path, **kw):
    rec, _ = synthetic_recording(np.array([[0.2, 1.0, 0.0]]), **kw)
    return write_recording(tmp_path / "ping.h5", rec)


def test_localize_json(tmp_path, capsys):
    path = _write(tmp_path, pose=[2.0, 1.5, 0.5, 90.0, 0.0, 0.0])
    assert main(["localize", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["method"] == "ca-cfar" and out["sound_speed_source"] == "recording"
    targets = out["pings"][0]["targets"]
    assert len(targets) == 1
    t = targets[0]
    assert t["class"] == "point"
    assert t["range_m"] == pytest.approx(np.hypot(0.2, 1.0), abs=1e-3)
    assert t["bearing_deg"] == pytest.approx(np.degrees(np.arctan2(0.2, 1.0)), abs=0.1)
    # Yaw 90: boresight along tank +y, the right receiver toward tank +x: (2.0 + 0.2, 1.5 + 1.0).
    assert t["position_tank_m"][:2] == pytest.approx([2.2, 2.5], abs=1e-3)
    assert t["range_std_m"] > 0 and t["bearing_std_deg"] > 0 and t["radius_std_m"] > 0
    assert set(t) >= {"radius_m", "status", "position_head_std_m", "position_tank_std_m"}


def test_localize_text_output_and_method(tmp_path, capsys):
    path = _write(tmp_path)
    assert main(["localize", str(path), "--method", "matched"]) == 0
    out = capsys.readouterr().out
    assert "ping 0: 1 target(s)" in out and "point" in out


def test_localize_without_sound_speed_exits_2(tmp_path, capsys):
    path = _write(tmp_path, store_c=False)
    assert main(["localize", str(path), "--json"]) == 2
    err = capsys.readouterr()
    assert "sound speed" in err.err and err.out == ""
    assert main(["localize", str(path), "--sound-speed", "1482", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["sound_speed_source"] == "argument"


def test_localize_bad_inputs_exit_2(tmp_path, capsys):
    assert main(["localize", str(tmp_path / "missing.h5")]) == 2
    assert "no such file" in capsys.readouterr().err
    path = _write(tmp_path)
    assert main(["localize", str(path), "--sound-speed", "-3"]) == 2
    assert "--sound-speed" in capsys.readouterr().err
    assert main(["localize", str(path), "--method", "no-such-method"]) == 2
    assert capsys.readouterr().err.startswith("binsonar: error:")


def test_recording_array_geometry_is_used(tmp_path, capsys):
    # Channel positions come from the file, not from a default.
    rec, _ = synthetic_recording(np.array([[0.0, 1.0, 0.0]]))
    moved = Recording(rec.waveforms, rec.sample_rate_hz, 0.0, G.receivers_m * 2, template=rec.template,
                      sound_speed_m_s=rec.sound_speed_m_s)
    path = write_recording(tmp_path / "moved.h5", moved)
    assert main(["localize", str(path), "--json"]) == 0
    t = json.loads(capsys.readouterr().out)["pings"][0]["targets"]
    # Paths made for d = 65 mm read with d = 130 mm: the centre echo no longer agrees with the side
    # pair (it expects the centre path 3 d^2 / (2 r) = 6 mm shorter; the gate's half-width is
    # d'^2 / (8 r) = 2 mm plus noise), and the side-only point is off.
    assert len(t) == 1 and t[0]["status"] == "no-centre-echo"
    assert abs(t[0]["position_head_m"][1] - 1.0) > 1e-3


def test_localize_beam_switch_and_pfa(tmp_path, capsys):
    # The synthetic recording has no array description: the times stay plain and the JSON says so.
    path = _write(tmp_path)
    assert main(["localize", str(path), "--json", "--pfa", "1e-4"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["beam_aware"] is False and out["beam"].startswith("off")
    assert out["pings"][0]["targets"][0]["echo_model"] is None
    assert main(["localize", str(path), "--no-beam"]) == 0
    assert "beam-aware timing: off" in capsys.readouterr().out
    for bad in (["--pfa", "0"], ["--pfa", "nan"], ["--tof-floor-ns", "1e9"]):
        assert main(["localize", str(path), *bad]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and bad[0] in err
