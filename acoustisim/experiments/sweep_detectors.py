"""The sweeps' detector rows: binsonar's detectors on a gated record, and the point each gives.

Each detector's earliest echo on the left and right channels gives the path lengths L = c TOF
and the seed's exact point solution (eqs. 4.30 and the corrected 4.31,
``binsonar.localization.point``); its reported TOF stds give the detector's own bound
(``binsonar.estimation.point_bound``).

``BEAM_MATCHED`` ("beam-matched") is the matched filter's echoes refined by binsonar's
beam-aware TOF estimator (``binsonar.localization.beam_refine``) with the beams and the baseline
the recording's array description gives (``recording_array``: the simulated head's pistons, as
the simulator writes them into every recording) and the target class (``beam_config``: a vertical
edge, a rigid 60-degree wedge facing the sonar). Its CPU time includes the matched filter's pass,
which it shares with the "matched" row when both run.
"""

from __future__ import annotations

import math
import time
from typing import Any, NamedTuple

import numpy as np

from acoustisim.experiments.edge_scene import PRISM_ANGLE_DEG

DETECTORS: tuple[str, ...] = ("threshold", "matched")
"""The seed's two detectors."""
BEAM_MATCHED = "beam-matched"
"""The matched filter followed by binsonar's beam-aware TOF refinement
(``binsonar.localization.beam_refine``) with the simulated sonar's pistons and a vertical-edge
target: an experiment-level detector name (not a ``binsonar.detection`` method)."""
BOUNDED_DETECTORS: tuple[str, ...] = ("matched", BEAM_MATCHED)
"""Detectors whose errors are compared with the CRLB-derived bound (range and bearing RMS / bound)."""
TOF_MATCH_S = 5e-6
"""A noise-free echo further than this from the true TOF (s, one pulse length) is not the edge's."""


def estimate_point(echoes: tuple[Any, Any, Any], sound_speed_m_s: float, half_baseline_m: float) -> tuple[float, float]:
    """Range (m) and bearing (deg) from the left and right echoes; NaN when one is missing."""
    from binsonar.localization.point import point_from_path_lengths

    left, _, right = echoes
    if left is None or right is None:
        return float("nan"), float("nan")
    r, th = point_from_path_lengths(sound_speed_m_s * left.tof_s, sound_speed_m_s * right.tof_s, half_baseline_m)
    return float(r), float(np.degrees(th))


def echo_bound(echoes: tuple[Any, Any, Any], range_m: float, bearing_deg: float, sound_speed_m_s: float,
               half_baseline_m: float) -> tuple[float, float]:
    """Std of range (m) and bearing (deg) from the left and right echoes' ``tof_std_s``; NaN without both."""
    from binsonar.estimation import point_bound

    left, _, right = echoes
    if left is None or right is None or not (math.isfinite(left.tof_std_s) and math.isfinite(right.tof_std_s)):
        return float("nan"), float("nan")
    return point_bound(left.tof_std_s, right.tof_std_s, range_m, bearing_deg, sound_speed_m_s, half_baseline_m)


def nearest_echoes(result: Any, truth_tof_s: Any) -> tuple[Any, Any, Any]:
    """Per channel, the detected echo nearest the true TOF (None when none lies within ``TOF_MATCH_S``)."""
    out = []
    for ch, echoes in enumerate(result.echoes[0]):
        best = min(echoes, key=lambda e: abs(e.tof_s - truth_tof_s[ch]), default=None)
        out.append(best if best is not None and abs(best.tof_s - truth_tof_s[ch]) <= TOF_MATCH_S else None)
    return out[0], out[1], out[2]


def recording_array(recording: Any) -> tuple[float, Any]:
    """What binsonar learns from the recording about its head: half the left-right baseline (m,
    from its channel positions) and the beams (``recording.array.transducers()``: the simulated
    head's pistons, as the simulator describes them in every recording; None without a
    description)."""
    from binsonar.localization.array_geometry import ArrayGeometry

    half_baseline = ArrayGeometry.from_channel_positions(recording.channel_positions_m).half_baseline_m
    array = getattr(recording, "array", None)
    return half_baseline, (array.transducers() if array is not None else None)


def beam_config() -> Any:
    """binsonar's beam-aware refinement for the sweeps' target: a vertical edge, a rigid 60-degree
    wedge facing the sonar (``PRISM_ANGLE_DEG``; the head is turned so that it looks along the
    prism's bisector), the refinement's other settings at their defaults."""
    from binsonar.localization.beam_model import BeamModelConfig
    from binsonar.localization.beam_refine import BeamRefinementConfig

    return BeamRefinementConfig(model=BeamModelConfig(target="vertical-edge", wedge_interior_angle_deg=PRISM_ANGLE_DEG))


