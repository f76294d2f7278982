"""The common driver of the range and angle sweeps (seed section 4.2.3, figures 4-13 and 4-14)."""

from __future__ import annotations

import math
from typing import Any, Sequence

from acoustisim.experiments.config import ExperimentConfig
from acoustisim.experiments.report import ExperimentReport, markdown_table
from acoustisim.experiments.runner import make_trials, run_trials

PHYSICS_NOTE = (
    "Physics differences from the seed's tank: the noise here is the simulated receiver chain's "
    "(thermal noise, a coloured electrical noise of 2 uV/sqrt(Hz) at 500 kHz falling 3 dB per octave whose "
    "level varies by 3 dB from ping to ping, illustrative interference lines at 153.6 kHz, 460.8 kHz and "
    "1.25 MHz, and 12-bit quantisation), a model of the electrical noise the seed blames on its motion "
    "control system, PC and building but never measured as a spectrum; and the target is a simulated rigid-steel wedge (Biot-Tolstoy-Medwin "
    "edge diffraction) in a tank with perfectly flat walls. The echo level, and so the SNR at each "
    "position, follows from the simulated source level and receiver gains, not from the seed's "
    "hardware; errors are therefore comparable in trend, not in absolute value. The simulated head "
    "is at mid-depth and the range gate keeps +/-0.2 m around the edge, so the prism's rear edges, "
    "the walls and most floor/surface paths are outside the record (the seed does not say how its "
    "record was windowed)."
)


REVERBERATION_NOTE = (
    "Reverberation: the simulation includes diffuse (Lambert) scattering from the floor, surface, walls and "
    "the prism's faces (Monte Carlo rays). It is the same in every ping, so averaging does not reduce it: "
    "floor and surface patches at the edge's delay add a coherent interference that shifts the matched-filter "
    "TOF by tens of ns, and at short range (< 0.5 m) the prism faces' diffuse return on the side receivers can "
    "exceed the edge's diffraction, so the strongest echo in the gate is not the edge. The CRLB-derived bound "
    "counts noise only; where the errors exceed it, compare the --no-reverberation run.")


def add_sweep_arguments(parser: Any, *, pings: int) -> None:
    """Options common to both sweeps."""
    parser.add_argument("--pings", type=int, default=pings, help=f"pings averaged per measurement (default {pings})")
    parser.add_argument("--no-reverberation", action="store_true",
                        help="leave out the diffuse (Lambert) reverberation of the floor, surface, walls and prism")
    parser.add_argument("--detectors", default="threshold,matched",
                        help="comma-separated detection methods (default threshold,matched)")


def detectors_of(config: ExperimentConfig) -> tuple[str, ...]:
    """The detectors option as a tuple (validated against binsonar's methods)."""
    from acoustisim.errors import InputError
    from binsonar.detection import METHODS

    names = tuple(s.strip() for s in str(config.option("detectors", "threshold,matched")).split(",") if s.strip())
    bad = [n for n in names if n not in METHODS]
    if bad or not names:
        raise InputError(f"--detectors {','.join(bad) or '(empty)'}: unknown method (known: {', '.join(METHODS)})")
    return names


