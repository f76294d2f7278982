"""``nine-methods``: the seed's section 4.2.4 (figures 4-15 to 4-17).

68 pings of the edge target at ranges of 2 to 5 m, processed by the seed's nine combinations
(``binsonar.detection.seed``: threshold / matched filter, single / averaged waveform, with or
without band-pass, and the local matched processing). The pings come in groups recorded at the
same position (``--pings-per-position``, default 4, at ``ceil(68 / 4) = 17`` ranges evenly spread
over 2-5 m, bearings drawn uniformly in +/-3 deg from the trial's seed), so that the averaging
methods have several pings to average; a single-waveform method gives one estimate per ping, an
averaging method one per position. A detection is correct when the range error is under 1 cm
(the seed's criterion); a ping or position without an echo on both side channels counts as
incorrect.

Processing time is measured the way the seed measured it: each method runs on the whole
acquired record, from the trigger (t = 0) to the sonar's record length (the scene's default
``sonar.record_length_s``, 12.5 ms: 250,000 samples per channel at 20 MHz, the thesis's
acquisition; "a complete echo signal is required for matched processing"), not on a cut-out
around the target. The record is not cut; the echo search is restricted to the range gate
``range +/- GATE_HALF_WIDTH_M`` with ``detect``'s ``search_window_s`` option, which all three
base methods of the nine (threshold, matched, local-matched) honour, so that the correctness
test asks about the target's echo and not the tank's walls. The noise floor each method
estimates is that of the whole record. Each method runs once untimed (its estimates are the
ones scored; it also pays any first-call import), then ``--timing-repeats`` more times, whose
median CPU time (``time.process_time``) is the method's time; per acquired ping, an averaging
method's time over its group is divided by the group's pings.
"""

from __future__ import annotations

import math
import time
import warnings
from typing import Any

import numpy as np

from acoustisim.experiments.config import ExperimentConfig
from acoustisim.experiments.report import ExperimentReport, markdown_table
from acoustisim.experiments.runner import Trial

NAME = "nine-methods"
SUMMARY = "the seed's nine detection combinations on 68 pings at 2-5 m: detection rate, time, error (figs. 4-15..4-17)"
DEFAULT_PINGS = 68
CORRECT_M = 0.01
"""A detection is correct when its range error is below this (m), the seed's 1 cm."""
METHODS: tuple[str, ...] = tuple(f"seed-{k}" for k in range(1, 10))


def add_arguments(parser: Any) -> None:
    """``--pings-per-position``, ``--min-range``, ``--max-range``, ``--max-bearing``."""
    parser.add_argument("--pings-per-position", type=int, default=4, metavar="N",
                        help="pings recorded at each position (default 4); --trials is the total number of pings (68)")
    parser.add_argument("--min-range", type=float, default=2.0, metavar="M", help="nearest range (m, default 2)")
    parser.add_argument("--max-range", type=float, default=5.0, metavar="M", help="farthest range (m, default 5)")
    parser.add_argument("--max-bearing", type=float, default=3.0, metavar="DEG", help="bearings drawn in +/- this (deg, default 3)")
    parser.add_argument("--timing-repeats", type=int, default=3, metavar="N",
                        help="timed runs of each method per position after an untimed one; the median counts (default 3)")
    parser.add_argument("--no-reverberation", action="store_true",
                        help="leave out the diffuse (Lambert) reverberation of the floor, surface, walls and prism")


