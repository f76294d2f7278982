"""The common driver of the range and angle sweeps (seed section 4.2.3, figures 4-13 and 4-14)."""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from acoustisim.experiments.config import ExperimentConfig
from acoustisim.experiments.report import ExperimentReport, markdown_table
from acoustisim.experiments.runner import make_trials, run_trials

PHYSICS_NOTE = (
    "Physics differences from the seed's tank: the noise here is the simulated receiver chain's "
    "(thermal noise, a coloured electrical noise of 2 uV/sqrt(Hz) at 500 kHz falling 3 dB per octave whose "
    "level varies by 3 dB from ping to ping, illustrative interference lines at 153.6 kHz, 460.8 kHz and "
    "1.25 MHz, and 12-bit quantisation), a model of the electrical noise the seed blames on its motion "
    "control system, PC and building but never measured as a spectrum; the target is a simulated machined-steel "
    "60-degree prism (Biot-Tolstoy-Medwin edge diffraction) standing floor to surface in the concrete tank, the "
    "head at mid-depth (the seed gives neither its depth nor the target's height, nor the fixed bearing and range "
    "of its two sweeps). The echo level, and so the SNR at each position, follows from the simulated source level "
    "and receiver gains, not from the seed's hardware; errors are therefore comparable in trend, not in absolute "
    "value. The range gate keeps +/-0.1 m around the edge, so the prism's rear edges (0.43 m behind) are outside "
    "the record (the seed does not say how its record was windowed). The head sits on the tank's centre line at "
    "mid-depth, 0.5 m from the floor and the surface and 1.5 m from both side walls: at ranges of 0.4-0.6 m and "
    "1.4-1.6 m their normal-incidence echoes (in the pistons' far sidelobes, 88-92 deg off axis, but from planes) "
    "fall inside the gate and the threshold detector's first crossing is theirs. The propagation keeps specular "
    "paths up to order 4, because the head's vertical multiples (floor and surface, 90 deg off every axis) return at "
    "ranges k x 0.5 m: the floor or surface alone at 0.5 m, the floor-surface pair at 1.0 m, order 3 at 1.5 m, order "
    "4 at 2.0 m (in a 1 m deep tank ranges of 1.0 and 2.0 m carry such a multiple at any head depth). Order 5, at "
    "2.5 m, is not modelled (the engine stops at 4 reflections). From 1.15 to 1.35 m no specular path of order 4 or "
    "less reaches the gate at any bearing within +/-12 deg, so the angle sweep runs at 1.25 m by default (at 2.0 m "
    "the order-4 multiple lies 1.8 us before the edge's echo and biases the range by tens of um near 0 deg)."
)

BIAS_NOTE = (
    "Bias and scatter: every repeat of a position has the same echo and new noise, so the error is a bias "
    "(the same in every repeat) plus a scatter. The bias is measured by running the detector on the noise-free "
    "averaged record, and split by re-synthesising it from subsets of the paths: `edge` (the edge's diffraction "
    "alone), `+specular` (plus walls, floor and surface), `+diffuse` (plus Lambert reverberation). Without "
    "directivity the edge alone gives a TOF within 2 ns of the geometric (least-time) truth at every range: the "
    "half-integrated echo does not bias the envelope peak. With the 19 mm pistons' per-frequency directivity, "
    "the beam cuts the vertical edge's Fresnel zone (the late, off-axis part of the edge's response), so the "
    "echo is shorter than the half-integrated pulse and the matched-filter peak comes early (measured once, at "
    "the default bearing: -8 ns at 1 m, -3 ns at 2.5 m on the side channels; this run's are the table's `edge` "
    "column); below 0.5 m the side receivers see the edge 10-35 deg off their axes "
    "(d = 65 mm), near or past the 500 kHz first null (11 deg), and the echo is distorted by microseconds. "
    "The bound is the CRLB at the measured SNR of the averaged ping: sigma_tau = 1 / (2 pi beta sqrt(2E/N0)), "
    "beta the template's RMS bandwidth (118 kHz for the default 5 us pulse), 2E/N0 the matched filter's output "
    "SNR of the edge's noise-free "
    "echo in the ping's actual averaged noise (both known in the simulation), on the left and right channels, "
    "propagated to range and bearing through the localiser's linearised covariance (`binsonar.estimation.noise_bound`). "
    "It bounds the scatter, not the bias. The JSON also holds the detector's own bound "
    "(`detector_bound_range_m`: its noise floor, the median over the gate, includes the frozen reverberation, "
    "so it is larger than this bound wherever reverberation reaches the gate), the optimal bound (`optimal_bound_range_m`: the received echo's own spectrum in "
    "the noise's own spectrum, which a whitened filter matched to the echo would reach) and the bound with the "
    "diffuse reverberation counted as Gaussian interference (`reverb_bound_range_m`, `binsonar.estimation.reverberation_bound`): "
    "the same CRLB with the reverberation's level at the echo's delay (the matched filter's output power of the "
    "reverberation alone over one template length around the edge's peak, averaged over the realisations "
    "measured, as the sonar equation's reverberation level) added to the noise's.")

