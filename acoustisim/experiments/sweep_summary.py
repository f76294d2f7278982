"""A sweep's summary: per position the RMS errors, bias and scatter against the bounds, and overall.

``summarise(positions, detectors)`` reads ``position_measurement.measure_position``'s results.
An efficient estimator's RMS error equals its Cramer-Rao bound; the ratios here say how far each
detector is from it (range and bearing), how much of its error is the bias of the noise-free
record (``noise_free_bias``) and how much the scatter about it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from acoustisim.experiments.edge_scene import NOISE_FREE_PARTS
from acoustisim.experiments.sweep_detectors import BOUNDED_DETECTORS


def finite_mean(values: Any) -> float:
    """Mean of the finite values (NaN, without a warning, when none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else float("nan")


def finite_max(values: Any) -> float:
    """Largest finite value (NaN, without a warning, when none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.max()) if v.size else float("nan")


def rms(values: list[float]) -> float:
    """RMS of the finite values (NaN when none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(v * v))) if v.size else float("nan")


def summarise(positions: list[dict[str, Any]], detectors: tuple[str, ...]) -> dict[str, Any]:
    """Per-position RMS errors, bounds and times, and the overall summary of a sweep."""
    rows = []
    for pos in positions:
        row: dict[str, Any] = {"range_m": pos["range_m"], "bearing_deg": pos["bearing_deg"],
                               "simulate_s_per_ping": pos["simulate_s_per_ping"],
                               "simulate_cpu_s_per_ping": pos.get("simulate_cpu_s_per_ping", float("nan")),
                               "solve_s": pos["solve_s"], "solve_cpu_s": pos.get("solve_cpu_s", float("nan"))}
        bound = pos["detectors"].get("matched", {})
        b_r = finite_mean(bound.get("bound_range_m", [])) if bound else float("nan")
        b_b = finite_mean(bound.get("bound_bearing_deg", [])) if bound else float("nan")
        # The bound: the CRLB at the averaged ping's true SNR (``noise_bound``); the detector's
        # own estimate (noise floor including the frozen reverberation) is kept for comparison.
        row["detector_bound_range_m"], row["detector_bound_bearing_deg"] = b_r, b_b
        b_r = float(pos.get("noise_bound_range_m", b_r))
        b_b = float(pos.get("noise_bound_bearing_deg", b_b))
        row["bound_range_m"], row["bound_bearing_deg"] = b_r, b_b
        row["optimal_bound_range_m"] = float(pos.get("optimal_bound_range_m", float("nan")))
        row["optimal_bound_bearing_deg"] = float(pos.get("optimal_bound_bearing_deg", float("nan")))
        row["reverb_bound_range_m"] = float(pos.get("reverb_bound_range_m", float("nan")))
        row["reverb_bound_bearing_deg"] = float(pos.get("reverb_bound_bearing_deg", float("nan")))
        row["reverb_to_noise_db"] = pos.get("reverb_to_noise_db")
        row["fresh_reverberation"] = bool(pos.get("fresh_reverberation", False))
        for m in detectors:
            d = pos["detectors"][m]
            row[m] = {
                "range_rms_m": rms(d["range_error_m"]),
                "bearing_rms_deg": rms(d["bearing_error_deg"]),
                "range_mean_error_m": finite_mean(d["range_error_m"]),
                "bearing_mean_error_deg": finite_mean(d["bearing_error_deg"]),
                "detection_rate": float(np.mean(d["detected"])),
                "elapsed_s": float(np.mean(d["elapsed_s"])),
                "cpu_s": float(np.mean(d["cpu_s"])) if d.get("cpu_s") else float("nan"),
                "snr_db": finite_mean(d["snr_db"]),
            }
        for m in detectors:
            parts = {part: pos.get("noise_free", {}).get(part, {}).get(m) for part in NOISE_FREE_PARTS}
            if parts["all"] is None:
                continue
            d = pos["detectors"][m]
            row[m]["bias_range_parts_m"] = {part: v["range_error_m"] for part, v in parts.items() if v is not None}
            row[m]["bias_tof_parts_s"] = {part: v["tof_error_s"] for part, v in parts.items() if v is not None}
            by_repeat = pos.get("noise_free_all_by_repeat")
            if by_repeat:
                # Fresh reverberation: every repeat has its own bias; the scatter is about each
                # repeat's own, and the bias shown (and its ``all`` part) is their RMS.
                bias_r = np.array([b[m]["range_error_m"] for b in by_repeat], dtype=float)
                bias_b = np.array([b[m]["bearing_error_deg"] for b in by_repeat], dtype=float)
                row[m]["bias_range_m"], row[m]["bias_bearing_deg"] = rms(bias_r), rms(bias_b)
                row[m]["bias_range_parts_m"]["all"] = rms(bias_r)
                row[m]["bias_range_per_repeat_m"] = [float(v) for v in bias_r]
            else:
                bias_r, bias_b = parts["all"]["range_error_m"], parts["all"]["bearing_error_deg"]
                row[m]["bias_range_m"], row[m]["bias_bearing_deg"] = bias_r, bias_b
            row[m]["scatter_range_rms_m"] = rms(np.asarray(d["range_error_m"], dtype=float) - bias_r)
            row[m]["scatter_bearing_rms_deg"] = rms(np.asarray(d["bearing_error_deg"], dtype=float) - bias_b)
        for m in BOUNDED_DETECTORS:
            if m not in detectors:
                continue
            mf = row[m]
            mf["range_rms_over_bound"] = mf["range_rms_m"] / b_r if b_r > 0 else float("nan")
            mf["bearing_rms_over_bound"] = mf["bearing_rms_deg"] / b_b if b_b > 0 else float("nan")
            rb = row["reverb_bound_range_m"]
            mf["range_rms_over_reverb_bound"] = mf["range_rms_m"] / rb if rb > 0 else float("nan")
            mf["scatter_range_rms_over_bound"] = (mf.get("scatter_range_rms_m", float("nan")) / b_r
                                                  if b_r > 0 else float("nan"))
            mf["scatter_bearing_rms_over_bound"] = (mf.get("scatter_bearing_rms_deg", float("nan")) / b_b
                                                    if b_b > 0 else float("nan"))
        rows.append(row)
    summary: dict[str, Any] = {
        "simulate_s_per_ping": float(np.mean([r["simulate_s_per_ping"] for r in rows])),
        "simulate_cpu_s_per_ping": float(np.mean([r["simulate_cpu_s_per_ping"] for r in rows])),
        "solve_s_per_position": float(np.mean([r["solve_s"] for r in rows])),
        "solve_cpu_s_per_position": float(np.mean([r["solve_cpu_s"] for r in rows])),
    }
    for m in detectors:
        summary[m] = {
            "elapsed_s_per_position": float(np.mean([r[m]["elapsed_s"] for r in rows])),
            "cpu_s_per_position": float(np.mean([r[m]["cpu_s"] for r in rows])),
            "max_range_rms_m": finite_max([r[m]["range_rms_m"] for r in rows]),
            "max_bearing_rms_deg": finite_max([r[m]["bearing_rms_deg"] for r in rows]),
            "detection_rate": float(np.mean([r[m]["detection_rate"] for r in rows])),
        }
    for m in BOUNDED_DETECTORS:
        if m not in detectors:
            continue
        ratios = np.array([r[m]["range_rms_over_bound"] for r in rows], dtype=float)
        summary[m]["max_range_rms_over_bound"] = finite_max(ratios)
        summary[m]["positions_within_1_5_bound"] = int(np.sum(ratios <= 1.5))
        bearing = np.array([r[m]["bearing_rms_over_bound"] for r in rows], dtype=float)
        summary[m]["positions_bearing_within_1_5_bound"] = int(np.sum(bearing <= 1.5))
        scatter = np.array([r[m]["scatter_range_rms_over_bound"] for r in rows], dtype=float)
        summary[m]["max_scatter_range_rms_over_bound"] = finite_max(scatter)
        summary[m]["positions_scatter_within_1_5_bound"] = int(np.sum(scatter <= 1.5))
        reverb = np.array([r[m]["range_rms_over_reverb_bound"] for r in rows], dtype=float)
        summary[m]["positions_within_1_5_reverb_bound"] = int(np.sum(reverb <= 1.5))
        summary[m]["max_range_rms_over_reverb_bound"] = finite_max(reverb)
        summary[m]["pooled_range_rms_over_reverb_bound"] = rms(reverb)
        # Pooled over positions: sqrt(mean((scatter / bound)^2)) is 1 for an efficient estimator.
        summary[m]["pooled_scatter_range_rms_over_bound"] = rms(scatter)
    return {"positions": rows, "summary": summary}