def measure_group(trial: Trial) -> dict[str, Any]:
    """Record ``n_pings`` pings at one position and run the nine methods on them (runner function)."""
    from acoustisim.experiments.gating import range_window_s
    from acoustisim.experiments.geometry import pose_for_target
    from acoustisim.experiments.edge_scene import EDGE_M, GATE_HALF_WIDTH_M, edge_tank_scene, solver_config
    from acoustisim.experiments.sweep_detectors import estimate_point, recording_array
    from acoustisim.experiments.truth import object_truth
    from acoustisim.simulation import simulate
    from binsonar.detection import detect

    p = dict(trial.params)
    range_m, bearing_deg, n_pings = float(p["range_m"]), float(p["bearing_deg"]), int(p["n_pings"])
    methods = tuple(p.get("methods", METHODS))
    repeats = int(p.get("timing_repeats", 3))
    scene = edge_tank_scene()
    c = float(scene.medium.sound_speed)
    window_s = range_window_s(range_m, c, GATE_HALF_WIDTH_M)
    # The scene's sonar keeps its own record length (the whole acquired record is processed).
    sonar = pose_for_target(scene.sonar, (*EDGE_M, scene.sonar.position_m[2]), range_m, bearing_deg,
                            yaw_deg=bearing_deg)
    truth = object_truth(scene, sonar, scene.objects[0])
    t, cpu = time.perf_counter(), time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # arrivals after the record's end are left out, as a digitiser would
        sim = simulate(scene, sonar, solver_config=solver_config(p), seed=trial.seed, n_pings=n_pings)
    simulate_s = time.perf_counter() - t
    simulate_cpu_s = time.process_time() - cpu
    recording = sim.recording
    half_baseline, _ = recording_array(recording)  # the baseline the recording describes
    out: dict[str, Any] = {"range_m": range_m, "bearing_deg": bearing_deg, "n_pings": n_pings,
                           "truth_range_m": truth.range_m, "truth_bearing_deg": truth.bearing_deg,
                           "simulate_s": simulate_s, "simulate_cpu_s": simulate_cpu_s,
                           "record_length_s": float(sonar.record_length_s),
                           "timed_samples": int(recording.waveforms.shape[-1]),
                           "search_window_s": list(window_s), "methods": {}}
    for method in methods:
        result = detect(recording, method, search_window_s=window_s)  # scored; pays first-call imports
        cpu_runs, wall_runs = [], []
        for _ in range(repeats):
            cpu = time.process_time()
            timed = detect(recording, method, search_window_s=window_s)
            cpu_runs.append(time.process_time() - cpu)
            wall_runs.append(timed.elapsed_s)
        cpu = float(np.median(cpu_runs))
        elapsed = float(np.median(wall_runs))
        errors, bearing_errors = [], []
        for ping in range(result.n_pings):
            r, b = estimate_point(result.first(ping), c, half_baseline)
            errors.append(r - truth.range_m)
            bearing_errors.append(b - truth.bearing_deg)
        out["methods"][method] = {
            "range_error_m": errors,
            "bearing_error_deg": bearing_errors,
            "estimates": result.n_pings,
            "elapsed_s": elapsed,
            "elapsed_s_per_ping": elapsed / n_pings,
            "cpu_s_per_ping": cpu / n_pings,
        }
    return out


def summarise(groups: list[dict[str, Any]], methods: tuple[str, ...]) -> dict[str, Any]:
    """Correct-detection rate, time per ping and errors of each method over all groups."""
    out: dict[str, Any] = {}
    for m in methods:
        err = np.array([e for g in groups for e in g["methods"][m]["range_error_m"]], dtype=float)
        berr = np.array([e for g in groups for e in g["methods"][m]["bearing_error_deg"]], dtype=float)
        found = np.isfinite(err)
        correct = found & (np.abs(np.where(found, err, np.inf)) < CORRECT_M)
        times = np.array([g["methods"][m]["elapsed_s_per_ping"] for g in groups], dtype=float)
        weights = np.array([g["n_pings"] for g in groups], dtype=float)
        out[m] = {
            "estimates": int(err.size),
            "detected": int(found.sum()),
            "correct": int(correct.sum()),
            "correct_rate": float(correct.mean()) if err.size else float("nan"),
            "time_per_ping_s": float(np.average(times, weights=weights)),
            "cpu_per_ping_s": float(np.average([g["methods"][m]["cpu_s_per_ping"] for g in groups], weights=weights)),
            "range_error_median_abs_m": float(np.median(np.abs(err[found]))) if found.any() else float("nan"),
            "range_error_rms_correct_m": float(np.sqrt(np.mean(err[correct] ** 2))) if correct.any() else float("nan"),
            "bearing_error_median_abs_deg": float(np.median(np.abs(berr[found]))) if found.any() else float("nan"),
        }
    return out


def time_ratios(summary: dict[str, Any]) -> dict[str, float]:
    """CPU time per ping of the local matched method (seed-9) over the full matched filter's on the
    averaged waveform, without (seed-4) and with (seed-8) band-pass: the seed's "fraction of its time"."""
    local = summary["seed-9"]["cpu_per_ping_s"]
    return {f"seed-9/{m}": float(local / summary[m]["cpu_per_ping_s"]) for m in ("seed-4", "seed-8")}


