"""The measurement of one sweep position (seed section 4.2.3), and the threshold's calibration.

One position (``measure_position``, a runner function): the paths solved once (or once per
repeat with fresh reverberation), then per repeat ``n_pings`` pings simulated and averaged (the
seed's 50), the record gated (``edge_scene.position_setup``), every detector run on it
(``sweep_detectors.measure_detectors``). With the first repeat also: the noise-free records of the
path subsets and each detector's bias on them (``noise_free_bias``), and the bound at the
averaged ping's true SNR (``binsonar.estimation.noise_bound``: the edge's noise-free echo in the
ping's actual noise, the record minus the noise-free record). At the end, the bound with the
diffuse reverberation counted as Gaussian interference at its level at the echo's delay
(``binsonar.estimation.reverberation_bound``), averaged over the realisations measured (one when
frozen, one per repeat with ``fresh_reverberation``).

The threshold detector is the seed's: a preset level and an offset calibrated once per sweep
(``calibrate_threshold``).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from acoustisim.experiments.edge_scene import NOISE_FREE_PARTS, Position, path_subsets, position_setup, solver_config
from acoustisim.experiments.gating import gate_recording
from acoustisim.experiments.noise_free_bias import noise_free_errors, noise_free_records
from acoustisim.experiments.runner import Trial
from acoustisim.experiments.sweep_detectors import (
    DETECTORS,
    DetectorMeasurement,
    PointGeometry,
    recording_array,
    measure_detectors,
)

THRESHOLD_LEVEL_SIGMA = 6.0
"""The seed's preset threshold, set once per sweep: this many noise standard deviations of the
averaged ping at the calibration position (a per-sample false-alarm probability of 2e-9)."""


def _simulate(position: Position, paths: Any, synthesiser: Any, seed: int, n_pings: int) -> Any:
    """``n_pings`` pings at the position, averaged when more than one."""
    from acoustisim.simulation import simulate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # arrivals past the short record are left out on purpose
        return simulate(position.scene, position.sonar, paths=paths, seed=seed, n_pings=n_pings, average=n_pings > 1,
                        synthesiser=synthesiser)


def calibrate_threshold(range_m: float, bearing_deg: float, n_pings: int, seed: int,
                        reverberation: bool = True) -> dict[str, float]:
    """The seed's threshold detector: a preset level and a TOF offset calibrated at one position.

    The seed (section 4.1.1) compares the echo with a pre-set level (0.04 V in its figure 4-1)
    and notes that the crossing comes after the echo's start by a rise time that depends on the
    echo's amplitude, so a constant calibration is right at one amplitude only. Here the level is
    ``THRESHOLD_LEVEL_SIGMA`` times the averaged ping's noise (left/right mean) at the
    calibration position, and the offset is the template's crossing delay at the edge's echo
    amplitude there (``binsonar`` threshold option ``calibrate_amplitude_v``); both then stay
    fixed for the whole sweep, so weaker echoes (longer range, larger angle) cross later.

    Returns
    -------
    dict
        ``level_v``, ``amplitude_v`` (peak of the edge's noise-free echo, left/right mean),
        ``range_m``, ``bearing_deg``.
    """
    from acoustisim.propagation import solve
    from acoustisim.simulation import simulate
    from acoustisim.synthesis.pings import PingSynthesiser

    position = position_setup(range_m, bearing_deg)
    paths = solve(position.scene, position.sonar, solver_config({"reverberation": reverberation}))
    synthesiser = PingSynthesiser.create(position.sonar, position.scene.medium)
    edge = paths.select(path_subsets(paths)["edge"])  # keeps the rows' transfer functions (Paths.responses)
    sim = _simulate(position, paths, synthesiser, seed, n_pings)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        edge_clean = simulate(position.scene, position.sonar, paths=edge, n_pings=1, synthesiser=synthesiser).clean
    fs = sim.recording.sample_rate_hz
    t0 = sim.recording.t0_s
    gate = position.gate
    span = slice(int(math.floor((gate[0] - t0) * fs)), int(math.ceil((gate[1] - t0) * fs)))
    noise = sim.recording.waveforms[0, :, span] - np.asarray(sim.clean)[:, span]
    sigma = float(np.mean(np.std(noise[[0, 2]], axis=1)))
    amplitude = float(np.mean(np.max(np.abs(np.asarray(edge_clean)[[0, 2], span]), axis=1)))
    return {"level_v": THRESHOLD_LEVEL_SIGMA * sigma, "amplitude_v": amplitude, "range_m": range_m,
            "bearing_deg": bearing_deg}


@dataclass
class Stopwatch:
    """Wall and CPU time (s) spent in the calls it times, summed (one per kind of work)."""

    wall_s: float = 0.0
    cpu_s: float = 0.0

    def time(self, work: Callable[[], Any]) -> Any:
        """``work()``, its wall and CPU time added."""
        wall, cpu = time.perf_counter(), time.process_time()
        result = work()
        self.wall_s += time.perf_counter() - wall
        self.cpu_s += time.process_time() - cpu
        return result


@dataclass(frozen=True)
class MeasurementSettings:
    """A trial's parameters (``measure_position``), read once.

    Attributes
    ----------
    range_m, bearing_deg : float
    n_pings, repeats : int
    detectors : tuple of str
    fresh : bool
        A new realisation of the diffuse reverberation per repeat (needs reverberation).
    diffuse_seeds : list of int
        The diffuse tracer's seed of each realisation (one when frozen).
    threshold_options : dict
        The sweep's calibrated threshold level and amplitude (binsonar's options), or {}.
    params : dict
        All the trial's parameters (for ``edge_scene.solver_config``).
    """

    range_m: float
    bearing_deg: float
    n_pings: int
    repeats: int
    detectors: tuple[str, ...]
    fresh: bool
    diffuse_seeds: list[int]
    threshold_options: dict[str, float] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_trial(cls, trial: Trial) -> "MeasurementSettings":
        """The settings of a runner trial (its parameters and seed)."""
        p = dict(trial.params)
        repeats = int(p["repeats"])
        fresh = bool(p.get("fresh_reverberation", False)) and bool(p.get("reverberation", True))
        seeds = ([int(v) for v in np.random.SeedSequence([trial.seed, 1]).generate_state(repeats, dtype=np.uint32)]
                 if fresh else [int(p.get("diffuse_seed", 0))])
        threshold = ({"level_v": float(p["threshold_level_v"]), "calibrate_amplitude_v": float(p["threshold_amplitude_v"])}
                     if "threshold_level_v" in p else {})
        return cls(range_m=float(p["range_m"]), bearing_deg=float(p["bearing_deg"]), n_pings=int(p["n_pings"]),
                   repeats=repeats, detectors=tuple(p.get("detectors", DETECTORS)), fresh=fresh, diffuse_seeds=seeds,
                   threshold_options=threshold, params=p)

    def solver_config(self, realisation: int) -> Any:
        """Propagation settings with the diffuse seed of realisation ``realisation``."""
        return solver_config({**self.params, "diffuse_seed": self.diffuse_seeds[realisation]})


def _header(settings: MeasurementSettings, position: Position) -> dict[str, Any]:
    """The position's own fields of ``measure_position``'s result, with empty per-detector lists."""
    return {
        "range_m": settings.range_m, "bearing_deg": settings.bearing_deg,
        "truth_range_m": position.truth.range_m, "truth_bearing_deg": position.truth.bearing_deg,
        "truth_tof_s": position.truth_tof_s,
        "sonar_position_m": list(position.sonar.position_m), "sonar_yaw_deg": position.sonar.yaw_deg,
        "gate_s": list(position.range_gate_s), "n_pings": settings.n_pings, "fresh_reverberation": settings.fresh,
        "diffuse_seeds": settings.diffuse_seeds,
        "detectors": {m: {k: [] for k in DetectorMeasurement._fields} for m in settings.detectors},
    }


def _gated_span(recording: Any, gated: Any) -> slice:
    """The samples of ``recording`` that ``gated`` (``gating.gate_recording`` of it) holds."""
    fs = recording.sample_rate_hz
    i0 = int(round((gated.t0_s - recording.t0_s) * fs))
    return slice(i0, i0 + gated.waveforms.shape[-1])


def measure_position(trial: Trial) -> dict[str, Any]:
    """Simulate and measure one position, ``repeats`` times (a module-level function for the runner).

    Trial parameters: ``range_m``, ``bearing_deg``, ``n_pings``, ``repeats``; optional
    ``detectors`` (tuple of method names), ``max_order`` and ``reverberation`` (propagation, see
    ``edge_scene.solver_config``), ``threshold_level_v`` and ``threshold_amplitude_v``
    (``calibrate_threshold``'s) and ``fresh_reverberation``: False (default) keeps one
    realisation of the diffuse reverberation for every repeat, as one tank does (diffuse seed 0);
    True draws a new one per repeat (diffuse seeds from ``trial.seed``), the ensemble over rough
    surfaces that a bound counting the reverberation as Gaussian interference is an expectation
    over.

    Returns
    -------
    dict
        ``range_m``, ``bearing_deg``, truth, ``solve_s``, ``simulate_s_per_ping``, per detector
        lists over the repeats of the ``sweep_detectors.DetectorMeasurement`` fields, the bounds
        (``noise_bound_*``, ``optimal_bound_*``, ``reverb_bound_*``), and ``noise_free``: per part
        of ``NOISE_FREE_PARTS`` the ``noise_free_errors`` of the first repeat (the bias of every
        repeat when the reverberation is frozen); with fresh reverberation also
        ``noise_free_all_by_repeat``, the ``all`` part of every repeat.
    """
    from acoustisim.propagation import solve
    from acoustisim.synthesis.pings import PingSynthesiser
    from binsonar.estimation import noise_bound, reverberation_bound

    settings = MeasurementSettings.from_trial(trial)
    position = position_setup(settings.range_m, settings.bearing_deg)
    scene, sonar, truth = position.scene, position.sonar, position.truth
    c = position.sound_speed_m_s
    solving, simulating = Stopwatch(), Stopwatch()
    paths, synthesiser = solving.time(lambda: (solve(scene, sonar, settings.solver_config(0)),
                                               PingSynthesiser.create(sonar, scene.medium)))
    out = _header(settings, position)

    def bias(recording: Any, clean: Any) -> dict[str, Any]:
        return noise_free_errors(recording, clean, settings.detectors, position.truth_tof_s, truth, c, half_baseline,
                                 position.gate, transducers)

    seeds = np.random.SeedSequence(trial.seed).generate_state(settings.repeats, dtype=np.uint32)
    reverberation: list[Any] = []  # the diffuse reverberation alone over the gate, per realisation
    for k in range(settings.repeats):
        if settings.fresh and k > 0:
            paths = solving.time(lambda: solve(scene, sonar, settings.solver_config(k)))
        sim = simulating.time(lambda: _simulate(position, paths, synthesiser, int(seeds[k]), settings.n_pings))
        recording = gate_recording(sim.recording, *position.gate)
        if k == 0:  # the head from the recording; the bias decomposition and the bound
            half_baseline, transducers = recording_array(sim.recording)
            geometry = PointGeometry(c, half_baseline, truth.range_m, truth.bearing_deg)
            records = noise_free_records(position, paths, synthesiser, sim.clean)
            out["noise_free"] = {part: bias(sim.recording, records[part]) for part in NOISE_FREE_PARTS}
            span = _gated_span(sim.recording, recording)
            noise = sim.recording.waveforms[0, :, span] - np.asarray(sim.clean)[:, span]
            edge_echo = np.asarray(records["edge"])[:, span]
            template = sim.recording.template.samples
            fs = sim.recording.sample_rate_hz
            bound = noise_bound(edge_echo, noise, template, fs, geometry.range_m, geometry.bearing_deg, c, half_baseline)
            out["noise_bound_range_m"], out["noise_bound_bearing_deg"] = bound.measured
            out["noise_snr_db"] = list(bound.snr_db)
            out["optimal_bound_range_m"], out["optimal_bound_bearing_deg"] = bound.optimal
        elif settings.fresh:
            out.setdefault("noise_free_all_by_repeat", [out["noise_free"]["all"]]).append(bias(sim.recording, sim.clean))
        if k == 0 or settings.fresh:
            reverberation.append(np.asarray(sim.clean)[:, span] - np.asarray(records["specular"])[:, span])
        rows = measure_detectors(recording, settings.detectors, geometry, transducers, settings.threshold_options)
        for method, row in rows.items():
            for key, value in row._asdict().items():
                out["detectors"][method][key].append(value)
    with_reverb = reverberation_bound(edge_echo, noise, reverberation, template, fs, geometry.range_m,
                                      geometry.bearing_deg, c, half_baseline)
    out["reverb_bound_range_m"], out["reverb_bound_bearing_deg"] = with_reverb.bound
    out["reverb_to_noise_db"] = list(with_reverb.reverb_to_noise_db)
    out["reverb_realisations"] = len(reverberation)
    out["solve_s"], out["solve_cpu_s"] = solving.wall_s, solving.cpu_s
    out["simulate_s_per_ping"] = simulating.wall_s / (settings.repeats * settings.n_pings)
    out["simulate_cpu_s_per_ping"] = simulating.cpu_s / (settings.repeats * settings.n_pings)
    return out
