"""``localization-accuracy``: bias and honesty of ``binsonar.localize``'s beam-aware estimates.

Targets: a thin rigid post (radius 5 mm) and a rigid 60-degree prism's sharp edge, each alone in
free field (the water of the thesis tank, no walls, floor or surface: their echoes would be
interference, not the localiser's error), 2 m tall and centred on the head's height. The prism
is 0.5 m deep and its bisector points at the transmitter (the head turned by the bearing, as in
the seed's sweeps): its rear corners lie 0.43 m behind the edge, outside the record, and no
other echo reaches it. The head is the default sonar (three 19 mm pistons, d = 65 mm), each
recording carries its array description, and ``binsonar.localize`` runs with its defaults
(CA-CFAR detection, beam-aware timing).

One trial = one position (target kind, range, bearing): the paths are traced once, then
``simulate(..., paths=..., n_pings=...)`` draws the pings in batches, each with white noise
setting 2E/N0 = ``snr_db`` of the target's echo on every channel, the receiver's attenuation set
so that the echo peaks at a quarter of the ADC's full scale (no clipping, quantisation far below
the noise). The record is gated to the target's range +/- ``GATE_HALF_WIDTH_M`` (a digitiser's
range window). Per ping, the target nearest the truth (``experiments.truth``: a post's axis, its
range to the nearest surface; the edge's point at the head's height) gives the range and
bearing errors and their reported stds; the pings' targets are also fused in groups of
``fuse_pings`` (``binsonar.localization.fuse``, all at the one pose).

Figures per position: the bias (mean error) with its standard error, the variance of the
normalised errors (error / reported std; 1 for an honest std, with a sampling std of
sqrt(2 / n) over n pings), the classes and expected-echo models chosen, the detection rate, and
the fused groups' errors; the ratio of the errors' scatter to the reported std (RMS over the
pings), 1 for an honest std. ``--no-beam`` runs the same pings through the plain matched filter's
times (``LocalizationConfig(beam=False)``), the "before" of issue 19. The command line:
``acoustisim experiment localization-accuracy`` (``--kinds``, ``--ranges``, ``--bearings``,
``--snr-db``, ``--fuse-pings``, ``--no-beam``, ``--echo-model``; ``--trials`` is the number of
pings per position). ``--echo-model point`` (or ``vertical-edge``) times every ping with that
expected echo (``LocalizationConfig.echo_model``) instead of the per-ping choice: the scatter
that the choice adds shows as the difference.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import replace
from typing import Any

import numpy as np

from acoustisim.experiments.config import ExperimentConfig
from acoustisim.experiments.report import ExperimentReport, markdown_table
from acoustisim.experiments.runner import Trial, make_trials, run_trials

NAME = "localization-accuracy"
SUMMARY = "posts and edges at 0.3-2.5 m, +/-10 deg: bias and normalised-error variance of binsonar's localiser"
DEFAULT_PINGS = 500
DEFAULT_RANGES_M: tuple[float, ...] = (0.3, 0.5, 0.8, 1.2, 1.8, 2.5)
DEFAULT_BEARINGS_DEG: tuple[float, ...] = (-10.0, -5.0, 0.0, 5.0, 10.0)
KINDS: tuple[str, ...] = ("post", "edge")
ECHO_MODEL_CHOICES: tuple[str, ...] = ("auto", "point", "vertical-edge")
"""``binsonar.localization.LocalizationConfig.echo_model``'s values (repeated: the parser is
built without importing binsonar's pipeline)."""
POST_RADIUS_M = 0.005
"""The thin post of issue 19."""
PRISM_SIZE_M = 0.5
"""Depth of the prism (m): its rear corners are 0.43 m behind the edge, outside the record."""
PRISM_ANGLE_DEG = 60.0
TARGET_HEIGHT_M = 2.0
"""Length of the post and the edge (m), centred on the head: their ends' echoes come at least
0.38 m of path after the target's at 2.5 m, outside the record."""
GATE_HALF_WIDTH_M = 0.1
"""Half depth (m) of the range window kept around the target."""
TEMPLATE_S = 30e-6
"""Record kept past the gate (s): the template's length, so the last echo is whole."""
ECHO_PEAK_V = 0.25
"""The target's noise-free echo peaks at this (V, a quarter of the ADC's 1 V full scale)."""
BATCH_PINGS = 25
"""Pings simulated at once (memory: 25 x 3 x 75,000 samples at 2.5 m)."""
MATCH_RANGE_M = 0.01
"""A ping's target further than this in range from the truth is not the target's."""
MATCH_BEARING_DEG = 2.0
"""... or further than this in bearing."""
BIAS_TOLERANCE = {"range_m": 0.05e-3, "bearing_deg": 0.02}
"""Issue 19's tolerances on the bias of one ping's estimates."""
FUSED_TOLERANCE = {"range_m": 0.2e-3, "bearing_deg": 0.05}
"""... and on a fused group's error."""
VARIANCE_TOLERANCE = 0.2
"""Issue 19's tolerance on the normalised errors' variance (1 +/- this)."""
COMPARABLE_CLASSES: tuple[str, ...] = ("point", "cylinder", "unknown")
"""Classes whose range and bearing are the truth's quantities (the reflecting surface's range, the
reflector's bearing): the statistics are over the pings so classified. A ping classified "plane"
reports a wall's perpendicular distance and normal instead (at 2.5 m a point's and a wall's
centre paths differ by d^2 / (4 r) = 0.4 mm, about 4 standard deviations at 30 dB): it is counted
apart, as a misclassification."""