def beam_matched_echoes(recording: Any, echoes: tuple[Any, Any, Any], transducers: Any,
                        sound_speed_m_s: float) -> tuple[Any, Any, Any]:
    """Echoes of ping 0 (the matched filter's) refined by the beam-aware filter (``beam_config``).

    Parameters
    ----------
    recording : Recording
        The (gated, averaged) record the matched filter ran on.
    echoes : tuple of 3 Echo or None
        The matched filter's echoes of the edge on each channel.
    transducers : PistonTransducers
    sound_speed_m_s : float
    """
    from binsonar.localization.beam_refine import refine_echoes

    return refine_echoes(recording.waveforms[0], echoes, sample_rate_hz=recording.sample_rate_hz,
                         t0_s=recording.t0_s, template=recording.template,
                         channel_positions_m=recording.channel_positions_m, sound_speed_m_s=sound_speed_m_s,
                         transducers=transducers, config=beam_config())


class DetectorMeasurement(NamedTuple):
    """One detector on one record: its point, errors, times and bound (the fields of a sweep's raw rows)."""

    range_est_m: float
    bearing_est_deg: float
    range_error_m: float
    bearing_error_deg: float
    detected: bool
    elapsed_s: float
    cpu_s: float
    snr_db: float
    bound_range_m: float
    bound_bearing_deg: float


class PointGeometry(NamedTuple):
    """What turns echoes into a point: the sound speed (m/s), the half baseline d (m) and the
    truth's range (m) and bearing (deg) the errors are measured from."""

    sound_speed_m_s: float
    half_baseline_m: float
    range_m: float
    bearing_deg: float


def measure_detectors(recording: Any, detectors: tuple[str, ...], geometry: PointGeometry, transducers: Any,
                      threshold_options: dict[str, float]) -> dict[str, DetectorMeasurement]:
    """Run each detector on a (gated) record and measure its point (``DetectorMeasurement``).

    The matched filter runs once when both "matched" and ``BEAM_MATCHED`` are asked for: the
    beam-aware row refines its first echoes and counts its time.

    Parameters
    ----------
    recording : Recording
        One (averaged) ping.
    detectors : tuple of str
        binsonar methods or ``BEAM_MATCHED``.
    geometry : PointGeometry
    transducers : PistonTransducers
        For ``BEAM_MATCHED`` (``recording_array``).
    threshold_options : dict
        Options of the "threshold" detector (the sweep's calibrated level and amplitude), or {}.
    """
    from binsonar.detection import detect

    c, half_baseline = geometry.sound_speed_m_s, geometry.half_baseline_m
    out: dict[str, DetectorMeasurement] = {}
    matched_run: tuple[Any, float] | None = None  # the matched filter's result and CPU time (s), shared
    for method in detectors:
        cpu = time.process_time()
        if method == BEAM_MATCHED:  # the matched filter (run once for both rows), then the refinement
            if matched_run is None:
                matched_run = (detect(recording, "matched"), time.process_time() - cpu)
                cpu = time.process_time()
            result = matched_run[0]
            wall = time.perf_counter()
            echoes = beam_matched_echoes(recording, result.first(0), transducers, c)
            elapsed = result.elapsed_s + time.perf_counter() - wall
            cpu = time.process_time() - cpu + matched_run[1]
        else:
            result = detect(recording, method, **(threshold_options if method == "threshold" else {}))
            cpu = time.process_time() - cpu
            elapsed = result.elapsed_s
            if method == "matched":
                matched_run = (result, cpu)
            echoes = result.first(0)
        r_est, b_est = estimate_point(echoes, c, half_baseline)
        r_sd, b_sd = echo_bound(echoes, r_est, b_est, c, half_baseline) if method != "threshold" else (np.nan, np.nan)
        snrs = [e.snr_db for e in (echoes[0], echoes[2]) if e is not None]
        out[method] = DetectorMeasurement(
            range_est_m=r_est, bearing_est_deg=b_est, range_error_m=r_est - geometry.range_m,
            bearing_error_deg=b_est - geometry.bearing_deg, detected=bool(math.isfinite(r_est)), elapsed_s=elapsed,
            cpu_s=cpu, snr_db=float(np.mean(snrs)) if snrs else float("nan"), bound_range_m=r_sd,
            bound_bearing_deg=b_sd)
    return out
