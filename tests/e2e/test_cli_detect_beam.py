"""``binsonar detect --transducer-diameter-m``: the beam-aware refinement from the command line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from binsonar.cli.main import main
from binsonar.recording import Recording, write_recording
from support.beam_echoes import C, FS, POSITIONS, RADIUS, point_echoes, template


@pytest.fixture()
def point_file(tmp_path):
    # A point 0.2 m ahead: the side receivers see it 18 deg off their axes, past the 500 kHz null
    # of a 19 mm piston, so the plain matched filter's side TOFs are biased by > 100 ns.
    target = np.array([0.0, 0.2, 0.0])
    rows, truth, t0 = point_echoes(target, np.array([[0.0, 1.0, 0.0]] * 3))
    noisy = rows + np.random.default_rng(7).normal(0.0, 1e-4 * np.abs(rows).max(), (2, *rows.shape))
    recording = Recording(noisy, FS, t0, POSITIONS, template=template(), sound_speed_m_s=C, created_by="test")
    return write_recording(tmp_path / "point.h5", recording), truth


def _tofs(capsys) -> np.ndarray:
    report = json.loads(capsys.readouterr().out)
    return report["method"], np.array([[ch["echoes"][0]["tof_s"] for ch in p["channels"]] for p in report["pings"]])


def test_refinement_removes_the_beam_bias(point_file, capsys):
    path, truth = point_file
    assert main(["detect", str(path), "--method", "matched", "--json"]) == 0
    method, plain = _tofs(capsys)
    assert method == "matched" and np.max(np.abs(plain - truth)) > 100e-9
    args = ["detect", str(path), "--method", "matched", "--json", "--transducer-diameter-m", str(2 * RADIUS),
            "--beam-target", "point"]
    assert main(args) == 0
    method, refined = _tofs(capsys)
    # 2E/N0 ~ 60 dB: CRLB ~1.4 ns; 10 ns is 7 of them (as in test_beam_refine).
    assert method == "matched+beam" and np.max(np.abs(refined - truth)) < 10e-9


@pytest.mark.parametrize("args, message", [
    (["--method", "threshold", "--transducer-diameter-m", "0.019"], "envelope peak"),
    (["--method", "matched", "--beam-target", "point"], "need --transducer-diameter-m"),
    (["--method", "matched", "--transducer-diameter-m", "-1"], "--transducer-diameter-m must be within"),
    (["--method", "matched", "--transducer-diameter-m", "0.019", "--wedge-angle-deg", "200"], "wedge_interior"),
])
def test_bad_beam_options_exit_2(point_file, capsys, args, message):
    path, _ = point_file
    assert main(["detect", str(path), *args]) == 2
    assert message in capsys.readouterr().err
