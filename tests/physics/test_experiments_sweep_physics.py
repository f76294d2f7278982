"""The range/angle sweeps' physics: the prism's roughness, the truth of the edge's TOF, bias and bound."""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from acoustisim.experiments.edge_scene import (
    EDGE_M,
    GATE_HALF_WIDTH_M,
    edge_tank_scene,
    prism_material,
    small_roughness_lambert_mu,
    solver_config,
)
from acoustisim.experiments.position_measurement import measure_position
from acoustisim.experiments.sweep_detectors import nearest_echoes
from acoustisim.experiments.runner import Trial


def test_small_roughness_mu_is_the_maximum_over_correlation_lengths() -> None:
    # Independent check of the closed form: maximise the Gaussian-spectrum SPM backscatter
    # k^4 (1 + sin^2 t)^2 h^2 L^2 / (4 pi) exp(-K^2 L^2 / 4) over L numerically.
    f, c, t_deg, h = 500e3, 1482.0, 60.0, 3e-6
    k, t = 2 * math.pi * f / c, math.radians(t_deg)
    big_k = 2 * k * math.sin(t)
    lengths = np.geomspace(1e-6, 1e-1, 200_001)
    w = h**2 * lengths**2 / (4 * math.pi) * np.exp(-(big_k * lengths) ** 2 / 4)
    sigma = k**4 * (1 + math.sin(t) ** 2) ** 2 * w.max()
    mu = small_roughness_lambert_mu(h, f, c, t_deg)
    assert mu == pytest.approx(sigma / math.cos(t) ** 2, rel=1e-6)  # grid step 6e-5 relative: 2e-9 at the peak
    # Intensity scales as h^2; a machined face scatters ~100x less than the library's steel (0.002).
    assert small_roughness_lambert_mu(2 * h, f, c, t_deg) == pytest.approx(4 * mu, rel=1e-12)
    assert prism_material().name == "steel-machined"  # a library material (tests/physics/test_materials.py checks mu)
    assert prism_material().diffuse_mu == pytest.approx(mu, rel=1e-14)  # the formula's double, a few ulp
    with pytest.raises(ValueError):
        small_roughness_lambert_mu(h, f, c, 90.0)


def test_nearest_echoes_picks_the_echo_nearest_the_truth() -> None:
    e = lambda tof: SimpleNamespace(tof_s=tof)  # noqa: E731
    result = SimpleNamespace(echoes=((
        (e(1.0e-3), e(1.3e-3)),  # left: the later one is 1 us from the truth
        (),  # centre: nothing detected
        (e(1.0e-3),),  # right: 0.3 ms away, beyond TOF_MATCH_S: not the edge
    ),))
    left, centre, right = nearest_echoes(result, [1.301e-3, 1.3e-3, 1.3e-3])
    assert left.tof_s == 1.3e-3 and centre is None and right is None


def test_edge_echo_without_directivity_peaks_at_the_least_time_truth() -> None:
    # The truth of the edge's TOF (least-time point at the sonar's height) is what an unbiased
    # matched filter returns: with the pistons made omnidirectional (off-axis angles zeroed) the
    # edge's diffraction alone, noise-free, must give the geometric TOF on every channel. The
    # half-integrated echo shifts the envelope peak by < 1 ns (measured 0.2 ns at 1 m); 2 ns is a
    # tenth of the smallest bound (~20 ns at 50 pings) and 1/5 of the beam's effect (-8 to -11 ns).
    from acoustisim.experiments.gating import gate_recording, range_window_s
    from acoustisim.experiments.geometry import pose_for_target
    from acoustisim.propagation import solve
    from acoustisim.propagation.paths import PathKind, Paths
    from acoustisim.simulation import simulate
    from binsonar.detection import detect

    scene = edge_tank_scene()
    c = float(scene.medium.sound_speed)
    range_m = 1.0
    start, stop = range_window_s(range_m, c, GATE_HALF_WIDTH_M)
    sonar = pose_for_target(scene.sonar, (*EDGE_M, scene.sonar.position_m[2]), range_m, 2.0, yaw_deg=2.0)
    sonar = replace(sonar, record_length_s=stop + 20e-6)
    paths = solve(scene, sonar, solver_config({"reverberation": False}))
    edge = paths.rows[(paths.rows["kind"] == PathKind.EDGE) & (paths.rows["order"] == 1)].copy()
    point = np.array([*EDGE_M, sonar.position_m[2]])
    truth = [(np.linalg.norm(point - sonar.transmitter_position) + np.linalg.norm(point - r)) / c
             for r in sonar.receiver_positions]
    errors = {}
    for name, omni in (("omni", True), ("piston", False)):
        rows = edge.copy()
        if omni:
            rows["angle_tx_rad"] = 0.0
            rows["angle_rx_rad"] = 0.0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sim = simulate(scene, sonar, paths=Paths(rows, paths.surface_names), n_pings=1)
        record = gate_recording(replace(sim.recording, waveforms=np.asarray(sim.clean)[np.newaxis]), start, stop)
        echoes = nearest_echoes(detect(record, "matched"), truth)
        errors[name] = np.array([e.tof_s - t for e, t in zip(echoes, truth)])
    assert np.all(np.abs(errors["omni"]) < 2e-9)
    # The beam cuts the edge's Fresnel zone: the echo is shorter and peaks early, by ~10 ns at 1 m.
    assert np.all((errors["piston"] < -3e-9) & (errors["piston"] > -30e-9))


