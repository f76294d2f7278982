"""``clutter``: detectors in cluttered tank scenes (ROC, localisation error, association, time).

Scenes: ``clutter_scenes.cluttered_scene``: the thesis tank with a rough sand floor and 1-8
random posts, edge prisms, short cylinders and spheres in front of the sonar (default pose).
Each trial is one scene of one clutter density: its paths are traced once (first and second
order, specular, edge and diffuse with ``DIFFUSE_RAYS`` rays) and one ping is synthesised at
each SNR (``snr_db``: 2E/N0 of the strongest target echo, white noise replacing the noise
models), recorded for ``RECORD_S`` and gated past the main bang and the cross-talk
(``gating.BLANKING_S``). The receive attenuation of each scene is set, like an operator's gain,
from a probe ping so that the strongest echo peaks at ``ECHO_PEAK_V``.

Each detector runs on a ping at a ladder of threshold settings (``LADDER``, from the most
permissive to the strictest, the nominal one among them): the most permissive run's echoes'
scores are swept post hoc for the ROC curve (``roc``: a detection is an echo within
``TOLERANCE_M`` of path length of an object's first-order arrival; a false alarm an echo no
significant arrival of any kind explains), and every run gives one operating point. The two
agree for detectors that report every peak above their threshold (the CFARs); for those that
report one echo per channel (the threshold detector's first crossing, local-matched,
whitened-matched) lowering the threshold changes *which* echo is reported (an early floor
reverberation instead of a later object), so only the ladder's operating points describe them.
The nominal run gives the localisation and the time per ping. The nominal detections are localised
(``binsonar.localization.localize``: association of the three channels' echoes and point /
circle / plane fits); a target is *correctly associated* when its three echoes are, by the truth
arrivals, from the same object. Its range and bearing errors are taken against the feature that
reflected (the point of the centre channel's matching arrival: range L / 2 on the monostatic
channel, bearing of the point), since an object has several (a prism's front and rear edges, a
short cylinder's rims); the errors against the object's reference point (``truth.object_truth``)
are kept too.

Elastic echoes (``--elastic``, default ``compare``): every scene is run with the elastic-echo
step (``SolverConfig.elastic_echoes``) and, with the same scene and noise seeds, without it. The
echoes of the objects' internal arrivals (``/truth/internal_arrivals``) are scored apart
(``roc.score_echoes_elastic``): *elastic detections* (real echoes, not false alarms) and the
localised targets built on them (*elastic false targets*); the report gives both runs' P_D,
false alarms and association side by side, and the ROC figure both curves.
"""

from __future__ import annotations

import math
import time
import warnings
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from acoustisim.experiments.config import ExperimentConfig
from acoustisim.experiments.report import ExperimentReport, markdown_table
from acoustisim.experiments.runner import Trial

NAME = "clutter"
SUMMARY = ("detectors in randomised cluttered tank scenes: ROC, localisation-error distribution, association "
           "accuracy and time per ping")
DEFAULT_SCENES = 4
"""Scenes per clutter density (``--trials``)."""
DENSITIES: tuple[int, ...] = (1, 4, 8)
"""Objects per scene."""
SNRS_DB: tuple[float, ...] = (20.0, 30.0, 40.0)
"""2E/N0 of the strongest target echo (dB); 20 dB is a peak-to-noise ratio of about 2.2."""
DETECTORS: tuple[str, ...] = ("threshold", "ca-cfar", "os-cfar", "local-matched", "dwt", "whitened-matched")
_PFA_LADDER = (1e-1, 1e-2, 1e-3, 1e-5)
_CFAR_LADDER = (1e-3, 1e-4, 1e-6, 1e-8)
LADDER: Mapping[str, tuple[dict[str, float], ...]] = MappingProxyType({
    "threshold": tuple({"level_sigma": v} for v in (4.0, 6.0, 9.0, 13.0)),
    "ca-cfar": tuple({"pfa": v} for v in _CFAR_LADDER),
    "os-cfar": tuple({"pfa": v} for v in _CFAR_LADDER),
    "local-matched": tuple({"pfa": v} for v in _PFA_LADDER),
    "dwt": tuple({"pfa": v} for v in _PFA_LADDER),
    "whitened-matched": tuple({"pfa": v} for v in _PFA_LADDER),
})
"""Threshold settings of each detector, most permissive first (nominal: level 6 sigma, CFAR pfa
1e-6, the others pfa 1e-3)."""
NOMINAL: Mapping[str, int] = MappingProxyType({"threshold": 1, "ca-cfar": 2, "os-cfar": 2, "local-matched": 2,
                                               "dwt": 2, "whitened-matched": 2})