def _figure(summary: dict[str, Any], methods: tuple[str, ...], record_ms: float, samples: int,
            range_m: tuple[float, float]) -> Any:
    from acoustisim.experiments.figures import new_figure
    from acoustisim.experiments.edge_scene import GATE_HALF_WIDTH_M

    fig, axes = new_figure(3, 1, row_height=2.2)
    labels = [m.replace("seed-", "") for m in methods]
    x = np.arange(len(methods))
    colours = ["tab:orange" if "threshold" in _base(m) else ("tab:green" if "local" in _base(m) else "tab:blue")
               for m in methods]
    rate = [summary[m]["correct_rate"] * 100 for m in methods]
    tpp = [summary[m]["cpu_per_ping_s"] * 1e3 for m in methods]
    err = [summary[m]["range_error_median_abs_m"] * 1e3 for m in methods]
    axes[0, 0].bar(x, rate, color=colours)
    axes[0, 0].set_ylabel("correct detection\nrate (%)")
    axes[0, 0].set_ylim(0, 105)
    axes[0, 0].set_title(f"Nine detection combinations, edge at {range_m[0]:g}-{range_m[1]:g} m "
                         "(cf. seed figs. 4-15 to 4-17)", fontsize=10)
    axes[1, 0].bar(x, tpp, color=colours)
    axes[1, 0].set_ylabel("processing CPU time\nper ping (ms)")
    axes[1, 0].set_title(f"each method on the whole {record_ms:g} ms record ({samples:,} samples per channel), "
                         f"echo search in the +/-{GATE_HALF_WIDTH_M:g} m range gate", fontsize=8)
    axes[2, 0].bar(x, err, color=colours)
    axes[2, 0].set_yscale("log")
    axes[2, 0].set_ylabel("median |range\nerror| (mm)")
    axes[2, 0].set_xlabel("method (seed numbering): 1,2,5,6 threshold; 3,4,7,8 matched; 9 local matched")
    for ax in axes[:, 0]:
        ax.set_xticks(x)
        ax.set_xticklabels(labels)
        ax.grid(True, axis="y", alpha=0.3)
    return fig


def _base(method: str) -> str:
    from binsonar.detection.seed import seed_combination

    return seed_combination(method).base


