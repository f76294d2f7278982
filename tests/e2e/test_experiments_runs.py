"""The experiments at a tiny size: JSON fields and invariants (full runs are ``slow``)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from acoustisim.experiments.config import ExperimentConfig
from acoustisim.experiments.registry import experiment_module

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _run(name: str, out: Path, trials: int, **options) -> dict:
    config = ExperimentConfig(name=name, out_dir=out, seed=3, trials=trials, workers=1, progress=False,
                              options=options)
    report = experiment_module(name).run(config)
    files = report.write()
    payload = json.loads(Path(files["results"]).read_text())
    assert payload["experiment"] == name
    assert Path(files["report"]).read_text().startswith(f"# Experiment `{name}`")
    for figure in payload["figures"]:
        data = (out / figure).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 10_000
    return payload


def test_range_sweep_tiny(tmp_path: Path) -> None:
    # One ping per measurement at 1.2 and 2.2 m: a low SNR, where the seed found the matched filter
    # far better than the threshold detector.
    out = _run("range-sweep", tmp_path, 1, start=1.2, stop=2.2, step=1.0, pings=1)
    assert [p["range_m"] for p in out["positions"]] == [1.2, 2.2]  # one entry per position
    assert len(out["raw"]) == 2
    for p in out["positions"]:
        assert 0.0 <= p["threshold"]["detection_rate"] <= 1.0 and 0.0 <= p["matched"]["detection_rate"] <= 1.0
        assert p["matched"]["detection_rate"] == 1.0
        assert p["bound_range_m"] > 0 and p["bound_bearing_deg"] > 0
        # The threshold detector's first crossing comes before the envelope peak (a bias of
        # millimetres at these SNRs); the matched filter's error is a fraction of a millimetre.
        assert p["matched"]["range_rms_m"] < 0.5e-3
        if p["threshold"]["detection_rate"] == 1.0:
            assert p["matched"]["range_rms_m"] < p["threshold"]["range_rms_m"]
        assert p["simulate_s_per_ping"] > 0 and p["matched"]["elapsed_s"] > 0
        # The default detectors include the matched filter with the beam-aware refinement: the same
        # echoes, refined, so it detects whatever the matched filter detects, also within 0.5 mm.
        beam = p["beam-matched"]
        assert beam["detection_rate"] == p["matched"]["detection_rate"] and beam["range_rms_m"] < 0.5e-3
        assert beam["cpu_s"] >= p["matched"]["cpu_s"] and math.isfinite(beam["range_rms_over_bound"])
        assert abs(beam["bias_range_parts_m"]["edge"]) < abs(p["matched"]["bias_range_parts_m"]["edge"])
    s = out["summary"]
    assert set(s) >= {"simulate_s_per_ping", "solve_s_per_position", "threshold", "matched", "beam-matched"}
    assert s["matched"]["positions_within_1_5_bound"] <= 2
    assert 0 <= s["beam-matched"]["positions_bearing_within_1_5_bound"] <= 2


def test_angle_sweep_tiny_without_reverberation(tmp_path: Path) -> None:
    out = _run("angle-sweep", tmp_path, 1, start=-2.0, stop=2.0, step=4.0, pings=5, no_reverberation=True,
               range=1.0)
    assert out["reverberation"] is False
    assert [p["bearing_deg"] for p in out["positions"]] == [-2.0, 2.0]
    for raw in out["raw"]:
        assert raw["truth_bearing_deg"] == pytest.approx(raw["bearing_deg"], abs=1e-9)
        assert raw["truth_range_m"] == pytest.approx(1.0, abs=1e-9)
    for p in out["positions"]:
        # Without reverberation, at 5 averaged pings the matched filter's bearing error is well
        # inside 0.1 deg (its bound is ~0.03 deg; 5 bounds of margin for one sample).
        assert abs(p["matched"]["bearing_rms_deg"]) < 5 * p["bound_bearing_deg"]


def test_nine_methods_tiny(tmp_path: Path) -> None:
    out = _run("nine-methods", tmp_path, 4, pings_per_position=2, min_range=2.0, max_range=2.5, timing_repeats=1)
    assert out["positions"] == 2 and out["pings"] == 4
    # Timed on the whole acquired record as the seed did (not a cut-out around the target): the
    # default sonar's 12.5 ms at 20 MHz, 250,000 samples per channel; the search is gated instead.
    from acoustisim.experiments.edge_scene import edge_tank_scene

    sonar = edge_tank_scene().sonar
    full = int(round(sonar.record_length_s * sonar.sample_rate_hz))
    assert full == 250_000 and out["timed_samples"] == full
    assert out["timed_record_length_s"] == sonar.record_length_s and out["timing_repeats"] == 1
    for group in out["groups"]:
        assert group["timed_samples"] == full
        start_s, stop_s = group["search_window_s"]
        assert start_s < 2.0 * group["truth_range_m"] / 1482.0 < stop_s < sonar.record_length_s / 2
    assert set(out["cpu_time_ratios"]) == {"seed-9/seed-4", "seed-9/seed-8"}
    assert all(v > 0 for v in out["cpu_time_ratios"].values())
    summary = out["summary"]
    assert list(summary) == [f"seed-{k}" for k in range(1, 10)]
    for name, s in summary.items():
        averaged = name in ("seed-2", "seed-4", "seed-6", "seed-8", "seed-9")
        assert s["estimates"] == (2 if averaged else 4)  # one per position or one per ping
        assert 0.0 <= s["correct_rate"] <= 1.0
        assert 0 <= s["correct"] <= s["detected"] <= s["estimates"]
        assert s["time_per_ping_s"] > 0
    # Matched filtering of the averaged pings localises the edge at 2-2.5 m within 1 cm.
    assert summary["seed-4"]["correct_rate"] == 1.0
    for group in out["groups"]:
        assert 2.0 <= group["range_m"] <= 2.5 and abs(group["bearing_deg"]) <= 3.0


def test_same_seed_same_results(tmp_path: Path) -> None:
    a = _run("range-sweep", tmp_path / "a", 1, start=1.0, stop=1.0, step=0.1, pings=2, detectors="matched")
    b = _run("range-sweep", tmp_path / "b", 1, start=1.0, stop=1.0, step=0.1, pings=2, detectors="matched")
    ea = a["raw"][0]["detectors"]["matched"]["range_error_m"]
    eb = b["raw"][0]["detectors"]["matched"]["range_error_m"]
    assert ea == eb and all(math.isfinite(v) for v in ea)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["range-sweep", "angle-sweep", "nine-methods"])
def test_full_run(name: str, tmp_path: Path) -> None:
    config = ExperimentConfig(name=name, out_dir=tmp_path, seed=0, progress=False)
    report = experiment_module(name).run(config)
    report.write()
    payload = json.loads((tmp_path / "results.json").read_text())
    if name == "range-sweep":
        assert len(payload["positions"]) == 25
        # The matched filter beats the seed's 1 cm beyond the first half metre (see the report for
        # the short-range and reverberation limits).
        far = [p for p in payload["positions"] if p["range_m"] >= 0.6]
        assert max(p["matched"]["range_rms_m"] for p in far) < 0.01
        # The beam-aware refinement removes the beam's bias at every range (0.1 m included): what
        # is left of its noise-free bias is the frozen reverberation's, ~10 um at most.
        assert max(abs(p["beam-matched"]["bias_range_parts_m"]["edge"]) for p in payload["positions"]) < 2e-6
        assert max(p["beam-matched"]["range_rms_m"] for p in payload["positions"]) < 50e-6
    elif name == "angle-sweep":
        assert len(payload["positions"]) == 25
    else:
        rates = np.array([s["correct_rate"] for s in payload["summary"].values()])
        assert np.all((rates >= 0) & (rates <= 1))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["range-sweep", "angle-sweep"])
def test_full_sweep_with_fresh_reverberation_reaches_the_reverberation_bound(name: str, tmp_path: Path) -> None:
    """Over fresh realisations of the reverberation the beam-aware matched filter is close to
    efficient against the CRLB that counts the reverberation as Gaussian interference: measured
    (seed 0) pooled RMS ratio 0.97 (range) and 1.03 (angle), every position within 1.5x. With 8
    measurements per position an efficient estimator exceeds 1.5x at a position with probability
    2.1 %, and a few positions sit at a true ratio of 1.2-1.3, so up to two may exceed it; the
    pooled ratio over 25 positions is known to about +/-5 %, so 1.2 fails only a real loss."""
    config = ExperimentConfig(name=name, out_dir=tmp_path, seed=0, progress=False,
                              options={"fresh_reverberation": True})
    report = experiment_module(name).run(config)
    report.write()
    payload = json.loads((tmp_path / "results.json").read_text())
    assert payload["fresh_reverberation"] is True
    beam = payload["summary"]["beam-matched"]
    assert beam["positions_within_1_5_reverb_bound"] >= 23
    assert beam["pooled_range_rms_over_reverb_bound"] < 1.2
    for raw in payload["raw"]:
        assert raw["reverb_realisations"] == 8 and len(set(raw["diffuse_seeds"])) == 8