BEAM_NOTE = (
    "Beam-aware matched filter (`beam-matched`): the matched filter's echoes refined by binsonar's beam-aware TOF "
    "estimator (`binsonar.localization.beam_refine`), which takes the pistons (19 mm, the V318's) and the baseline "
    "from the recording's array description (`recording.array.transducers()`, written by the simulator into every "
    "recording) and is told the target class (a vertical edge, a rigid 60-degree wedge facing the "
    "sonar). From a first localisation it builds per channel the echo the pistons receive from the edge (the "
    "template filtered per frequency by the beam-weighted Biot-Tolstoy-Medwin line integral along the edge, "
    "D_tx(f, theta_tx(z)) D_rx(f, theta_rx(z)) beta(z) / (m l) at delay tau(z)) and takes the maximum of the "
    "correlation's envelope with it, whose reference is the geometric TOF by construction (no offset to "
    "calibrate); three locate-and-refine passes. Where the plain filter finds the edge on two channels but not on "
    "the third (the far receiver near its null at +/-11-12 deg), the two echoes predict when and with what shape "
    "it arrives there, and a search with that shape within a few microseconds finds it "
    "(`binsonar.localization.beam_cue`, false-alarm probability 1e-3 over its window). "
    "The simulator's physics, the bound and the scene are unchanged. "
    "Its noise-free bias `edge` is the beam's residue (well under 1 um of range at every position of the default "
    "sweeps; this run's is in the table); what remains "
    "in `+diffuse` is the frozen Lambert reverberation of the floor, walls and the prism's faces, the same in "
    "every ping, which no filter matched to the edge removes: where it exceeds the bound, the RMS exceeds 1.5x "
    "the bound, and the last column counts it as Gaussian interference instead.")

REVERBERATION_NOTE = (
    "Reverberation: the simulation includes diffuse (Lambert) scattering from the floor and walls (concrete, "
    "mu = 0.01) and the prism's faces. The prism's faces are machined steel: their Lambert strength "
    "(about 2e-5) follows from small-perturbation backscatter for a 3 um rms roughness (an upper bound over "
    "correlation lengths), not the library's steel (mu = 0.002, which needs about 30 um rms); with mu = 0.002 "
    "the faces' frozen speckle right behind the edge shifts the TOF by up to 240 ns. The floor's reverberation "
    "at the edge's delay changed the TOF by a few ns at most in the default sweeps (this run's: the table's "
    "`+diffuse` bias against `+specular`). Reverberation is the same in every ping, so "
    "averaging does not reduce it.")


FRESH_NOTE = (
    "Fresh reverberation (--fresh-reverberation): every measurement of a position draws a new realisation of the "
    "diffuse field (a new seed of the Lambert tracer: new scattering points and speckle on the same surfaces, as "
    "if the rough surfaces were made anew), so the RMS over the measurements estimates the error over that "
    "ensemble: noise and reverberation both random, the model in which the bound with the reverberation counted "
    "as Gaussian interference is a Cramer-Rao bound. The bias column's `+diffuse` part is then the RMS over the "
    "realisations of each one's noise-free bias, and the scatter is taken about each measurement's own bias. "
    "Without the option one realisation (seed 0) is frozen for every measurement, as in one tank: its bias is "
    "the same in every measurement and averaging does not remove it.")


