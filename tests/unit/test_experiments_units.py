"""Record gating, echo labels, the experiment registry and the experiment verb's bad input."""

from __future__ import annotations

import numpy as np
import pytest

from acoustisim.errors import InputError
from acoustisim.experiments.gating import BLANKING_S, gate_recording, range_window_s
from acoustisim.experiments.labels import label_echo, path_label
from acoustisim.experiments.registry import experiment_module, experiment_names
from binsonar.recording import Recording, Template


def _recording(n: int = 1000, fs: float = 1e6) -> Recording:
    rng = np.random.default_rng(1)
    return Recording(waveforms=rng.standard_normal((2, 3, n)), sample_rate_hz=fs, t0_s=0.0,
                     template=Template(np.hanning(16), fs), sound_speed_m_s=1482.0, pose=np.zeros((2, 6)))


def test_gate_keeps_samples_at_their_times() -> None:
    rec = _recording()
    gated = gate_recording(rec, 100.4e-6, 300e-6)
    # Sample k of the gated record is at t0 + k / fs and equals the original sample at that time.
    k0 = int(round(gated.t0_s * rec.sample_rate_hz))
    assert k0 == 100  # floor of 100.4 us at 1 MHz: the gate starts on a sample
    np.testing.assert_array_equal(gated.waveforms, rec.waveforms[..., 100:301])
    assert gated.template is rec.template and gated.sound_speed_m_s == rec.sound_speed_m_s
    assert gated.pose.shape == (2, 6)


def test_gate_rejects_an_empty_window() -> None:
    with pytest.raises(ValueError, match="fewer than 2 samples"):
        gate_recording(_recording(), 2.0, 3.0)


def test_range_window() -> None:
    start, stop = range_window_s(1.0, 1500.0, 0.2)
    assert start == pytest.approx(2 * 0.8 / 1500.0) and stop == pytest.approx(2 * 1.2 / 1500.0)
    # Near the head the blanking wins: nothing before the cross-talk has died down.
    assert range_window_s(0.1, 1500.0, 0.2)[0] == BLANKING_S


def test_path_labels() -> None:
    boundaries = ["wall-x0", "floor", "surface"]
    assert path_label([], boundaries) == "direct path"
    assert path_label(["post-1"], boundaries) == "post-1"
    assert path_label(["floor", "post-1"], boundaries) == "post-1 via floor"
    assert path_label(["floor", "post-1", "surface"], boundaries) == "post-1 via floor+surface"
    assert path_label(["floor", "surface"], boundaries) == "floor+surface"
    assert path_label(["edge-1", "post-2"], boundaries) == "edge-1+post-2"


def test_label_echo_picks_the_strongest_arrival_in_the_window() -> None:
    dtype = [("channel", "i1"), ("delay_s", "f8"), ("kind", "i1"), ("amplitude", "f8")]
    arrivals = np.array([(0, 1e-3, 1, 0.1), (0, 1.0005e-3, 3, 0.5), (0, 1.5e-3, 1, 1.0), (1, 1e-3, 1, 9.0),
                         (0, 0.0, 0, 99.0)], dtype=dtype)
    labels = ["a", "b", "c", "d", "direct"]
    assert label_echo(arrivals, labels, 0, 1.0002e-3) == ("b (diffuse)", pytest.approx(1.0005e-3))
    assert label_echo(arrivals, labels, 0, 1.2e-3)[0] == "unexplained"
    assert label_echo(arrivals, labels, 0, 0.0)[0] == "unexplained"  # the direct path is not an echo


def test_a_ringing_elastic_echo_names_its_late_peak_before_a_weak_arrival_nearer_it() -> None:
    # The pipe's elastic echo peaks ~3 us after its specular delay; a chain grazing another post,
    # 40 dB weaker, lies 0.5 us from that peak: the echo is the pipe's.
    dtype = [("path_id", "i8"), ("channel", "i1"), ("delay_s", "f8"), ("kind", "i1"), ("amplitude", "f8")]
    arrivals = np.array([(7, 1, 4.6517e-3, 1, 4e-3), (8, 1, 4.6539e-3, 1, 4.8e-5)], dtype=dtype)
    internal = np.array([(7, 1, 2, b"wall", 4.6557e-3, 4e-6, -20.0)],
                        dtype=[("path_id", "i8"), ("channel", "i1"), ("object_id", "i2"), ("arrival", "S40"),
                               ("delay_s", "f8"), ("after_echo_s", "f8"), ("level_db", "f8")])
    labels = ["pipe-1", "post-2+pipe-1"]
    tof = 4.6545e-3
    assert label_echo(arrivals, labels, 1, tof)[0] == "post-2+pipe-1"  # without the elastic truth
    assert label_echo(arrivals, labels, 1, tof, internal=internal, resolution_s=4e-6)[0] == "pipe-1"


def test_registry_finds_the_experiments() -> None:
    names = experiment_names()
    for name in ("range-sweep", "angle-sweep", "nine-methods"):
        assert name in names
        module = experiment_module(name)
        assert callable(module.run) and module.NAME == name
    # Helper modules are not experiments.
    assert "runner" not in names and "report" not in names
    with pytest.raises(InputError, match="unknown experiment 'nope'.*range-sweep"):
        experiment_module("nope")


@pytest.mark.parametrize("argv, message", [
    (["experiment", "range-sweep", "--trials", "0"], "--trials must be >= 1"),
    (["experiment", "range-sweep", "--workers", "0"], "--workers must be >= 1"),
    (["experiment", "range-sweep", "--start", "3", "--stop", "1"], "range sweep: need"),
    (["experiment", "angle-sweep", "--detectors", "bogus"], "--detectors bogus: unknown method"),
    (["experiment", "nine-methods", "--pings-per-position", "0"], "must be >= 1"),
    (["demo", "--method", "bogus"], "--method 'bogus': unknown"),
    (["demo", "--pings", "0"], "--pings must be >= 1"),
])
def test_bad_input_is_one_line_and_exit_2(argv: list[str], message: str, capsys: pytest.CaptureFixture[str],
                                          tmp_path) -> None:
    from acoustisim.cli.main import main

    code = main(argv + ["--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()  # nothing written


def test_a_module_that_fails_to_import_does_not_hide_the_others(monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib

    from acoustisim.experiments import registry

    real = importlib.import_module

    def fake(name: str, package: str | None = None):
        if name.endswith(".range_sweep"):
            raise SyntaxError("half-written module")
        return real(name, package)

    monkeypatch.setattr(registry.importlib, "import_module", fake)
    modules, broken = registry.discover()
    assert "range-sweep" not in modules and "angle-sweep" in modules
    assert broken == {"range_sweep": "SyntaxError: half-written module"}
    with pytest.raises(InputError, match="failed to import: range_sweep"):
        registry.experiment_module("range-sweep")