"""Index of the nominal (default) setting in each ladder."""
RECORD_S = 5e-3
"""Record length (s): 3.7 m of range, past the farthest object (3.2 m)."""
ELASTIC_MODES: tuple[str, ...] = ("compare", "on", "off")
"""``--elastic``: run every scene with and without the elastic echoes (same scene and noise seeds;
the default), only with them, or only without."""
DIFFUSE_RAYS = 2000
MAX_ORDER = 2
PROBE_ATTENUATION_DB = 60.0
"""Receive attenuation (dB) of the probe ping that measures the strongest echo."""
ECHO_PEAK_V = 0.25
"""The operator's gain setting: the attenuation of a scene puts the strongest echo past the
blanking at this peak (V). With the noise set relative to that echo (``snr_db``) the attenuation
only trades ADC headroom against quantisation: at 20 dB the noise is then 0.11 V (peaks of echo
plus noise stay under the 1 V full scale), at 40 dB 11 mV (23 ADC steps). A fixed 60 dB left
the noise at 40 dB under one step: the noise windows quantised to constants, the detectors'
noise estimates collapsed to zero and the threshold detector fired on the record's first
sample with a score of 1e150."""
TOLERANCE_M = 0.01
"""A detection lies within this much path length (m) of a true arrival: 6.8 us, more than the
5 us pulse, so that a detector's TOF bias on a distorted (diffracted, overlapping) echo is not
counted as a miss."""


def add_arguments(parser: Any) -> None:
    """``--densities``, ``--snrs``, ``--detectors``, ``--elastic``."""
    parser.add_argument("--densities", metavar="LIST", default=",".join(str(d) for d in DENSITIES),
                        help="objects per scene, comma-separated (default 1,4,8)")
    parser.add_argument("--snrs", metavar="LIST", default=",".join(f"{s:g}" for s in SNRS_DB),
                        help="SNRs (2E/N0 of the strongest target echo, dB), comma-separated (default 20,30,40)")
    parser.add_argument("--detectors", metavar="LIST", default=",".join(DETECTORS),
                        help=f"detectors, comma-separated (default {','.join(DETECTORS)})")
    parser.add_argument("--elastic", default=ELASTIC_MODES[0], choices=ELASTIC_MODES,
                        help="elastic echoes of the posts, cylinders and spheres: compare (every scene with and "
                             "without them, same seeds; default), on, off")


def _localise(result: Any, recording: Any) -> Any:
    from binsonar.bounds import rms_bandwidth_hz
    from binsonar.localization import localize

    bandwidth = rms_bandwidth_hz(recording.template.samples, recording.template.sample_rate_hz)
    with np.errstate(over="ignore"):  # association squares the huge TOF stds of echoes barely above threshold
        return localize(result, sound_speed_m_s=recording.sound_speed_m_s,
                        channel_positions_m=recording.channel_positions_m, pose=recording.pose,
                        rms_bandwidth_hz=bandwidth)


def measure_scene(trial: Trial) -> dict[str, Any]:
    """One scene: trace once, one ping per SNR, every detector at every ladder setting (runner function).

    Trial parameters: ``density``, ``snrs_db`` (tuple), ``detectors`` (tuple), ``elastic``
    ("on", "off" or "compare": both, the same scene and noise seeds).

    Returns
    -------
    dict
        ``density``, ``objects`` (kinds), ``elastic_echoes`` (bool), ``solve_s``, and per SNR and
        detector: ``target_best`` (best score per target in the most permissive run, None =
        missed), ``false_alarm_scores``, ``elastic_scores`` (echoes of elastic objects' internal
        arrivals), ``nominal_detected`` / ``nominal_false_alarms`` / ``nominal_elastic``,
        ``ladder_detected`` / ``ladder_false_alarms`` (per ladder setting), ``range_errors_m``,
        ``bearing_errors_deg``, ``object_range_errors_m``, ``object_bearing_errors_deg`` (against
        the reflecting feature, the centre channel's arrival, and against the object's reference
        point), ``targets`` / ``associated`` (localised targets with three echoes / from one
        object), ``elastic_targets`` / ``elastic_ghosts`` (localised targets holding an elastic
        echo / made of one object's elastic echoes only), ``elapsed_s`` and ``cpu_s`` (nominal
        detection of the ping), ``clipped``. With "compare", the same under ``without_elastic``.
    """
    from acoustisim.experiments.clutter_scenes import cluttered_scene
    from acoustisim.experiments.truth import object_truth

    p = dict(trial.params)
    rng = np.random.default_rng(np.random.SeedSequence([trial.seed, 1]))
    scene = cluttered_scene(int(p["density"]), rng, RECORD_S)
    truths = {o.name: object_truth(scene, scene.sonar, o) for o in scene.objects}
    mode = str(p.get("elastic", "on"))
    out = _measure_variant(trial, scene, truths, p, elastic=mode != "off")
    if mode == "compare":
        out["without_elastic"] = _measure_variant(trial, scene, truths, p, elastic=False)
    return out


