"""The curvature report's prose follows the run it reports: its SNR, its noise, its cases; and
robust statistics stand beside the means."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from acoustisim.experiments import curvature
from acoustisim.experiments.report import ExperimentReport


def _values(noise_m: float, snr_db: float, rng: np.random.Generator, diverged: int = 0) -> list[dict]:
    """Case 3 positions with path-length errors of std ``noise_m`` and radius fits scattered by
    5 cm, ``diverged`` of them absurd (1e5 m)."""
    values = []
    for k, angle in enumerate(curvature.CASES["case3"]["values"]):
        radius, rng_m = 0.66, 3.91
        radii = radius + rng.normal(0.0, 0.05, 4)
        if k < diverged:
            radii[0] = 1e5
        methods = {m: {"radius_m": list(radii + (0.2 if m == "approximate" else 0.0)),
                       "range_m": list(rng_m + rng.normal(0, 1e-4, 4)),
                       "bearing_deg": list(angle + rng.normal(0, 0.01, 4))} for m in curvature.METHODS}
        values.append({"value": float(angle), "truth": {"radius_m": radius, "range_m": rng_m, "bearing_deg": angle},
                       "gated_clipped": False, "path_length_error_m": list(rng.normal(0.0, noise_m, (4, 3))),
                       "snr_db": [[snr_db] * 3] * 4, "methods": methods})
    return values


def _report(tmp_path: Path, noise_m: float, snr_db: float | None, measured_db: float, diverged: int = 0) -> str:
    rng = np.random.default_rng(1)
    summaries = {"case3": curvature.summarise_case(_values(noise_m, measured_db, rng, diverged))}
    report = ExperimentReport("curvature", tmp_path)
    curvature.write_report_text(report, summaries, None, 4, "matched", snr_db, 1.0)
    report.results = {}
    report.write()
    return (tmp_path / "report.md").read_text()


def test_a_low_snr_run_reports_its_own_snr_and_noise(tmp_path: Path) -> None:
    text = _report(tmp_path, 200e-6, 20.0, 20.0, diverged=3)
    assert "60-70 dB" not in text and "close to the seed's 2 um" not in text and "comparable" not in text
    assert "2E/N0 = 20 dB" in text and "set to 20 dB" in text
    assert "times the seed's 2 um" in text  # ~100 times
    assert "changes nothing here" in text  # the 0.5 um floor is irrelevant at 200 um of noise
    # Medians beside the means, and the diverged fits counted.
    assert "median |radius error| (mm)" in text and "radius fits diverged" in text
    row = next(line for line in text.splitlines() if line.startswith("| case3 | exact"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[4] == "3 / 48"
    assert float(cells[3]) > 1e6 > float(cells[2])  # the mean is set by the diverged fits; the median is not


def test_a_high_snr_run_says_the_studies_are_comparable(tmp_path: Path) -> None:
    text = _report(tmp_path, 2.2e-6, None, 65.0)
    assert "the simulator's noise models" in text and "comparable" in text
    assert "65 dB" in text
    assert "quantisation floor" in text and "changes nothing" not in text


def test_the_clutter_reading_follows_the_run() -> None:
    from acoustisim.experiments.clutter import reading_note

    def summary(pd_max: float, ladder: list[float]) -> dict:
        return {"all": {"threshold": {"pd_max": pd_max, "ladder_pd": ladder}}}

    under = reading_note(summary(0.2, [0.2, 0.5, 0.4, 0.3]), ["threshold", "ca-cfar"], 0, 12)
    assert "lies under its ladder's best point (P_D 0.5)" in under and "0.67 ms" in under
    assert "0 of 12 pings clipped" in under
    assert "one echo per channel" not in under  # no such detector in this run
    over = reading_note(summary(0.6, [0.6, 0.5, 0.4, 0.3]), ["threshold", "local-matched"], 2, 9)
    assert "did not capture it" in over and "lies under" not in over
    assert "(local-matched) cannot exceed one target" in over and "2 of 9 pings clipped" in over
    assert "threshold detector" not in reading_note(summary(0.6, [0.6]), ["ca-cfar"], 0, 3)