def test_binsonar_piston_model_is_the_simulator_s() -> None:
    # binsonar may not import the simulator, so it has its own 2 J1(x)/x: the beam-aware
    # refinement models the simulated echo only if both are the same function (to rounding).
    from acoustisim.propagation.directivity import piston_directivity as simulator
    from binsonar.localization.beam_model import piston_directivity as pipeline

    rng = np.random.default_rng(0)
    angle = rng.uniform(0.0, math.pi, 2000)  # front and back of the baffle
    f = rng.uniform(0.0, 2e6, 2000)
    assert np.max(np.abs(pipeline(angle, f, 0.0095, 1482.38) - simulator(angle, f, 0.0095, 1482.38))) < 1e-15


@pytest.mark.parametrize("range_m", [0.3, 1.0])
def test_beam_aware_refinement_removes_the_beam_bias_of_the_simulated_edge(range_m: float) -> None:
    # The simulator's noise-free edge diffraction alone (BTM edge elements, per-element piston
    # directivity per frequency, absorption, the receiver chain): the plain matched filter is
    # biased early (microseconds on the side channels at 0.3 m, 10 deg off axis; ~10 ns at 1 m);
    # binsonar's beam-aware refinement, told only the pistons' diameter and the target class
    # (a rigid 60-degree wedge facing the sonar), lands within 1 ns of the least-time truth
    # (measured <= 0.3 ns at 0.3 m, <= 0.1 ns at 1 m: the model leaves out absorption's spectral
    # tilt and the edge beyond 16 us of excess delay). 1 ns is 1/20 of the smallest bound at 50
    # averaged pings.
    from acoustisim.experiments.gating import gate_recording
    from acoustisim.experiments.edge_scene import position_setup
    from acoustisim.experiments.sweep_detectors import beam_matched_echoes, recording_array
    from acoustisim.propagation import solve
    from acoustisim.propagation.paths import PathKind, Paths
    from acoustisim.simulation import simulate
    from binsonar.detection import detect

    scene, sonar, _, truth, gate = position_setup(range_m, 2.0)
    paths = solve(scene, sonar, solver_config({"reverberation": False}))
    edge = paths.rows[(paths.rows["kind"] == PathKind.EDGE) & (paths.rows["order"] == 1)].copy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = simulate(scene, sonar, paths=Paths(edge, paths.surface_names), n_pings=1)
    record = gate_recording(replace(sim.recording, waveforms=np.asarray(sim.clean)[np.newaxis]), *gate)
    matched = detect(record, "matched")
    plain = np.array([e.tof_s for e in matched.first(0)]) - truth
    _, transducers = recording_array(record)  # the simulated head's pistons, from the recording
    assert transducers.diameters_m == (sonar.transducer_diameter_m,) * 3
    refined = beam_matched_echoes(record, matched.first(0), transducers, float(scene.medium.sound_speed))
    error = np.array([e.tof_s for e in refined]) - truth
    assert np.all(plain < -5e-9)
    assert np.max(np.abs(error)) < 1e-9