def _measure_variant(trial: Trial, scene: Any, truths: dict[str, Any], p: dict[str, Any], *,
                     elastic: bool) -> dict[str, Any]:
    """:func:`measure_scene` for one setting of the elastic echoes."""
    from scipy.signal import hilbert

    from acoustisim.experiments.gating import BLANKING_S, gate_recording
    from acoustisim.experiments.geometry import range_bearing_of
    from acoustisim.experiments.roc import (arrival_object, echo_arrival, elastic_object, first_order_targets,
                                            score_echoes_elastic)
    from acoustisim.propagation import SolverConfig, solve
    from acoustisim.simulation import simulate
    from acoustisim.synthesis.chain import ReceiverChain
    from binsonar.detection import detect

    sonar = scene.sonar
    names = [o.name for o in scene.objects]
    t = time.perf_counter()
    paths = solve(scene, sonar, SolverConfig(max_order=MAX_ORDER, diffuse_rays=DIFFUSE_RAYS, seed=trial.seed % 2**31,
                                             elastic_echoes=elastic))
    solve_s = time.perf_counter() - t
    arrivals = paths.arrivals()
    surface_names = tuple(paths.surface_names)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # arrivals past the short record are left out on purpose
        probe = simulate(scene, sonar, chain=ReceiverChain(attenuation_db=(PROBE_ATTENUATION_DB,) * 3), paths=paths,
                         seed=trial.seed, n_pings=1, snr_db=float(p["snrs_db"][0]))
    internal = probe.truth.get("internal_arrivals")
    i_blank = int(math.ceil(BLANKING_S * sonar.sample_rate_hz))
    peak = float(np.max(np.abs(probe.clean[:, i_blank:])))
    attenuation = float(np.clip(PROBE_ATTENUATION_DB + 20.0 * math.log10(peak / ECHO_PEAK_V), 0.0, 68.0))
    chain = ReceiverChain(attenuation_db=(attenuation,) * 3)
    out: dict[str, Any] = {"density": int(p["density"]), "objects": [o.kind for o in scene.objects],
                           "elastic_echoes": elastic, "solve_s": solve_s, "attenuation_db": attenuation, "snr": {}}
    for k, snr in enumerate(p["snrs_db"]):
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # arrivals past the short record are left out on purpose
            sim = simulate(scene, sonar, chain=chain, paths=paths, seed=trial.seed + k, n_pings=1, snr_db=float(snr))
        simulate_s = time.perf_counter() - t
        recording = gate_recording(sim.recording, BLANKING_S)
        c = float(recording.sound_speed_m_s)
        tol_s = TOLERANCE_M / c
        fs = recording.sample_rate_hz
        i0 = int(round(recording.t0_s * fs))
        envelope = np.abs(hilbert(sim.clean[:, i0:i0 + recording.waveforms.shape[-1]], axis=-1))
        window = (recording.t0_s, recording.t0_s + recording.waveforms.shape[-1] / fs)
        targets = first_order_targets(arrivals, surface_names, names, window)
        sigma = np.asarray(sim.noise_sigma_v, dtype=float)
        clipped = bool(np.max(np.abs(recording.waveforms)) >= chain.adc_full_scale_v * (1 - 1e-9))
        per: dict[str, Any] = {"simulate_s": simulate_s, "clipped": clipped, "n_targets": len(targets),
                               "detectors": {}}
        for method in p["detectors"]:
            ladder_detected, ladder_fa = [], []
            for level, options in enumerate(LADDER[method]):
                cpu = time.process_time()
                res = detect(recording, method, **options)
                cpu = time.process_time() - cpu
                b, f, el = score_echoes_elastic(res.echoes[0], targets, arrivals, envelope, recording.t0_s, fs, sigma,
                                                tol_s, internal=internal)
                if level == 0:
                    best, fa, elastic_scores = b, f, el
                if level == NOMINAL[method]:
                    nominal, nominal_cpu, nb, nfa, nel = res, cpu, b, f, el
                ladder_detected.append(int(np.sum(b >= 1.0)))
                ladder_fa.append(int(np.sum(f >= 1.0)))
            loc = _localise(nominal, recording)
            range_err, bearing_err, obj_range_err, obj_bearing_err, n_three, n_assoc = [], [], [], [], 0, 0
            n_elastic_targets = n_ghosts = 0
            for target in loc.targets[0]:
                if any(e is None for e in target.echoes):
                    continue
                n_three += 1
                rows = [echo_arrival(arrivals, e.channel, e.tof_s, tol_s) for e in target.echoes]
                # an echo no target explains but an internal arrival does is elastic
                ringing = [None if _is_target_echo(targets, e.channel, e.tof_s, tol_s)
                           else elastic_object(internal, e.channel, e.tof_s, tol_s) for e in target.echoes]
                if any(r is not None for r in ringing):
                    n_elastic_targets += 1
                    n_ghosts += int(None not in ringing and len(set(ringing)) == 1)
                    continue
                owners = {arrival_object(arrivals, row, surface_names, names) for row in rows}
                if len(owners) == 1 and None not in owners:
                    n_assoc += 1
                    truth = truths[owners.pop()]
                    obj_range_err.append(float(target.range_m - truth.range_m))
                    obj_bearing_err.append(float(target.bearing_deg - truth.bearing_deg))
                    # the feature that reflected: the centre channel's arrival (monostatic: range L / 2)
                    centre = rows[1]
                    _, feature_bearing = range_bearing_of(sonar, np.asarray(arrivals["points_m"][centre][0]))
                    range_err.append(float(target.range_m - 0.5 * arrivals["path_length_m"][centre]))
                    bearing_err.append(float(target.bearing_deg - feature_bearing))
            per["detectors"][method] = {
                "target_best": [float(v) if np.isfinite(v) else None for v in best],
                "false_alarm_scores": fa.tolist(), "elastic_scores": elastic_scores.tolist(),
                "nominal_detected": int(np.sum(nb >= 1.0)), "nominal_false_alarms": int(np.sum(nfa >= 1.0)),
                "nominal_elastic": int(np.sum(nel >= 1.0)),
                "ladder_detected": ladder_detected, "ladder_false_alarms": ladder_fa,
                "range_errors_m": range_err, "bearing_errors_deg": bearing_err,
                "object_range_errors_m": obj_range_err, "object_bearing_errors_deg": obj_bearing_err,
                "targets": n_three, "associated": n_assoc,
                "elastic_targets": n_elastic_targets, "elastic_ghosts": n_ghosts,
                "elapsed_s": float(nominal.elapsed_s), "cpu_s": float(nominal_cpu),
            }
        out["snr"][f"{float(snr):g}"] = per
    return out