DEFAULT_DETECTORS = "threshold,matched,beam-matched"
"""The seed's two detectors and the matched filter with binsonar's beam-aware refinement."""


def add_sweep_arguments(parser: Any, *, pings: int) -> None:
    """Options common to both sweeps."""
    parser.add_argument("--pings", type=int, default=pings, help=f"pings averaged per measurement (default {pings})")
    parser.add_argument("--no-reverberation", action="store_true",
                        help="leave out the diffuse (Lambert) reverberation of the floor, surface, walls and prism")
    parser.add_argument("--fresh-reverberation", action="store_true",
                        help="draw a new realisation of the diffuse reverberation for every measurement (the ensemble "
                             "over rough surfaces) instead of one frozen realisation per position, as in one tank")
    parser.add_argument("--detectors", default=DEFAULT_DETECTORS,
                        help=f"comma-separated detection methods (default {DEFAULT_DETECTORS}); beam-matched is the "
                             "matched filter refined by binsonar's beam-aware TOF estimator with the sonar's pistons")


def detectors_of(config: ExperimentConfig) -> tuple[str, ...]:
    """The detectors option as a tuple (validated against binsonar's methods)."""
    from acoustisim.errors import InputError
    from acoustisim.experiments.sweep_detectors import BEAM_MATCHED
    from binsonar.detection import METHODS

    known = (*METHODS, BEAM_MATCHED)
    names = tuple(s.strip() for s in str(config.option("detectors", DEFAULT_DETECTORS)).split(",") if s.strip())
    bad = [n for n in names if n not in known]
    if bad or not names:
        raise InputError(f"--detectors {','.join(bad) or '(empty)'}: unknown method (known: {', '.join(known)})")
    return names