def test_measure_position_reports_bias_parts_and_the_true_noise_bound() -> None:
    out = measure_position(Trial(0, 5, (("range_m", 1.0), ("bearing_deg", 2.0), ("n_pings", 10), ("repeats", 2),
                                        ("detectors", ("threshold", "matched", "beam-matched")))))
    parts = out["noise_free"]
    assert list(parts) == ["edge", "specular", "all"]
    assert "threshold" not in parts["all"]  # its threshold needs noise
    for part in parts.values():
        assert abs(part["matched"]["range_error_m"]) < 20e-6  # beam bias ~ -7 um at 1 m
    # The beam-aware refinement removes the beam's part: the edge alone to 1 um of range (measured
    # 0.1 um; the plain filter's -6.8 um); the reverberation's part stays (a few um, frozen).
    assert abs(parts["edge"]["beam-matched"]["range_error_m"]) < 1e-6
    assert abs(parts["edge"]["matched"]["range_error_m"]) > 3e-6
    beam = out["detectors"]["beam-matched"]
    assert all(math.isfinite(v) for v in beam["range_error_m"])
    # Its time includes the matched filter's pass it starts from.
    assert np.all(np.array(beam["cpu_s"]) >= np.array(out["detectors"]["matched"]["cpu_s"]))
    # The detector's noise floor (median over the gate) includes the frozen reverberation, so its
    # bound is not below the bound at the true noise-only SNR (10 % slack: its SNR estimate scatters
    # by ~0.3 dB over a 5000-sample median).
    detector = np.nanmean(out["detectors"]["matched"]["bound_range_m"])
    assert 0 < out["noise_bound_range_m"] < 1.1 * detector
    assert out["noise_bound_bearing_deg"] > 0 and len(out["noise_snr_db"]) == 3
    # Counting the reverberation as interference can only raise the bound (1 % for the Welch estimate).
    assert out["reverb_bound_range_m"] >= 0.99 * out["noise_bound_range_m"]


def test_calibrated_threshold_error_grows_with_range() -> None:
    # The seed's threshold detector: a preset level and an offset calibrated at 1 m. At 2.2 m the
    # edge's echo is ~6 dB weaker (r^-3/2 each way), so it reaches the level later in its rise:
    # the range error grows by a few tenths of a millimetre (measured +0.4 mm at 2 m and +0.7 mm at
    # 2.5 m with 50 pings), while its noise jitter is ~0.01 mm.
    from acoustisim.experiments.position_measurement import calibrate_threshold

    cal = calibrate_threshold(1.0, 2.0, n_pings=10, seed=2)
    assert cal["amplitude_v"] > 5 * cal["level_v"] > 0
    errors = {}
    for range_m in (1.0, 2.2):
        out = measure_position(Trial(0, 9, (("range_m", range_m), ("bearing_deg", 2.0), ("n_pings", 10),
                                            ("repeats", 1), ("detectors", ("threshold",)),
                                            ("threshold_level_v", cal["level_v"]),
                                            ("threshold_amplitude_v", cal["amplitude_v"]))))
        errors[range_m] = out["detectors"]["threshold"]["range_error_m"][0]
    assert abs(errors[1.0]) < 0.2e-3  # the edge's echo is not the template's shape: a residual of ~0.1 mm
    assert 0.2e-3 < errors[2.2] - errors[1.0] < 2e-3


def test_chi2_exceedance_matches_the_two_degree_closed_form() -> None:
    # chi2 with 2 degrees of freedom has survival exp(-x / 2): P(RMS of 2 samples > 1.5 sigma) = exp(-2.25).
    from acoustisim.experiments.sweep import chi2_exceedance

    assert chi2_exceedance(2, 2.25) == pytest.approx(math.exp(-2.25), rel=1e-12)
    assert chi2_exceedance(8, 2.25) < chi2_exceedance(4, 2.25) < chi2_exceedance(2, 2.25)


def test_recording_truth_scene_loads_back_with_the_machined_prism(tmp_path) -> None:
    # The paths and the recording's truth come from one scene: the truth's scene file, read back,
    # names the machined prism (a library material) and gives the same paths again, including the
    # prism's diffuse paths, whose gains scale with its Lambert strength (the rough library
    # "steel" gives different gains: the comparison can fail).
    import tomllib

    import h5py

    from acoustisim.experiments.edge_scene import position_setup
    from acoustisim.materials import get_material
    from acoustisim.propagation import solve
    from acoustisim.propagation.paths import PathKind
    from acoustisim.simulation import simulate, write_simulation
    from scenes.scene_file import scene_from_toml

    scene, sonar, _, _, _ = position_setup(1.0, 2.0)
    config = solver_config({})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # arrivals past the short record are left out on purpose
        sim = simulate(scene, sonar, solver_config=config, n_pings=1)
    path = write_simulation(tmp_path / "edge.h5", sim)
    with h5py.File(path, "r") as h5:
        text = h5["truth"].attrs["scene_toml"]
    loaded = scene_from_toml(tomllib.loads(text if isinstance(text, str) else text.decode()))
    assert loaded.objects[0].material == get_material("steel-machined") == scene.objects[0].material
    rows = sim.paths.rows
    prism_id = sim.paths.surface_names.index(scene.objects[0].name)
    on_prism = (rows["kind"] == PathKind.DIFFUSE) & (rows["object_ids"][:, 0] == prism_id)
    assert on_prism.sum() > 100
    again = solve(loaded, sonar, config).rows
    assert again.shape == rows.shape
    for field in ("kind", "delay_s", "geometric_gain"):
        np.testing.assert_array_equal(again[field], rows[field])  # deterministic tracer: bit for bit
    rough = solve(edge_tank_scene("steel"), sonar, config).rows
    assert rough.shape == rows.shape
    # Diffuse gains scale as sqrt(mu): 0.002 / 1.93e-5 is 20 dB in mu, 10x in gain (to rounding).
    ratio = np.abs(rough["geometric_gain"][on_prism] / rows["geometric_gain"][on_prism])
    np.testing.assert_allclose(ratio, np.sqrt(get_material("steel").diffuse_mu / prism_material().diffuse_mu),
                               rtol=1e-9)