def _is_target_echo(targets: list[tuple[int, str, Any]], channel: int, tof_s: float, tolerance_s: float) -> bool:
    """Whether an echo lies within the tolerance of some object's first-order arrival on its channel."""
    return any(ch == channel and np.any(np.abs(delays - tof_s) <= tolerance_s) for ch, _, delays in targets)


def _best_array(values: list[Any]) -> np.ndarray:
    return np.array([-np.inf if v is None else v for v in values], dtype=float)


def summarise(scenes: list[dict[str, Any]], snrs: list[str], detectors: list[str]) -> dict[str, Any]:
    """Per detector and SNR (all densities), and per detector and density (all SNRs): ROC, rates, errors, time."""
    from acoustisim.experiments.roc import roc_curve

    def pooled(select: Any) -> dict[str, Any]:
        out = {}
        for m in detectors:
            best, fa, el, rng_e, brg_e, obj_e = [], [], [], [], [], []
            pings = targets = detected = fas = n_three = n_assoc = n_elastic = el_targets = el_ghosts = 0
            lad_d = np.zeros(len(LADDER[m]))
            lad_f = np.zeros(len(LADDER[m]))
            elapsed, cpu = [], []
            for s in scenes:
                for snr, per in s["snr"].items():
                    if not select(s, snr):
                        continue
                    d = per["detectors"][m]
                    pings += 1
                    targets += per["n_targets"]
                    best.append(_best_array(d["target_best"]))
                    fa.append(np.asarray(d["false_alarm_scores"], dtype=float))
                    el.append(np.asarray(d.get("elastic_scores", []), dtype=float))
                    n_elastic += d.get("nominal_elastic", 0)
                    el_targets += d.get("elastic_targets", 0)
                    el_ghosts += d.get("elastic_ghosts", 0)
                    detected += d["nominal_detected"]
                    lad_d += np.asarray(d["ladder_detected"], dtype=float)
                    lad_f += np.asarray(d["ladder_false_alarms"], dtype=float)
                    fas += d["nominal_false_alarms"]
                    rng_e += d["range_errors_m"]
                    brg_e += d["bearing_errors_deg"]
                    obj_e += d["object_range_errors_m"]
                    n_three += d["targets"]
                    n_assoc += d["associated"]
                    elapsed.append(d["elapsed_s"])
                    cpu.append(d["cpu_s"])
            b = np.concatenate(best) if best else np.zeros(0)
            f = np.concatenate(fa) if fa else np.zeros(0)
            e = np.concatenate(el) if el else np.zeros(0)
            r = np.abs(np.asarray(rng_e, dtype=float))
            out[m] = {
                "pings": pings, "targets": targets,
                "roc": roc_curve(b, f, pings),
                # the elastic echoes counted as false alarms too (a detection no object is at)
                "roc_elastic_as_false": roc_curve(b, np.concatenate([f, e]), pings),
                "nominal_elastic_per_ping": n_elastic / pings if pings else float("nan"),
                "elastic_per_ping_most_permissive": float(np.sum(e >= 1.0)) / pings if pings else float("nan"),
                "elastic_targets": el_targets, "elastic_ghosts": el_ghosts,
                "elastic_targets_per_ping": el_targets / pings if pings else float("nan"),
                "pd_max": float(np.mean(np.isfinite(b))) if b.size else float("nan"),
                "ladder_pd": (lad_d / targets).tolist() if targets else [float("nan")] * lad_d.size,
                "ladder_fa_per_ping": (lad_f / pings).tolist() if pings else [float("nan")] * lad_f.size,
                "nominal_pd": detected / targets if targets else float("nan"),
                "nominal_false_alarms_per_ping": fas / pings if pings else float("nan"),
                "localised_targets": n_three, "associated_targets": n_assoc,
                "association_accuracy": n_assoc / n_three if n_three else float("nan"),
                "range_errors_m": rng_e, "bearing_errors_deg": brg_e,
                "range_error_median_abs_m": float(np.median(r)) if r.size else float("nan"),
                "range_error_p90_abs_m": float(np.quantile(r, 0.9)) if r.size else float("nan"),
                "bearing_error_median_abs_deg": (float(np.median(np.abs(brg_e))) if brg_e else float("nan")),
                "object_range_error_median_abs_m": (float(np.median(np.abs(obj_e))) if obj_e else float("nan")),
                "object_range_error_p90_abs_m": (float(np.quantile(np.abs(obj_e), 0.9)) if obj_e else float("nan")),
                "time_per_ping_s": float(np.mean(elapsed)) if elapsed else float("nan"),
                "cpu_per_ping_s": float(np.mean(cpu)) if cpu else float("nan"),
            }
        return out

    densities = sorted({s["density"] for s in scenes})
    return {
        "by_snr": {snr: pooled(lambda s, x, snr=snr: x == snr) for snr in snrs},
        "by_density": {str(d): pooled(lambda s, x, d=d: s["density"] == d) for d in densities},
        "all": pooled(lambda s, x: True),
    }


