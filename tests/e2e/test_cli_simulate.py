"""``acoustisim simulate`` on the command line (in-process: the verb, its JSON and exit codes)."""

from __future__ import annotations

import json

import h5py
import pytest

from acoustisim.cli.main import main
from binsonar.recording import read_recording


def test_simulate_builtin_scene_json(tmp_path, capsys):
    out = tmp_path / "ping.h5"
    assert main(["simulate", "free-sphere", "-o", str(out), "--seed", "3", "--pings", "2", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)  # one JSON object, nothing else on stdout
    assert report["n_pings"] == 2 and report["output"] == str(out)
    assert "specular" in {row["kind"] for row in report["arrivals"]}
    assert {row["channel"] for row in report["arrivals"]} == {"left", "centre", "right"}
    recording = read_recording(out)
    assert recording.waveforms.shape[:2] == (2, 3)
    with h5py.File(out) as h5:
        assert h5["truth/arrivals"].shape[0] == len(report["arrivals"])
    # Same seed, same bytes; the CLI adds nothing run-dependent to the file.
    again = tmp_path / "again.h5"
    assert main(["simulate", "free-sphere", "-o", str(again), "--seed", "3", "--pings", "2"]) == 0
    assert again.read_bytes() == out.read_bytes()


def test_simulate_snr_and_average(tmp_path, capsys):
    out = tmp_path / "avg.h5"
    assert main(["simulate", "free-sphere", "-o", str(out), "--snr-db", "20", "--pings", "3", "--average"]) == 0
    assert str(out) in capsys.readouterr().out
    recording = read_recording(out)
    assert recording.n_pings == 1 and recording.volts_per_code is None


@pytest.mark.parametrize(
    "args, needle",
    [
        (("no-such-scene",), "no-such-scene"),
        (("free-sphere", "--snr-db", "10", "--snr-echo", "nothing"), "nothing"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, args, needle):
    out = tmp_path / "bad.h5"
    assert main(["simulate", args[0], "-o", str(out), *args[1:]]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0]
    assert not out.exists()  # nothing written on bad input


@pytest.mark.parametrize("args", [("--snr-db", "nan"), ("--pings", "0"), ("--seed", "-2")])
def test_bad_option_values_are_usage_errors(tmp_path, capsys, args):
    """argparse's errors are one line naming the option and the value (the usage stays in --help)."""
    assert main(["simulate", "free-sphere", "-o", str(tmp_path / "x.h5"), *args]) == 2
    err = capsys.readouterr().err
    assert args[1] in err and args[0] in err and err.count("\n") == 1 and "usage:" not in err