def test_default_angle_sweep_range_has_no_specular_path_in_the_gate() -> None:
    """The angle sweep's default range was chosen so that no wall, floor or surface echo of order
    <= 4 shares the edge's gate at any bearing: if the tank, the head's depth, the gate or the
    default range change, this fails."""
    from acoustisim.experiments.angle_sweep import DEFAULT_RANGE_M
    from acoustisim.experiments.edge_scene import SWEEP_MAX_ORDER, position_setup
    from acoustisim.propagation import solve
    from acoustisim.propagation.paths import PathKind

    for bearing in (-12.0, -6.0, 0.0, 6.0, 12.0):
        scene, sonar, _, _, gate = position_setup(DEFAULT_RANGE_M, bearing)
        rows = solve(scene, sonar, solver_config({"reverberation": False})).rows
        specular = rows[(rows["kind"] == PathKind.SPECULAR) & (rows["delay_s"] >= gate[0])
                        & (rows["delay_s"] <= gate[1])]
        assert specular.size == 0, (bearing, specular["delay_s"])
    # ...while at 2.0 m the order-4 floor-surface multiple is in it at 0 deg.
    scene, sonar, _, _, gate = position_setup(2.0, 0.0)
    rows = solve(scene, sonar, solver_config({"reverberation": False})).rows
    inside = rows[(rows["kind"] == PathKind.SPECULAR) & (rows["delay_s"] >= gate[0]) & (rows["delay_s"] <= gate[1])]
    assert SWEEP_MAX_ORDER in set(int(v) for v in inside["order"])


def test_fresh_reverberation_draws_a_new_diffuse_field_per_measurement() -> None:
    params = (("range_m", 1.25), ("bearing_deg", 2.0), ("n_pings", 2), ("repeats", 3), ("detectors", ("matched",)))
    fresh = measure_position(Trial(0, 11, (*params, ("fresh_reverberation", True))))
    frozen = measure_position(Trial(0, 11, params))
    assert fresh["fresh_reverberation"] and not frozen["fresh_reverberation"]
    assert len(set(fresh["diffuse_seeds"])) == 3 and frozen["diffuse_seeds"] == [0]
    assert fresh["reverb_realisations"] == 3 and frozen["reverb_realisations"] == 1
    biases = [b["matched"]["range_error_m"] for b in fresh["noise_free_all_by_repeat"]]
    assert len(biases) == 3 and len(set(biases)) == 3  # each realisation biases the TOF differently
    # The first repeat of the fresh run is its own realisation (not seed 0's), while the edge alone
    # is the same in both runs: only the diffuse part changes.
    assert fresh["noise_free"]["edge"]["matched"] == frozen["noise_free"]["edge"]["matched"]
    assert fresh["noise_free"]["all"]["matched"] != frozen["noise_free"]["all"]["matched"]
    assert fresh["reverb_bound_range_m"] >= fresh["noise_bound_range_m"]
    from acoustisim.experiments.sweep_summary import summarise

    row = summarise([fresh], ("matched",))["positions"][0]["matched"]
    assert row["bias_range_m"] == pytest.approx(float(np.sqrt(np.mean(np.square(biases)))))
    errors = np.asarray(fresh["detectors"]["matched"]["range_error_m"])
    assert row["scatter_range_rms_m"] == pytest.approx(float(np.sqrt(np.mean((errors - biases) ** 2))))
