"""The edge-target measurement of the seed's section 4.2.3 (range and angle sweeps).

Scene: the 9 m x 3 m x 1 m concrete tank of fresh water with one steel prism whose sharp
60-degree vertical edge (the seed's "sharp edge of a triangle", a point target in the
horizontal plane) faces the sonar at ``EDGE_M``. The prism is ``PRISM_SIZE_M`` deep, so its two
rear edges (which diffract more strongly than the front one, being seen near grazing) lie
about 0.43 m behind the front edge, outside the range gate.

One position: the sonar placed so that the edge is at a given range and bearing, the head
turned so that the line to the edge stays on the prism's bisector (``pose_for_target`` with
yaw = bearing); ``n_pings`` pings averaged (the seed's 50); the record gated to the edge's
range +/- ``GATE_HALF_WIDTH_M`` (blanking the main bang and the cross-talk); each detector's
earliest echo on the left and right channels gives the path lengths L = c TOF and the seed's
exact point solution (eqs. 4.30 and the corrected 4.31, ``binsonar.localization.point``).

The bound: the matched filter's TOF standard deviation at its estimated SNR (the Cramer-Rao
bound, ``Echo.tof_std_s``) propagated through the localiser's linearised covariance
(``seed_point_covariance``) to range and bearing.
"""

from __future__ import annotations

import math
import time
import warnings
from typing import Any

import numpy as np

from acoustisim.experiments.gating import gate_recording, range_window_s
from acoustisim.experiments.geometry import pose_for_target
from acoustisim.experiments.runner import Trial
from acoustisim.experiments.truth import object_truth
from acoustisim.scene import Scene, Tank

EDGE_M: tuple[float, float] = (6.0, 1.5)
"""Tank-frame (x, y) of the prism's sharp edge (m): 6 m from the near wall, mid-width."""
PRISM_SIZE_M = 0.5
"""Depth of the prism (m): its rear edges are 0.43 m behind the front edge."""
GATE_HALF_WIDTH_M = 0.2
"""Half depth of the range gate around the edge (m)."""
DETECTORS: tuple[str, ...] = ("threshold", "matched")
"""The seed's two detectors."""


def edge_tank_scene() -> Scene:
    """The thesis tank with only the steel 60-degree prism facing -x (toward the sonar)."""
    from acoustisim.medium import Medium
    from scenes.builders import default_sonar, edge_prism

    tank = Tank(length_m=9.0, width_m=3.0, water_depth_m=1.0, wall_material="concrete", floor_material="concrete")
    edge = edge_prism("edge", EDGE_M, 60.0, 180.0, PRISM_SIZE_M, tank.water_depth_m, "steel")
    medium = Medium(water="fresh", temperature_c=20.0, salinity_ppt=0.0, depth_m=0.5)
    return Scene(name="edge-tank", medium=medium, sonar=default_sonar(), tank=tank, objects=(edge,))


def estimate_point(echoes: tuple[Any, Any, Any], sound_speed_m_s: float, half_baseline_m: float) -> tuple[float, float]:
    """Range (m) and bearing (deg) from the left and right echoes; NaN when one is missing."""
    from binsonar.localization.point import point_from_path_lengths

    left, _, right = echoes
    if left is None or right is None:
        return float("nan"), float("nan")
    r, th = point_from_path_lengths(sound_speed_m_s * left.tof_s, sound_speed_m_s * right.tof_s, half_baseline_m)
    return float(r), float(np.degrees(th))


def bound_of(echoes: tuple[Any, Any, Any], range_m: float, bearing_deg: float, sound_speed_m_s: float,
             half_baseline_m: float) -> tuple[float, float]:
    """CRLB-derived std of range (m) and bearing (deg) from the echoes' ``tof_std_s``."""
    from binsonar.localization.point import seed_point_covariance

    left, _, right = echoes
    if left is None or right is None or not (math.isfinite(left.tof_std_s) and math.isfinite(right.tof_std_s)):
        return float("nan"), float("nan")
    cov = seed_point_covariance(range_m, math.radians(bearing_deg), half_baseline_m,
                                sound_speed_m_s * left.tof_std_s, sound_speed_m_s * right.tof_std_s)
    return float(math.sqrt(cov[0, 0])), float(math.degrees(math.sqrt(cov[1, 1])))


def solver_config(params: dict[str, Any]) -> Any:
    """Propagation settings of a trial: ``max_order`` (default 2: the gate holds no higher order) and,
    with ``reverberation`` False, no diffuse mechanism (no Lambert reverberation from the floor,
    surface, walls and the prism's faces)."""
    from acoustisim.propagation import SolverConfig
    from acoustisim.propagation.config import MECHANISMS

    mechanisms = MECHANISMS if params.get("reverberation", True) else tuple(m for m in MECHANISMS if m != "diffuse")
    return SolverConfig(max_order=int(params.get("max_order", 2)), mechanisms=mechanisms)