COLOURS: Mapping[str, str] = MappingProxyType({"threshold": "tab:orange", "ca-cfar": "tab:blue", "os-cfar": "tab:cyan", "local-matched": "tab:green",
           "dwt": "tab:purple", "whitened-matched": "tab:red"})


def reading_note(summary: dict[str, Any], detectors: list[str], clipped: int, pings: int) -> str:
    """How to read the tables, from this run's own figures (detectors, ladders, clipping)."""
    from acoustisim.experiments.clutter_scenes import BEARING_DEG
    from acoustisim.medium import Medium
    from scenes.builders import default_sonar

    floor_s = 2.0 * default_sonar().position_m[2] / Medium(water="fresh", temperature_c=20.0).sound_speed
    text = [
        "Reading: P_D counts every object's echo on every channel, including objects off the 19 mm "
        f"transducers' main lobe (bearings up to {BEARING_DEG:g} deg) and small posts and spheres, whose echoes lie "
        "tens of dB under the strongest.",
    ]
    single = [m for m in ("local-matched", "whitened-matched", "dwt") if m in detectors]
    if single:
        text.append(f"Detectors that report one echo per channel ({', '.join(single)}) cannot exceed one target "
                    "per channel per ping.")
    if "threshold" in detectors:
        s = summary["all"]["threshold"]
        best_ladder = float(np.nanmax(s["ladder_pd"])) if np.isfinite(s["ladder_pd"]).any() else float("nan")
        if s["pd_max"] < best_ladder:
            text.append(
                "The threshold detector reports its first crossing: lowered, it locks onto the floor's "
                f"reverberation (which begins {floor_s * 1e3:.2f} ms after the ping) and finds fewer objects, so "
                f"its post-hoc curve (P_D {s['pd_max']:.3g} at its most permissive run) lies under its ladder's best "
                f"point (P_D {best_ladder:.3g}).")
        else:
            text.append(
                "The threshold detector reports its first crossing; in this run its most permissive setting "
                f"(P_D {s['pd_max']:.3g}) finds at least as many objects as any other rung of its ladder "
                f"({best_ladder:.3g}), so the floor's reverberation (from {floor_s * 1e3:.2f} ms) did not capture it.")
    text.append(
        "The seed's tank had electrical noise and interference; here white noise at a set SNR replaces them, so "
        "the false alarms come from noise and from reverberation peaks the truth does not explain at the noise "
        f"level. {clipped} of {pings} pings clipped the ADC. Errors are against the reflecting feature; against the "
        "object's reference point (a prism's front edge, a post's nearest surface) they include the choice of "
        "feature (a prism's rear edges lie 9-17 cm behind its front edge, for its 10-20 cm faces). The errors are "
        "medians (the 90th percentile is in results.json): a few associations to the wrong feature would set a "
        "mean. Time per ping is wall-clock on a shared machine; the CPU time is the comparable figure.")
    return " ".join(text)