def run_sweep(config: ExperimentConfig, *, variable: str, values: Sequence[float], fixed: dict[str, float],
              default_repeats: int, default_pings: int, title: str, figure_name: str, seed_note: str,
              calibration_at: tuple[float, float]) -> ExperimentReport:
    """Measure every position in parallel and build the report.

    Parameters
    ----------
    config : ExperimentConfig
        ``trials``: repeated measurements (each of ``--pings`` averaged pings) per position.
    variable : {"range_m", "bearing_deg"}
        The swept parameter.
    values : sequence of float
    fixed : dict
        The other parameter.
    calibration_at : (range_m, bearing_deg)
        Where the threshold detector's preset level and offset are calibrated
        (``position_measurement.calibrate_threshold``), once for the sweep.
    """
    from acoustisim.errors import InputError
    from acoustisim.experiments.figures import sweep_figure
    from acoustisim.experiments.position_measurement import calibrate_threshold, measure_position
    from acoustisim.experiments.sweep_detectors import BEAM_MATCHED, BOUNDED_DETECTORS
    from acoustisim.experiments.sweep_summary import summarise

    repeats = config.trials_or(default_repeats)
    pings = int(config.option("pings", default_pings))
    if repeats < 1 or pings < 1:
        raise InputError(f"--trials ({repeats}) and --pings ({pings}) must be >= 1")
    detectors = detectors_of(config)
    reverberation = not bool(config.option("no_reverberation", False))
    fresh = reverberation and bool(config.option("fresh_reverberation", False))

    calibration: dict[str, float] = {}
    extra: dict[str, float] = {}
    if "threshold" in detectors:
        calibration = calibrate_threshold(*calibration_at, n_pings=pings, seed=config.seed,
                                          reverberation=reverberation)
        extra = {"threshold_level_v": calibration["level_v"], "threshold_amplitude_v": calibration["amplitude_v"]}
    params = [{variable: float(v), **fixed, "n_pings": pings, "repeats": repeats, "detectors": detectors,
               "reverberation": reverberation, "fresh_reverberation": fresh, **extra} for v in values]
    trials = make_trials(config.seed, params)
    import time

    start = time.perf_counter()
    positions = run_trials(measure_position, trials, workers=config.workers, description=config.name,
                           progress=config.progress)
    wall_s = time.perf_counter() - start
    summary = summarise(positions, detectors)
    report = ExperimentReport(config.name, config.out_dir)
    report.results = {
        "seed": config.seed, "reverberation": reverberation, "fresh_reverberation": fresh, "repeats_per_position": repeats, "pings_averaged": pings, "detectors": list(detectors),
        "swept": variable, "fixed": fixed, "threshold_calibration": calibration, "wall_time_s": wall_s, "workers": config.workers,
        "summary": summary["summary"], "positions": summary["positions"], "raw": positions,
    }
    xs = [p[variable] for p in positions]
    fig = sweep_figure(xs, summary["positions"], detectors,
                       xlabel="range (m)" if variable == "range_m" else "bearing (deg)", title=title)
    bounded = [m for m in BOUNDED_DETECTORS if m in detectors]
    for m in bounded:
        # The noise-free bias (|.|) and the scatter about it, on the range and bearing axes.
        ax_r, ax_b = fig.axes[0], fig.axes[1]
        rows = summary["positions"]
        colour = {"matched": ("tab:green", "tab:purple"), BEAM_MATCHED: ("tab:olive", "tab:pink")}[m]
        for ax, bias_key, scatter_key, scale in ((ax_r, "bias_range_m", "scatter_range_rms_m", 1e3),
                                                 (ax_b, "bias_bearing_deg", "scatter_bearing_rms_deg", 1.0)):
            bias = np.array([abs(r[m].get(bias_key, np.nan)) for r in rows], dtype=float) * scale
            scatter = np.array([r[m].get(scatter_key, np.nan) for r in rows], dtype=float) * scale
            ax.semilogy(xs, bias, "v", ms=3, color=colour[0], label=f"{m} |bias| (noise-free)")
            ax.semilogy(xs, scatter, "^", ms=3, color=colour[1], label=f"{m} scatter RMS")
            ax.legend(fontsize=6, loc="best")
    report.add_figure(fig, figure_name, title)
    s = summary["summary"]
    header = [variable.replace("_", " "), "bound range (um)", "bound bearing (mdeg)"]
    for m in detectors:
        header += [f"{m} range RMS (um)", f"{m} bearing RMS (mdeg)", f"{m} detected"]
    for m in bounded:
        header += [f"{m} bias edge / +specular / +diffuse (um)", f"{m} scatter RMS (um)", f"{m} RMS / bound",
                   f"{m} bearing RMS / bound", f"{m} scatter / bound", f"{m} RMS / bound with reverberation"]
    rows = []
    for p in summary["positions"]:
        row: list[Any] = [p[variable], p["bound_range_m"] * 1e6, p["bound_bearing_deg"] * 1e3]
        for m in detectors:
            row += [p[m]["range_rms_m"] * 1e6, p[m]["bearing_rms_deg"] * 1e3, f"{p[m]['detection_rate']:.0%}"]
        for m in bounded:
            mf = p[m]
            parts = mf.get("bias_range_parts_m", {})
            row += [" / ".join(f"{parts.get(k, float('nan')) * 1e6:.1f}" for k in ("edge", "specular", "all")),
                    mf.get("scatter_range_rms_m", float("nan")) * 1e6, mf["range_rms_over_bound"],
                    mf["bearing_rms_over_bound"], mf["scatter_range_rms_over_bound"],
                    mf.get("range_rms_over_reverb_bound", float("nan"))]
        rows.append(row)
    timing = [f"- simulation: {s['simulate_s_per_ping'] * 1e3:.1f} ms per ping wall, "
              f"{s['simulate_cpu_s_per_ping'] * 1e3:.1f} ms CPU (synthesis); "
              f"{s['solve_s_per_position']:.2f} s wall, {s['solve_cpu_s_per_position']:.2f} s CPU per position "
              + ("(propagation, once per measurement: a new reverberation realisation each)" if fresh
                 else "(propagation, once per position)")]
    for m in detectors:
        timing.append(f"- {m}: {s[m]['elapsed_s_per_position'] * 1e3:.2f} ms wall, {s[m]['cpu_s_per_position'] * 1e3:.2f}"
                      f" ms CPU per position (detection of one averaged ping, 3 channels); detected at "
                      f"{s[m]['detection_rate']:.0%} of measurements")
    cpu_total = sum(r["solve_cpu_s"] + r["simulate_cpu_s_per_ping"] * repeats * pings
                    + sum(sum(r["detectors"][m]["cpu_s"]) for m in detectors) for r in positions)
    report.results["cpu_time_s"] = cpu_total
    timing.append(f"- wall time {wall_s:.1f} s for {len(positions)} positions x {repeats} x {pings} pings "
                  f"({config.workers or 'all'} worker(s)); CPU time of the trials {cpu_total:.1f} s in all")
    for m in bounded:
        mf = s[m]
        timing.append(f"- {m} range RMS within 1.5x the bound at {mf['positions_within_1_5_bound']} of "
                      f"{len(positions)} positions (largest ratio {mf['max_range_rms_over_bound']:.3g}), bearing RMS "
                      f"at {mf['positions_bearing_within_1_5_bound']}; its scatter "
                      f"about the noise-free bias within 1.5x at {mf['positions_scatter_within_1_5_bound']} "
                      f"(pooled RMS of scatter / bound {mf['pooled_scatter_range_rms_over_bound']:.2f}); RMS within "
                      f"1.5x the bound with the reverberation as Gaussian interference at "
                      f"{mf['positions_within_1_5_reverb_bound']} (largest ratio "
                      f"{mf['max_range_rms_over_reverb_bound']:.3g}, pooled RMS ratio "
                      f"{mf['pooled_range_rms_over_reverb_bound']:.2f}; "
                      f"{'a fresh realisation per measurement' if fresh else 'one frozen realisation'}); RMS over "
                      f"{repeats} measurement(s) per position (with n measurements an efficient estimator's RMS "
                      "exceeds 1.5x its bound at a position with probability P(chi2_n > 2.25 n): "
                      f"{chi2_exceedance(repeats, 2.25):.1%} for n = {repeats})")
    report.add_section(seed_note)
    if calibration:
        report.add_section(
            f"Threshold detector (the seed's section 4.1.1): a preset level, {calibration['level_v'] * 1e3:.3g} mV "
            f"(6 noise standard deviations of the averaged ping), and a TOF offset calibrated on the template at the "
            f"edge's echo amplitude ({calibration['amplitude_v'] * 1e3:.3g} mV) at {calibration['range_m']:g} m, "
            f"{calibration['bearing_deg']:g} deg, both fixed for the sweep: weaker echoes cross later (the rise-time "
            "error the seed describes). With a level relative to each record's own noise and no offset, the crossing "
            "instead comes earlier for stronger echoes, so the error would fall with range.")
    report.add_section(BIAS_NOTE)
    if BEAM_MATCHED in detectors:
        report.add_section(BEAM_NOTE)
    if fresh:
        report.add_section(FRESH_NOTE)
    report.add_section(REVERBERATION_NOTE if reverberation else
                       "Run with --no-reverberation: the diffuse (Lambert) scattering of the floor, surface, walls "
                       "and prism is left out; the records hold the edge's diffraction, specular multipaths and noise.")
    report.add_section("\n".join(timing))
    report.add_section(markdown_table(header, rows))
    report.add_section(PHYSICS_NOTE)
    return report


def chi2_exceedance(n: int, ratio_squared: float) -> float:
    """P(chi2_n / n > ``ratio_squared``): the chance that the RMS of n Gaussian samples exceeds sqrt(ratio) sigma."""
    from scipy.stats import chi2

    return float(chi2.sf(ratio_squared * n, n))


def frange(start: float, stop: float, step: float) -> list[float]:
    """Inclusive float range, rounded to the step's decimals."""
    n = int(math.floor((stop - start) / step + 1e-9)) + 1
    decimals = max(0, -int(math.floor(math.log10(step))) + 1)
    return [round(start + i * step, decimals) for i in range(n)]