def run(config: ExperimentConfig) -> ExperimentReport:
    """Record the pings (``config.trials`` in all, default 68) and compare the nine methods."""
    from acoustisim.errors import InputError
    from acoustisim.experiments.edge_scene import GATE_HALF_WIDTH_M
    from acoustisim.experiments.runner import make_trials, run_trials
    from binsonar.detection.seed import seed_combination

    total = config.trials_or(DEFAULT_PINGS)
    per = int(config.option("pings_per_position", 4))
    lo, hi = float(config.option("min_range", 2.0)), float(config.option("max_range", 5.0))
    max_bearing = float(config.option("max_bearing", 3.0))
    repeats = int(config.option("timing_repeats", 3))
    if total < 1 or per < 1:
        raise InputError(f"--trials ({total}) and --pings-per-position ({per}) must be >= 1")
    if not 1 <= repeats <= 20:
        raise InputError(f"nine-methods: --timing-repeats must be in [1, 20], got {repeats}")
    if not (0.3 <= lo <= hi <= 5.5):
        raise InputError(f"nine-methods: need 0.3 <= --min-range <= --max-range <= 5.5 m, got {lo}, {hi}")
    if not 0.0 <= max_bearing <= 10.0:
        raise InputError(f"nine-methods: --max-bearing must be in [0, 10] deg, got {max_bearing}")
    n_groups = int(math.ceil(total / per))
    sizes = [per] * (total // per) + ([total % per] if total % per else [])
    ranges = np.linspace(lo, hi, n_groups) if n_groups > 1 else np.array([0.5 * (lo + hi)])
    rng = np.random.default_rng(np.random.SeedSequence([config.seed, 4_2_4]))
    bearings = rng.uniform(-max_bearing, max_bearing, n_groups)
    reverberation = not bool(config.option("no_reverberation", False))
    params = [{"range_m": float(r), "bearing_deg": float(b), "n_pings": int(n), "methods": METHODS,
               "reverberation": reverberation, "timing_repeats": repeats} for r, b, n in zip(ranges, bearings, sizes)]
    trials = make_trials(config.seed, params)
    start = time.perf_counter()
    groups = run_trials(measure_group, trials, workers=config.workers, description=config.name,
                        progress=config.progress)
    wall_s = time.perf_counter() - start
    summary = summarise(groups, METHODS)
    ratios = time_ratios(summary)
    record_s, samples = groups[0]["record_length_s"], groups[0]["timed_samples"]
    report = ExperimentReport(config.name, config.out_dir)
    report.results = {
        "seed": config.seed, "reverberation": reverberation, "pings": total, "pings_per_position": per, "positions": n_groups,
        "range_m": [lo, hi], "correct_threshold_m": CORRECT_M, "wall_time_s": wall_s,
        "timed_record_length_s": record_s, "timed_samples": samples, "timing_repeats": repeats,
        "search_half_width_m": GATE_HALF_WIDTH_M, "cpu_time_ratios": ratios,
        "simulate_s_per_ping": float(sum(g["simulate_s"] for g in groups) / total),
        "simulate_cpu_s_per_ping": float(sum(g["simulate_cpu_s"] for g in groups) / total),
        "summary": summary, "groups": groups,
    }
    report.add_figure(_figure(summary, METHODS, record_s * 1e3, samples, (lo, hi)), "nine_methods.png",
                      f"Correct-detection rate (range error < 1 cm), processing CPU time per ping (each method on the "
                      f"whole {record_s * 1e3:g} ms record, {samples:,} samples per channel) and median range error "
                      f"of the seed's nine combinations")
    rows = [[m, seed_combination(m).description, f"{s['correct']}/{s['estimates']}", s["correct_rate"],
             s["time_per_ping_s"] * 1e3, s["cpu_per_ping_s"] * 1e3, s["range_error_median_abs_m"] * 1e3,
             s["range_error_rms_correct_m"] * 1e3] for m, s in summary.items()]
    report.add_section(
        f"{total} pings at {n_groups} positions ({per} per position) between {lo:g} and {hi:g} m, bearings within "
        f"+/-{max_bearing:g} deg, "
        + ("with the tank's diffuse (Lambert) reverberation" if reverberation else "without diffuse reverberation "
           "(--no-reverberation)")
        + f"; single-waveform methods give one estimate per ping, averaging methods one per position. Wall time "
        f"{wall_s:.1f} s.")
    report.add_section(
        f"Timing: every method processes the whole acquired record, t = 0 to the sonar's record length "
        f"{record_s * 1e3:g} ms ({samples:,} samples per channel per ping, 3 channels), as the seed timed its "
        f"methods; the record is not cut, the echo search is restricted to the range gate +/-{GATE_HALF_WIDTH_M:g} m "
        f"around the target (``search_window_s``). Times are the median of {repeats} timed runs after an untimed "
        f"one, per acquired ping.")
    report.add_section(markdown_table(
        ["method", "combination", "correct", "rate", "wall per ping (ms)", "CPU per ping, full record (ms)",
         "median |range error| (mm)",
         "RMS error of correct (mm)"], rows))
    report.add_section(
        "Seed (figs. 4-15 to 4-17): a higher correct-detection rate costs more time; the matched filter dominates "
        "both; averaging and band-pass cost little and help; the local matched processing (9) improves the rate at "
        "much less time than the full matched filter.")
    report.add_section(
        "Here: local matched (9) over the full matched filter on the averaged waveform, CPU time per ping: "
        + ", ".join(f"{k} = {v:.2f}" for k, v in ratios.items())
        + f"; correct {summary['seed-9']['correct']}/{summary['seed-9']['estimates']} against "
        f"{summary['seed-4']['correct']}/{summary['seed-4']['estimates']} (seed-4) and "
        f"{summary['seed-8']['correct']}/{summary['seed-8']['estimates']} (seed-8).")
    report.add_section(
        "The rates are those of the whole record: each method's noise floor is estimated over the whole record "
        "(which holds the tank's other echoes and reverberation), and the matched filters' detection threshold "
        "holds a false-alarm probability of 1e-3 over the searched lags (binsonar's "
        "`MatchedPlan.threshold_factor`); the weakest (farthest) echoes can fall below it and count as missed. "
        "In the note below, \"range gate\" is the search window: the record is not cut here, so the prism's rear "
        "edges are in the record but outside the search.")
    from acoustisim.experiments.sweep import PHYSICS_NOTE

    report.add_section(PHYSICS_NOTE)
    return report