def run_sweep(config: ExperimentConfig, *, variable: str, values: Sequence[float], fixed: dict[str, float],
              default_repeats: int, default_pings: int, title: str, figure_name: str, seed_note: str) -> ExperimentReport:
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
    """
    from acoustisim.errors import InputError
    from acoustisim.experiments.figures import sweep_figure
    from acoustisim.experiments.point_target import measure_position, summarise

    repeats = config.trials_or(default_repeats)
    pings = int(config.option("pings", default_pings))
    if repeats < 1 or pings < 1:
        raise InputError(f"--trials ({repeats}) and --pings ({pings}) must be >= 1")
    detectors = detectors_of(config)
    reverberation = not bool(config.option("no_reverberation", False))
    params = [{variable: float(v), **fixed, "n_pings": pings, "repeats": repeats, "detectors": detectors,
               "reverberation": reverberation} for v in values]
    trials = make_trials(config.seed, params)
    import time

    start = time.perf_counter()
    positions = run_trials(measure_position, trials, workers=config.workers, description=config.name,
                           progress=config.progress)
    wall_s = time.perf_counter() - start
    summary = summarise(positions, detectors)
    report = ExperimentReport(config.name, config.out_dir)
    report.results = {
        "seed": config.seed, "reverberation": reverberation, "repeats_per_position": repeats, "pings_averaged": pings, "detectors": list(detectors),
        "swept": variable, "fixed": fixed, "wall_time_s": wall_s, "workers": config.workers,
        "summary": summary["summary"], "positions": summary["positions"], "raw": positions,
    }
    xs = [p[variable] for p in positions]
    fig = sweep_figure(xs, summary["positions"], detectors,
                       xlabel="range (m)" if variable == "range_m" else "bearing (deg)", title=title)
    report.add_figure(fig, figure_name, title)
    s = summary["summary"]
    header = [variable.replace("_", " "), "bound range (mm)"]
    for m in detectors:
        header += [f"{m} range RMS (mm)", f"{m} bearing RMS (deg)", f"{m} detected"]
    header += ["bound bearing (deg)"]
    rows = []
    for p in summary["positions"]:
        row: list[Any] = [p[variable], p["bound_range_m"] * 1e3]
        for m in detectors:
            row += [p[m]["range_rms_m"] * 1e3, p[m]["bearing_rms_deg"], f"{p[m]['detection_rate']:.0%}"]
        row += [p["bound_bearing_deg"]]
        rows.append(row)
    timing = [f"- simulation: {s['simulate_s_per_ping'] * 1e3:.1f} ms per ping wall, "
              f"{s['simulate_cpu_s_per_ping'] * 1e3:.1f} ms CPU (synthesis); "
              f"{s['solve_s_per_position']:.2f} s wall, {s['solve_cpu_s_per_position']:.2f} s CPU per position "
              "(propagation, once per position)"]
    for m in detectors:
        timing.append(f"- {m}: {s[m]['elapsed_s_per_position'] * 1e3:.2f} ms wall, {s[m]['cpu_s_per_position'] * 1e3:.2f}"
                      f" ms CPU per position (detection of one averaged ping, 3 channels); detected at "
                      f"{s[m]['detection_rate']:.0%} of measurements")
    cpu_total = sum(r["solve_cpu_s"] + r["simulate_cpu_s_per_ping"] * repeats * pings
                    + sum(sum(r["detectors"][m]["cpu_s"]) for m in detectors) for r in positions)
    report.results["cpu_time_s"] = cpu_total
    timing.append(f"- wall time {wall_s:.1f} s for {len(positions)} positions x {repeats} x {pings} pings "
                  f"({config.workers or 'all'} worker(s)); CPU time of the trials {cpu_total:.1f} s in all")
    if "matched" in detectors:
        within = s["matched"]["positions_within_1_5_bound"]
        timing.append(f"- matched-filter range RMS within 1.5x the bound at {within} of {len(positions)} positions "
                      f"(largest ratio {s['matched']['max_range_rms_over_bound']:.3g}; RMS over {repeats} "
                      "measurement(s) per position)")
    report.add_section(seed_note)
    report.add_section(REVERBERATION_NOTE if reverberation else
                       "Run with --no-reverberation: the diffuse (Lambert) scattering of the floor, surface, walls "
                       "and prism is left out; the records hold the edge's diffraction, specular multipaths and noise.")
    report.add_section("\n".join(timing))
    report.add_section(markdown_table(header, rows))
    report.add_section(PHYSICS_NOTE)
    return report


def frange(start: float, stop: float, step: float) -> list[float]:
    """Inclusive float range, rounded to the step's decimals."""
    n = int(math.floor((stop - start) / step + 1e-9)) + 1
    decimals = max(0, -int(math.floor(math.log10(step))) + 1)
    return [round(start + i * step, decimals) for i in range(n)]