def measure_position(trial: Trial) -> dict[str, Any]:
    """Simulate and measure one position, ``repeats`` times (a module-level function for the runner).

    Trial parameters: ``range_m``, ``bearing_deg``, ``n_pings``, ``repeats``; optional
    ``detectors`` (tuple of method names), ``max_order`` and ``reverberation`` (propagation, see
    ``solver_config``).

    Returns
    -------
    dict
        ``range_m``, ``bearing_deg``, truth, ``solve_s``, ``simulate_s_per_ping``, and per
        detector lists over the repeats of ``range_est_m``, ``bearing_est_deg``,
        ``range_error_m``, ``bearing_error_deg``, ``detected``, ``elapsed_s``, ``snr_db``
        (left/right mean), ``bound_range_m``, ``bound_bearing_deg``.
    """
    from acoustisim.propagation import solve
    from acoustisim.simulation import simulate
    from binsonar.detection import detect

    p = dict(trial.params)
    range_m, bearing_deg = float(p["range_m"]), float(p["bearing_deg"])
    n_pings, repeats = int(p["n_pings"]), int(p["repeats"])
    detectors = tuple(p.get("detectors", DETECTORS))
    scene = edge_tank_scene()
    c = float(scene.medium.sound_speed)
    start_s, stop_s = range_window_s(range_m, c, GATE_HALF_WIDTH_M)
    template_s = 20e-6  # the record runs a template length past the gate, so the last echo is whole
    sonar = pose_for_target(scene.sonar, (*EDGE_M, scene.sonar.position_m[2]), range_m, bearing_deg,
                            yaw_deg=bearing_deg)
    from dataclasses import replace

    sonar = replace(sonar, record_length_s=stop_s + template_s)
    truth = object_truth(scene, sonar, scene.objects[0])
    half_baseline = float(sonar.separation_m)
    t, cpu = time.perf_counter(), time.process_time()
    paths = solve(scene, sonar, solver_config(p))
    solve_s, solve_cpu_s = time.perf_counter() - t, time.process_time() - cpu
    out: dict[str, Any] = {
        "range_m": range_m, "bearing_deg": bearing_deg,
        "truth_range_m": truth.range_m, "truth_bearing_deg": truth.bearing_deg,
        "sonar_position_m": list(sonar.position_m), "sonar_yaw_deg": sonar.yaw_deg,
        "gate_s": [start_s, stop_s], "solve_s": solve_s, "solve_cpu_s": solve_cpu_s, "n_pings": n_pings,
        "detectors": {m: {k: [] for k in ("range_est_m", "bearing_est_deg", "range_error_m", "bearing_error_deg",
                                          "detected", "elapsed_s", "cpu_s", "snr_db", "bound_range_m",
                                          "bound_bearing_deg")}
                      for m in detectors},
    }
    sim_s = sim_cpu_s = 0.0
    seeds = np.random.SeedSequence(trial.seed).generate_state(repeats, dtype=np.uint32)
    for k in range(repeats):
        t, cpu = time.perf_counter(), time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # arrivals past the short record are left out on purpose
            sim = simulate(scene, sonar, paths=paths, seed=int(seeds[k]), n_pings=n_pings, average=n_pings > 1)
        sim_s += time.perf_counter() - t
        sim_cpu_s += time.process_time() - cpu
        recording = gate_recording(sim.recording, start_s, stop_s + template_s)
        for method in detectors:
            cpu = time.process_time()
            result = detect(recording, method)
            cpu = time.process_time() - cpu
            echoes = result.first(0)
            r_est, b_est = estimate_point(echoes, c, half_baseline)
            r_sd, b_sd = bound_of(echoes, r_est, b_est, c, half_baseline) if method != "threshold" else (np.nan, np.nan)
            snrs = [e.snr_db for e in (echoes[0], echoes[2]) if e is not None]
            rec = out["detectors"][method]
            rec["range_est_m"].append(r_est)
            rec["bearing_est_deg"].append(b_est)
            rec["range_error_m"].append(r_est - truth.range_m)
            rec["bearing_error_deg"].append(b_est - truth.bearing_deg)
            rec["detected"].append(bool(math.isfinite(r_est)))
            rec["elapsed_s"].append(result.elapsed_s)
            rec["cpu_s"].append(cpu)
            rec["snr_db"].append(float(np.mean(snrs)) if snrs else float("nan"))
            rec["bound_range_m"].append(r_sd)
            rec["bound_bearing_deg"].append(b_sd)
    out["simulate_s_per_ping"] = sim_s / (repeats * n_pings)
    out["simulate_cpu_s_per_ping"] = sim_cpu_s / (repeats * n_pings)
    return out


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
        row["bound_range_m"], row["bound_bearing_deg"] = b_r, b_b
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
        if "matched" in detectors:
            row["matched"]["range_rms_over_bound"] = row["matched"]["range_rms_m"] / b_r if b_r > 0 else float("nan")
            row["matched"]["bearing_rms_over_bound"] = (row["matched"]["bearing_rms_deg"] / b_b
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
    if "matched" in detectors:
        ratios = np.array([r["matched"]["range_rms_over_bound"] for r in rows], dtype=float)
        summary["matched"]["max_range_rms_over_bound"] = finite_max(ratios)
        summary["matched"]["positions_within_1_5_bound"] = int(np.sum(ratios <= 1.5))
    return {"positions": rows, "summary": summary}