def add_arguments(parser: Any) -> None:
    """``--kinds``, ``--ranges`` (m), ``--bearings`` (deg), ``--snr-db``, ``--fuse-pings``, ``--no-beam``, ``--echo-model``."""
    parser.add_argument("--kinds", nargs="+", choices=KINDS, default=None, help="targets (default: post edge)")
    parser.add_argument("--ranges", nargs="+", type=float, default=None,
                        help=f"ranges (m, default {' '.join(f'{r:g}' for r in DEFAULT_RANGES_M)})")
    parser.add_argument("--bearings", nargs="+", type=float, default=None,
                        help=f"bearings (deg, default {' '.join(f'{b:g}' for b in DEFAULT_BEARINGS_DEG)})")
    parser.add_argument("--snr-db", type=float, default=None, dest="snr_db", help="2E/N0 per channel (dB, default 30)")
    parser.add_argument("--fuse-pings", type=int, default=None, dest="fuse_pings",
                        help="pings per fused group (default 20)")
    parser.add_argument("--no-beam", action="store_true", default=None, dest="no_beam",
                        help="the plain matched filter's times (binsonar localize --no-beam), for comparison")
    parser.add_argument("--echo-model", choices=ECHO_MODEL_CHOICES, default=None, dest="echo_model",
                        help="expected echo of the beam-aware timing (default auto: chosen per ping)")


def target_scene(kind: str, range_m: float, bearing_deg: float) -> tuple[Any, Any, Any]:
    """The free-field scene of one position, its posed sonar (record ending after the gate) and the truth.

    Returns
    -------
    scene : Scene
    sonar : SonarHead
    truth : ObjectTruth
    """
    from acoustisim.experiments.gating import range_window_s
    from acoustisim.experiments.geometry import pose_for_target
    from acoustisim.experiments.truth import object_truth
    from acoustisim.medium import Medium
    from acoustisim.scene import Scene
    from scenes.builders import default_sonar, edge_prism, post

    half = 0.5 * TARGET_HEIGHT_M
    head = replace(default_sonar(), position_m=(0.0, 0.0, 0.0))
    if kind == "post":
        obj = post("post", (0.0, 0.0), POST_RADIUS_M, half, "rigid", bottom_m=-half)
        sonar = pose_for_target(head, (0.0, 0.0, 0.0), range_m + POST_RADIUS_M, bearing_deg, yaw_deg=0.0)
    elif kind == "edge":
        obj = edge_prism("edge", (0.0, 0.0), PRISM_ANGLE_DEG, 180.0, PRISM_SIZE_M, half, "rigid", bottom_m=-half)
        sonar = pose_for_target(head, (0.0, 0.0, 0.0), range_m, bearing_deg, yaw_deg=bearing_deg)
    else:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    medium = Medium(water="fresh", temperature_c=20.0, salinity_ppt=0.0, depth_m=0.5)
    scene = Scene(name=f"free-{kind}", medium=medium, sonar=sonar, tank=None, objects=(obj,))
    _, stop = range_window_s(range_m, float(medium.sound_speed), GATE_HALF_WIDTH_M)
    sonar = replace(sonar, record_length_s=stop + TEMPLATE_S)
    return scene, sonar, object_truth(scene, sonar, obj)