def roc_figure(summary: dict[str, Any], detectors: list[str], without: dict[str, Any] | None = None) -> Any:
    """ROC curves per detector, one panel per SNR, with the nominal operating points (and, thin
    dashed, the curves of ``without``: the same run without elastic echoes)."""
    from acoustisim.experiments.figures import new_figure

    snrs = list(summary["by_snr"])
    fig, axes = new_figure(1, len(snrs), width=4.2 * len(snrs), row_height=3.6)
    for j, snr in enumerate(snrs):
        ax = axes[0, j]
        for m in detectors:
            s = summary["by_snr"][snr][m]
            fa = np.asarray(s["roc"]["fa_per_ping"], dtype=float)
            pd = np.asarray(s["roc"]["pd"], dtype=float)
            floor = 0.5 / max(1, s["pings"])  # zero false alarms drawn at half of one per all pings
            ax.step(np.maximum(fa, floor), pd, where="post", color=COLOURS.get(m), label=m)
            if without is not None:
                w = without["by_snr"][snr][m]
                ax.step(np.maximum(np.asarray(w["roc"]["fa_per_ping"], dtype=float), floor), w["roc"]["pd"],
                        where="post", color=COLOURS.get(m), lw=0.8, ls="--", alpha=0.7)
            ax.plot(np.maximum(s["ladder_fa_per_ping"], floor), s["ladder_pd"], ":", marker=".", color=COLOURS.get(m))
            ax.plot(max(s["nominal_false_alarms_per_ping"], floor), s["nominal_pd"], "o", color=COLOURS.get(m), ms=6,
                    mfc="none")
        ax.set_xscale("log")
        ax.set_ylim(0, 1.02)
        ax.set_xlabel("false alarms per ping (3 channels)")
        if j == 0:
            ax.set_ylabel("probability of detection")
        ax.set_title(f"2E/N0 of the strongest echo {snr} dB", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        if j == 0:
            ax.legend(fontsize=7, loc="upper left", title_fontsize=7, ncol=2,
                      title="lines: post-hoc sweep; dotted: threshold ladder;\ncircles: nominal threshold")
    return fig


def error_figure(summary: dict[str, Any], detectors: list[str]) -> Any:
    """Histograms of the range and bearing errors of the targets associated to one object."""
    from acoustisim.experiments.figures import new_figure

    fig, axes = new_figure(1, 2, width=10.0, row_height=3.4)
    bins_r = np.logspace(-3, 2, 41)  # |range error| in mm
    bins_b = np.logspace(-3, 1.5, 41)  # |bearing error| in deg
    for m in detectors:
        s = summary["all"][m]
        r = np.abs(np.asarray(s["range_errors_m"], dtype=float)) * 1e3
        b = np.abs(np.asarray(s["bearing_errors_deg"], dtype=float))
        if r.size:
            axes[0, 0].hist(np.clip(r, bins_r[0], bins_r[-1]), bins=bins_r, histtype="step", color=COLOURS.get(m),
                            label=f"{m} ({r.size})")
            axes[0, 1].hist(np.clip(b, bins_b[0], bins_b[-1]), bins=bins_b, histtype="step", color=COLOURS.get(m),
                            label=m)
    for ax, label in ((axes[0, 0], "|range error| (mm)"), (axes[0, 1], "|bearing error| (deg)")):
        ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel("targets")
        ax.grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    axes[0, 0].set_title("Targets whose three echoes are from one object: error against\n"
                         "the reflecting feature", fontsize=9)
    axes[0, 1].set_title("(all densities and SNRs; values clipped to the axes)\n", fontsize=9)
    return fig


def _fmt(value: float, digits: int = 2) -> str:
    return "-" if not np.isfinite(value) else f"{value:.{digits}f}"


def elastic_section(summary: dict[str, Any], without: dict[str, Any] | None, detectors: list[str]) -> str:
    """The report's paragraph and table on the elastic echoes (numbers from this run)."""
    rows = []
    for m in detectors:
        s = summary["all"][m]
        w = None if without is None else without["all"][m]
        rows.append([m, _fmt(s["nominal_elastic_per_ping"]), _fmt(s["elastic_per_ping_most_permissive"]),
                     f"{s['elastic_targets']} ({s['elastic_ghosts']} ghosts)", f"{s['localised_targets']}",
                     _fmt(s["nominal_pd"]) + ("" if w is None else f" ({_fmt(w['nominal_pd'])})"),
                     _fmt(s["nominal_false_alarms_per_ping"])
                     + ("" if w is None else f" ({_fmt(w['nominal_false_alarms_per_ping'])})"),
                     _fmt(s["pd_max"]) + ("" if w is None else f" ({_fmt(w['pd_max'])})"),
                     _fmt(s["association_accuracy"]) + ("" if w is None else f" ({_fmt(w['association_accuracy'])})")])
    pings = summary["all"][detectors[0]]["pings"]
    total_targets = sum(summary["all"][m]["elastic_targets"] for m in detectors)
    total_localised = sum(summary["all"][m]["localised_targets"] for m in detectors)
    busiest = max(detectors, key=lambda m: summary["all"][m]["nominal_elastic_per_ping"])
    text = (
        "Elastic echoes (the exact echoes of the PVC posts and cylinders and the steel spheres: the "
        "compressional echo through a post's diameter 4 a / c_L after its specular echo, about -20 dB, and the "
        "later shear and circumferential arrivals). An *elastic detection* is an echo that no object's "
        "first-order arrival explains but an internal arrival of an elastic echo does (with the noise-free "
        "envelope above the noise): a real echo, not counted as a false alarm in the ROC, but one with no object "
        "where it places a reflector. An *elastic false target* is a localised target one of whose three echoes "
        "is elastic; a *ghost* is made of one object's elastic echoes only (a reflector a few centimetres behind "
        f"it: 31 mm for a 25 mm PVC post). Over {pings} pings, the nominal thresholds report "
        f"{_fmt(summary['all'][busiest]['nominal_elastic_per_ping'])} elastic detections per ping at most "
        f"({busiest}), and the localiser made {total_targets} elastic false targets out of {total_localised} "
        "localised targets (all detectors together)."
    )
    worst = max(detectors, key=lambda m: summary["all"][m]["elastic_targets"])
    ws = summary["all"][worst]
    text += (f" Most come from {worst}: {ws['elastic_targets']} of its {ws['localised_targets']} localised targets, "
             f"{ws['elastic_ghosts']} of them ghosts.")
    quiet = [m for m in detectors if summary["all"][m]["elastic_targets"] == 0]
    if quiet:
        text += f" {', '.join(quiet)} made none."
    if without is not None:
        d_pd = {m: summary["all"][m]["nominal_pd"] - without["all"][m]["nominal_pd"] for m in detectors}
        d_fa = {m: summary["all"][m]["nominal_false_alarms_per_ping"] - without["all"][m]["nominal_false_alarms_per_ping"]
                for m in detectors}
        d_as = {m: summary["all"][m]["association_accuracy"] - without["all"][m]["association_accuracy"]
                for m in detectors}
        big_pd = max(detectors, key=lambda m: abs(d_pd[m]) if np.isfinite(d_pd[m]) else -1.0)
        big_fa = max(detectors, key=lambda m: abs(d_fa[m]) if np.isfinite(d_fa[m]) else -1.0)
        big_as = min(detectors, key=lambda m: d_as[m] if np.isfinite(d_as[m]) else np.inf)
        text += (
            " In brackets, the same scenes and noise seeds without the elastic step. The ROC "
            + ("hardly moves" if abs(d_pd[big_pd]) < 0.05 and abs(d_fa[big_fa]) < 0.2 else "moves") + ": the "
            f"nominal P_D changes by at most {d_pd[big_pd]:+.3f} ({big_pd}) and the false alarms by at most "
            f"{d_fa[big_fa]:+.3f} per ping ({big_fa}), the targets' echoes changing level and shape a little and the "
            "SNR staying set on the strongest target echo; counted as false alarms, the elastic detections would "
            f"add {_fmt(summary['all'][busiest]['nominal_elastic_per_ping'])} per ping to {busiest}'s. What changes "
            f"is the localisation: the association accuracy falls by {-d_as[big_as]:.2f} for {big_as} "
            f"({_fmt(without['all'][big_as]['association_accuracy'])} without, "
            f"{_fmt(summary['all'][big_as]['association_accuracy'])} with), its elastic false targets counted as "
            "wrongly associated.")
    table = markdown_table(
        ["detector", "elastic detections / ping (nominal)", "elastic detections / ping (most permissive)",
         "elastic false targets", "localised targets", "P_D nominal (without)",
         "false alarms / ping nominal (without)", "P_D most permissive (without)",
         "association accuracy (without)"], rows)
    return text + "\n\n" + table


def _parse(text: str, kind: type, what: str) -> list[Any]:
    from acoustisim.errors import InputError

    try:
        values = [kind(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise InputError(f"clutter: --{what} {text!r}: expected comma-separated numbers") from None
    if not values:
        raise InputError(f"clutter: --{what} is empty")
    return values


def run(config: ExperimentConfig) -> ExperimentReport:
    """``config.trials`` scenes (default 4) per density, one ping per SNR, every detector."""
    from acoustisim.errors import InputError
    from acoustisim.experiments.runner import make_trials, run_trials

    n_scenes = config.trials_or(DEFAULT_SCENES)
    densities = _parse(config.option("densities", ",".join(map(str, DENSITIES))), int, "densities")
    snrs = _parse(config.option("snrs", ",".join(f"{s:g}" for s in SNRS_DB)), float, "snrs")
    detectors = [d.strip() for d in str(config.option("detectors", ",".join(DETECTORS))).split(",") if d.strip()]
    elastic = str(config.option("elastic", ELASTIC_MODES[0]))
    if elastic not in ELASTIC_MODES:
        raise InputError(f"clutter: --elastic {elastic!r}: choose among {', '.join(ELASTIC_MODES)}")
    if n_scenes < 1:
        raise InputError(f"clutter: --trials must be >= 1, got {n_scenes}")
    if any(not 1 <= d <= 12 for d in densities):
        raise InputError(f"clutter: --densities must lie in 1..12 objects, got {densities}")
    if any(not (math.isfinite(s) and 0.0 < s <= 80.0) for s in snrs):
        raise InputError(f"clutter: --snrs must lie in (0, 80] dB, got {snrs}")
    unknown = [d for d in detectors if d not in LADDER]
    if unknown or not detectors:
        raise InputError(f"clutter: --detectors {','.join(unknown) or '(empty)'}: choose among {', '.join(LADDER)}")
    params = [{"density": d, "snrs_db": tuple(snrs), "detectors": tuple(detectors), "elastic": elastic}
              for d in densities for _ in range(n_scenes)]
    trials = make_trials(config.seed, params)
    start = time.perf_counter()
    scenes = run_trials(measure_scene, trials, workers=config.workers, description=config.name,
                        progress=config.progress)
    wall_s = time.perf_counter() - start
    snr_keys = [f"{s:g}" for s in snrs]
    summary = summarise(scenes, snr_keys, detectors)
    without = (summarise([s["without_elastic"] for s in scenes], snr_keys, detectors) if elastic == "compare"
               else None)
    report = ExperimentReport(config.name, config.out_dir)
    sim_s = [per["simulate_s"] for s in scenes for per in s["snr"].values()]
    report.results = {
        "seed": config.seed, "scenes_per_density": n_scenes, "densities": densities, "snrs_db": snrs,
        "detectors": detectors, "ladder_options": {d: LADDER[d] for d in detectors},
        "nominal_ladder_index": {d: NOMINAL[d] for d in detectors},
        "tolerance_m": TOLERANCE_M, "record_s": RECORD_S, "diffuse_rays": DIFFUSE_RAYS, "max_order": MAX_ORDER,
        "wall_time_s": wall_s, "solve_s_per_scene": float(np.mean([s["solve_s"] for s in scenes])),
        "attenuation_db": [s["attenuation_db"] for s in scenes], "echo_peak_v": ECHO_PEAK_V,
        "simulate_s_per_ping": float(np.mean(sim_s)),
        "clipped_pings": int(sum(per["clipped"] for s in scenes for per in s["snr"].values())),
        "elastic": elastic, "summary": summary, "summary_without_elastic": without, "scenes": scenes,
    }
    report.add_figure(roc_figure(summary, detectors, without), "clutter_roc.png",
                      "ROC per detector, one panel per SNR, all densities pooled: solid, the most permissive run's "
                      "threshold swept post hoc over the echoes' scores; dotted, the operating points of the "
                      "threshold ladder; circles, the nominal thresholds (zero false alarms drawn at the left edge)"
                      + ("; thin dashed, the same scenes and noise without the elastic echoes" if without else ""))
    report.add_figure(error_figure(summary, detectors), "clutter_errors.png",
                      "Range and bearing errors of the localised targets whose three echoes come from one object")
    rows = []
    for m in detectors:
        s = summary["all"][m]
        rows.append([m, s["nominal_pd"], s["nominal_false_alarms_per_ping"], s["pd_max"], s["association_accuracy"],
                     f"{s['associated_targets']}/{s['localised_targets']}", s["range_error_median_abs_m"] * 1e3,
                     s["bearing_error_median_abs_deg"], s["object_range_error_median_abs_m"] * 1e3,
                     s["time_per_ping_s"] * 1e3, s["cpu_per_ping_s"] * 1e3])
    report.add_section(
        f"{n_scenes} random scenes per density ({', '.join(map(str, densities))} objects), one ping per SNR "
        f"({', '.join(snr_keys)} dB, 2E/N0 of the strongest target echo), record {RECORD_S * 1e3:g} ms, "
        f"{DIFFUSE_RAYS} diffuse rays, order <= {MAX_ORDER}; a detection is within {TOLERANCE_M * 100:g} cm of "
        f"path length of an object's first-order arrival. Wall time {wall_s:.1f} s.")
    report.add_section(markdown_table(
        ["detector", "P_D (nominal)", "false alarms / ping (nominal)", "P_D (most permissive run)",
         "association accuracy", "associated / localised", "median |range error| (mm)",
         "median |bearing error| (deg)", "median |range error| to the object's reference (mm)",
         "time per ping (ms)", "CPU per ping (ms)"], rows))
    drows = []
    for d, per in summary["by_density"].items():
        for m in detectors:
            s = per[m]
            drows.append([d, m, s["nominal_pd"], s["nominal_false_alarms_per_ping"], s["association_accuracy"]])
    report.add_section("By clutter density (all SNRs):\n\n" + markdown_table(
        ["objects", "detector", "P_D (nominal)", "false alarms / ping", "association accuracy"], drows))
    if elastic != "off":
        report.add_section(elastic_section(summary, without, detectors))
    report.add_section(reading_note(summary, detectors, report.results["clipped_pings"],
                                    sum(len(sc["snr"]) for sc in scenes)))
    return report