def target_paths(scene: Any, sonar: Any) -> Any:
    """The traced paths that arrive within the record (the prism's rear corners do not)."""
    from acoustisim.propagation import solve
    from acoustisim.propagation.config import SolverConfig
    from acoustisim.propagation.paths import Paths

    paths = solve(scene, sonar, SolverConfig(diffuse_rays=0))
    rows = paths.rows[paths.rows["delay_s"] < sonar.record_length_s - TEMPLATE_S]
    return Paths(rows, paths.surface_names, paths.centre_frequency_hz, paths.sound_speed_m_s, paths.responses)


def receiver_chain(scene: Any, sonar: Any, paths: Any, gate_start_s: float) -> Any:
    """The default receiver chain with the attenuation that puts the echo's peak at ``ECHO_PEAK_V``."""
    from acoustisim.simulation import simulate
    from acoustisim.synthesis.chain import ReceiverChain

    chain = ReceiverChain()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        clean = np.asarray(simulate(scene, sonar, paths=paths, chain=chain, snr_db=60.0).clean)
    first = int(math.ceil(gate_start_s * float(sonar.sample_rate_hz)))
    peak = float(np.max(np.abs(clean[:, first:])))
    attenuation = tuple(float(np.clip(a + 20.0 * math.log10(peak / ECHO_PEAK_V), 0.0, 68.0))
                        for a in chain.attenuation_db)
    return replace(chain, attenuation_db=attenuation)


def nearest_target(targets: Any, truth: Any) -> Any:
    """The ping's target nearest the truth in range, None beyond ``MATCH_RANGE_M`` / ``MATCH_BEARING_DEG``."""
    best = min(targets, key=lambda t: abs(t.range_m - truth.range_m) if math.isfinite(t.range_m) else math.inf,
               default=None)
    if best is None or not (abs(best.range_m - truth.range_m) <= MATCH_RANGE_M
                            and abs(best.bearing_deg - truth.bearing_deg) <= MATCH_BEARING_DEG):
        return None
    return best


def head_range_bearing(position_tank_m: Any, radius_m: float, sonar: Any) -> tuple[float, float]:
    """A fused tank position's range (to the surface: minus a finite radius) and bearing from the head."""
    from acoustisim.experiments.geometry import range_bearing_of

    r, b = range_bearing_of(sonar, np.asarray(position_tank_m, dtype=float))
    return (r - radius_m if math.isfinite(radius_m) and radius_m > 0 else r), b


def measure_position(trial: Trial) -> dict[str, Any]:
    """Simulate ``n_pings`` pings of one position and localise each (a module-level function for the runner)."""
    from acoustisim.experiments.gating import gate_recording, range_window_s
    from acoustisim.simulation import simulate
    from acoustisim.synthesis.pings import PingSynthesiser
    from binsonar.localization import LocalizationConfig, localize
    from binsonar.localization.fusion import fuse, observations_of

    p = dict(trial.params)
    kind, range_m, bearing_deg = str(p["kind"]), float(p["range_m"]), float(p["bearing_deg"])
    n_pings, snr_db, group = int(p["n_pings"]), float(p["snr_db"]), int(p["fuse_pings"])
    scene, sonar, truth = target_scene(kind, range_m, bearing_deg)
    c = float(scene.medium.sound_speed)
    start_s, stop_s = range_window_s(range_m, c, GATE_HALF_WIDTH_M)
    t0 = time.process_time()
    paths = target_paths(scene, sonar)
    chain = receiver_chain(scene, sonar, paths, start_s)
    synthesiser = PingSynthesiser.create(sonar, scene.medium, chain)
    solve_cpu_s = time.process_time() - t0
    config = LocalizationConfig(fuse=False, beam=bool(p.get("beam", True)),
                                echo_model=str(p.get("echo_model", "auto")))
    pose = np.array([*sonar.position_m, sonar.yaw_deg, sonar.pitch_deg, sonar.roll_deg])
    columns: dict[str, list[Any]] = {k: [] for k in ("range_error_m", "bearing_error_deg", "range_std_m",
                                                     "bearing_std_deg", "cls", "status", "echo_model")}
    found = []
    sim_cpu_s = loc_cpu_s = 0.0
    full_scale = float(chain.adc_full_scale_v)
    seeds = np.random.SeedSequence(trial.seed).generate_state((n_pings + BATCH_PINGS - 1) // BATCH_PINGS,
                                                             dtype=np.uint32)
    for batch, first in enumerate(range(0, n_pings, BATCH_PINGS)):
        count = min(BATCH_PINGS, n_pings - first)
        t0 = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sim = simulate(scene, sonar, paths=paths, chain=chain, seed=int(seeds[batch]), n_pings=count,
                           snr_db=snr_db, synthesiser=synthesiser)
        recording = gate_recording(sim.recording, start_s, stop_s + TEMPLATE_S)
        # Clipping within the window only (the main bang before it clips by design).
        clipped = np.max(np.abs(np.asarray(recording.waveforms)), axis=-1) >= full_scale * (1.0 - 1e-9)
        recording = replace(recording, clipped=clipped)
        sim_cpu_s += time.process_time() - t0
        t0 = time.process_time()
        result = localize(recording, config=config)
        loc_cpu_s += time.process_time() - t0
        for targets in result.targets:
            target = nearest_target(targets, truth)
            found.append(target)
            if target is None:
                continue
            columns["range_error_m"].append(target.range_m - truth.range_m)
            columns["bearing_error_deg"].append(target.bearing_deg - truth.bearing_deg)
            columns["range_std_m"].append(target.range_std_m)
            columns["bearing_std_deg"].append(target.bearing_std_deg)
            columns["cls"].append(target.cls)
            columns["status"].append(target.status)
            columns["echo_model"].append(target.echo_model)
    geometry = result.geometry
    fused_rows = []
    for g in range(0, n_pings - group + 1, group):
        members = [t.with_pose(pose) for t in found[g:g + group] if t is not None]
        if len(members) < max(3, group // 2):
            continue
        fused = fuse(observations_of(members), geometry, config.estimation)
        radius = fused.radius_m if fused.cls == "cylinder" else 0.0
        r, b = head_range_bearing(fused.position_tank_m, radius, sonar)
        fused_rows.append({"cls": fused.cls, "status": fused.status, "pings": len(members),
                           "range_error_m": r - truth.range_m, "bearing_error_deg": b - truth.bearing_deg,
                           "radius_m": fused.radius_m})
    return {"kind": kind, "range_m": range_m, "bearing_deg": bearing_deg, "n_pings": n_pings, "snr_db": snr_db,
            "truth_range_m": truth.range_m, "truth_bearing_deg": truth.bearing_deg, "truth_cls": truth.cls,
            "attenuation_db": list(chain.attenuation_db), "beam": result.beam, "detected": len(columns["cls"]),
            **columns, "fused": fused_rows, "solve_cpu_s": solve_cpu_s, "simulate_cpu_s": sim_cpu_s,
            "localize_cpu_s": loc_cpu_s}


def summarise(raw: dict[str, Any]) -> dict[str, Any]:
    """Bias, its standard error, the normalised errors' variance and the fused errors of one position."""
    out: dict[str, Any] = {k: raw[k] for k in ("kind", "range_m", "bearing_deg", "n_pings", "detected", "truth_cls")}
    comparable = np.isin(np.asarray(raw["cls"], dtype=str), COMPARABLE_CLASSES)
    out["compared"] = int(comparable.sum())
    for name in ("range", "bearing"):
        unit = "m" if name == "range" else "deg"
        error = np.asarray(raw[f"{name}_error_{unit}"], dtype=float)[comparable]
        std = np.asarray(raw[f"{name}_std_{unit}"], dtype=float)[comparable]
        n = error.size
        out[f"{name}_bias_{unit}"] = float(np.mean(error)) if n else math.nan
        out[f"{name}_bias_se_{unit}"] = float(np.std(error, ddof=1) / math.sqrt(n)) if n > 1 else math.nan
        out[f"{name}_scatter_{unit}"] = float(np.std(error, ddof=1)) if n > 1 else math.nan
        out[f"{name}_reported_std_{unit}"] = float(np.sqrt(np.mean(std ** 2))) if n else math.nan
        out[f"{name}_normalised_variance"] = float(np.var(error / std, ddof=1)) if n > 1 else math.nan
        out[f"{name}_scatter_to_reported"] = (out[f"{name}_scatter_{unit}"] / out[f"{name}_reported_std_{unit}"]
                                              if n > 1 else math.nan)
        fused = np.asarray([f[f"{name}_error_{unit}"] for f in raw["fused"]], dtype=float)
        out[f"fused_{name}_max_abs_error_{unit}"] = float(np.max(np.abs(fused))) if fused.size else math.nan
        out[f"fused_{name}_mean_error_{unit}"] = float(np.mean(fused)) if fused.size else math.nan
    out["classes"] = {c: raw["cls"].count(c) for c in sorted(set(raw["cls"]))}
    out["echo_models"] = {m or "plain": raw["echo_model"].count(m) for m in sorted(set(raw["echo_model"]))}
    out["fused_classes"] = {c: [f["cls"] for f in raw["fused"]].count(c) for c in sorted({f["cls"] for f in raw["fused"]})}
    out["fused_groups"] = len(raw["fused"])
    out["within_tolerance"] = within_tolerance(out)
    return out


def within_tolerance(s: dict[str, Any]) -> dict[str, bool]:
    """Issue 19's criteria for one position."""
    return {
        "bias": all(abs(s[f"{k.split('_')[0]}_bias_{k.split('_')[1]}"]) <= tol for k, tol in BIAS_TOLERANCE.items()),
        "variance": all(abs(s[f"{name}_normalised_variance"] - 1.0) <= VARIANCE_TOLERANCE
                        for name in ("range", "bearing")),
        "fused": all(s[f"fused_{k.split('_')[0]}_max_abs_error_{k.split('_')[1]}"] <= tol
                     for k, tol in FUSED_TOLERANCE.items()),
        "detected": s["detected"] == s["n_pings"],
    }


def run(config: ExperimentConfig) -> ExperimentReport:
    """Measure every (kind, range, bearing); ``config.trials`` is the number of pings per position."""
    from acoustisim.errors import InputError

    kinds = tuple(config.option("kinds", KINDS))
    ranges = tuple(float(r) for r in config.option("ranges", DEFAULT_RANGES_M))
    bearings = tuple(float(b) for b in config.option("bearings", DEFAULT_BEARINGS_DEG))
    snr_db = float(config.option("snr_db", 30.0))
    group = int(config.option("fuse_pings", 20))
    n_pings = config.trials_or(DEFAULT_PINGS)
    beam = not bool(config.option("no_beam", False))
    echo_model = str(config.option("echo_model", "auto"))
    if not all(0.2 <= r <= 5.0 for r in ranges) or not all(-20.0 <= b <= 20.0 for b in bearings):
        raise InputError(f"localization accuracy: ranges must be within 0.2-5 m and bearings within +/-20 deg, got "
                         f"{list(ranges)}, {list(bearings)}")
    if echo_model not in ECHO_MODEL_CHOICES:
        raise InputError(f"localization accuracy: echo_model must be one of {', '.join(ECHO_MODEL_CHOICES)}, got "
                         f"{echo_model!r}")
    if not (2 <= n_pings <= 100_000 and 1 <= group <= n_pings and 5.0 <= snr_db <= 80.0):
        raise InputError(f"localization accuracy: need 2 <= pings <= 100000, 1 <= fuse pings <= pings and "
                         f"5 <= snr_db <= 80, got {n_pings}, {group}, {snr_db}")
    params = [{"kind": k, "range_m": r, "bearing_deg": b, "n_pings": n_pings, "snr_db": snr_db, "fuse_pings": group,
               "beam": beam, "echo_model": echo_model}
              for k in kinds for r in ranges for b in bearings]
    wall = time.perf_counter()
    raw = run_trials(measure_position, make_trials(config.seed, params), workers=config.workers,
                     description=NAME, progress=config.progress)
    wall_s = time.perf_counter() - wall
    positions = [summarise(r) for r in raw]
    report = ExperimentReport(NAME, config.out_dir)
    passed = {k: sum(p["within_tolerance"][k] for p in positions) for k in ("bias", "variance", "fused", "detected")}
    report.results.update({"positions": positions, "raw": raw, "n_pings": n_pings, "snr_db": snr_db,
                           "fuse_pings": group, "beam": beam, "echo_model": echo_model, "wall_s": wall_s,
                           "passed": passed,
                           "tolerances": {"bias": BIAS_TOLERANCE, "fused": FUSED_TOLERANCE,
                                          "normalised_variance": VARIANCE_TOLERANCE}})
    report.add_section(__doc__.split("\n\n", 1)[1].split("The command line")[0].strip())
    header = ["target", "range (m)", "bearing (deg)", "detected", "compared", "range bias (um)", "+/- (um)",
              "bearing bias (mdeg)", "+/- (mdeg)", "range var(e/sd)", "bearing var(e/sd)", "range sd (um)",
              "bearing sd (mdeg)", "range sd / reported", "bearing sd / reported", "fused max |range err| (um)",
              "fused max |bearing err| (mdeg)", "classes", "echo models"]
    rows = []
    for s in positions:
        rows.append([s["kind"], s["range_m"], s["bearing_deg"], f"{s['detected']}/{s['n_pings']}", s["compared"],
                     s["range_bias_m"] * 1e6, 2 * s["range_bias_se_m"] * 1e6, s["bearing_bias_deg"] * 1e3,
                     2 * s["bearing_bias_se_deg"] * 1e3, s["range_normalised_variance"],
                     s["bearing_normalised_variance"], s["range_scatter_m"] * 1e6, s["bearing_scatter_deg"] * 1e3,
                     s["range_scatter_to_reported"], s["bearing_scatter_to_reported"],
                     s["fused_range_max_abs_error_m"] * 1e6, s["fused_bearing_max_abs_error_deg"] * 1e3,
                     ", ".join(f"{k} {v}" for k, v in s["classes"].items()),
                     ", ".join(f"{k} {v}" for k, v in s["echo_models"].items())])
    report.add_section(f"{n_pings} pings per position at 2E/N0 = {snr_db:g} dB; fused groups of {group} pings; "
                       f"{'beam-aware timing (the default)' if beam else 'plain matched-filter times (--no-beam)'}. "
                       "+/- is twice the bias's standard error. The statistics are over the pings classified "
                       f"{', '.join(COMPARABLE_CLASSES)} (\"compared\"; see \"classes\" for the others). Issue 19's criteria: |bias| within 50 um and 20 mdeg "
                       f"({passed['bias']} of {len(positions)} positions), var(e/sd) within 1 +/- 0.2 for range and "
                       f"bearing ({passed['variance']}), every fused group within 200 um and 50 mdeg "
                       f"({passed['fused']}), every ping's target found ({passed['detected']}). "
                       f"Wall time {wall_s:.0f} s.")
    report.add_section(markdown_table(header, rows))
    return report
