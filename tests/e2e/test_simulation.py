"""simulate / write_simulation: recordings, ground truth, determinism, named echoes, bad input."""

from __future__ import annotations

import hashlib
import json

import h5py
import numpy as np
import pytest

from acoustisim.errors import InputError
from acoustisim.propagation.paths import PathKind, Paths, empty_paths_array
from acoustisim.scene import Scene
from acoustisim.simulation import echo_rows, simulate, write_simulation
from acoustisim.sonar import SonarHead
from acoustisim.synthesis import ReceiverChain
from binsonar.recording import read_recording


def hand_made_paths(scene: Scene) -> Paths:
    """A wall echo (boundary 0, strong) and a weaker target echo (first object) on each channel."""
    rows = empty_paths_array(6)
    n_boundaries = len(scene.boundaries)
    rows["channel"] = [0, 1, 2, 0, 1, 2]
    rows["path_id"] = [0, 0, 0, 1, 1, 1]
    rows["kind"] = PathKind.SPECULAR
    rows["order"] = 1
    rows["delay_s"] = [1.35e-3] * 3 + [2.7e-3 + 1e-9 * np.arange(3)][0].tolist()
    rows["geometric_gain"] = [0.36] * 3 + [0.004] * 3
    rows["amplitude"] = rows["geometric_gain"]
    rows["path_length_m"] = [2.0] * 3 + [4.0] * 3
    rows["object_ids"][:3, 0] = 0
    rows["object_ids"][3:, 0] = n_boundaries
    return Paths(rows, scene.surface_names, 500e3, scene.medium.sound_speed)


@pytest.fixture(scope="module")
def scene():
    from scenes.builtin import builtin_scene

    base = builtin_scene("free-sphere")
    return Scene("test", base.medium, SonarHead(record_length_s=4e-3), None, base.objects)


@pytest.fixture(scope="module")
def tank_scene(scene):
    from acoustisim.scene import Tank

    return Scene("tank", scene.medium, scene.sonar, Tank(), scene.objects)


def digest(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def test_recording_round_trip_and_truth(tmp_path, tank_scene):
    paths = hand_made_paths(tank_scene)
    sim = simulate(tank_scene, paths=paths, seed=4, n_pings=3)
    out = write_simulation(tmp_path / "ping.h5", sim)
    recording = read_recording(out)
    assert recording.waveforms.shape == (3, 3, tank_scene.sonar.n_samples)
    assert np.array_equal(recording.waveforms, sim.recording.waveforms)  # int16 codes x volts_per_code
    assert recording.volts_per_code == pytest.approx(2.0 / 4096)
    assert recording.template is not None and recording.template.kind == "transmitted-pulse"
    assert recording.sound_speed_m_s == pytest.approx(tank_scene.medium.sound_speed)
    assert recording.pose.shape == (3, 6) and recording.pose[0, :3].tolist() == list(tank_scene.sonar.position_m)
    with h5py.File(out) as h5:
        assert h5["waveforms"].dtype == np.int16
        arrivals = h5["truth/arrivals"][()]
        names = [n.decode() for n in h5["truth/surface_names"][()]]
        objects = json.loads(h5["truth"].attrs["objects"])
        assert "scene_toml" in h5["truth"].attrs
    assert arrivals.size == 6 and np.allclose(np.sort(arrivals["delay_s"]), np.sort(paths.rows["delay_s"]))
    assert names == list(tank_scene.surface_names)
    assert objects[0]["name"] == tank_scene.objects[0].name and objects[0]["class"] == "cylinder"
    assert objects[0]["radius_m"] > 0


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path, tank_scene):
    paths = hand_made_paths(tank_scene)
    files = []
    for name, seed in (("a", 11), ("b", 11), ("c", 12)):
        files.append(write_simulation(tmp_path / f"{name}.h5", simulate(tank_scene, paths=paths, seed=seed)))
    assert digest(files[0]) == digest(files[1])
    assert digest(files[0]) != digest(files[2])


def test_default_snr_echo_is_the_strongest_target_not_the_wall(tank_scene):
    paths = hand_made_paths(tank_scene)
    rows = echo_rows(paths, None, len(tank_scene.boundaries))
    assert all(r["path_id"].tolist() == [1] for r in rows)
    assert echo_rows(paths, "wall-x0", len(tank_scene.boundaries))[1]["path_id"].tolist() == [0]
    with pytest.raises(InputError, match="no surface"):
        echo_rows(paths, "no-such-thing", len(tank_scene.boundaries))
    with pytest.raises(InputError, match="does not exist on channel"):
        echo_rows(paths, "floor", len(tank_scene.boundaries))


def test_snr_db_through_simulate(tank_scene):
    paths = hand_made_paths(tank_scene)
    # 68 dB attenuation keeps the strong wall echo (0.45 V) inside the ADC's range: no clipping.
    chain = ReceiverChain(main_bang_peak_v=0.0, attenuation_db=(68.0, 68.0, 68.0))
    sim = simulate(tank_scene, paths=paths, chain=chain, seed=1, n_pings=8, snr_db=15.0)
    assert not sim.recording.clipped.any()
    target = simulate(tank_scene, paths=paths.select(paths.rows["path_id"] == 1), chain=chain).clean
    noise = sim.recording.waveforms - sim.clean
    measured = 10 * np.log10(np.sum(target**2, axis=1) / np.mean(noise**2, axis=(0, 2)))
    assert np.all(np.abs(measured - 15.0) < 0.3)  # see test_synthesis_noise for the budget
    with pytest.raises(InputError, match="snr_echo"):
        simulate(tank_scene, paths=paths, snr_db=10.0, snr_echo="surface")


def test_average_of_pings(tank_scene):
    paths = hand_made_paths(tank_scene)
    many = simulate(tank_scene, paths=paths, seed=3, n_pings=6)
    averaged = simulate(tank_scene, paths=paths, seed=3, n_pings=6, average=True)
    assert averaged.codes is None and averaged.recording.n_pings == 1
    assert np.allclose(averaged.recording.waveforms[0], many.recording.waveforms.mean(axis=0))
    # Averaging 6 independent pings lowers the noise variance 6-fold (within sampling error).
    late = slice(int(3.5e-3 * 20e6), None)
    ratio = np.var(many.recording.waveforms[:, 1, late]) / np.var(averaged.recording.waveforms[0, 1, late])
    assert 4.5 < ratio < 7.5


def test_record_too_short_keeps_what_fits(tank_scene):
    paths = hand_made_paths(tank_scene)
    rows = paths.rows.copy()
    rows["delay_s"][3:] = 9e-3  # beyond the 4 ms record
    with pytest.warns(UserWarning, match="too short for 1 arrival"):
        sim = simulate(tank_scene, paths=Paths(rows, paths.surface_names), chain=ReceiverChain(main_bang_peak_v=0))
    assert np.abs(sim.clean[:, int(1.3e-3 * 20e6) : int(1.4e-3 * 20e6)]).max() > 0.1  # the wall echo is kept


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(n_pings=0), "n_pings"),
        (dict(seed=-1), "seed"),
        (dict(snr_db=float("inf")), "snr_db"),
    ],
)
def test_bad_parameters(tank_scene, kwargs, match):
    with pytest.raises(InputError, match=match):
        simulate(tank_scene, paths=hand_made_paths(tank_scene), **kwargs)


def test_non_finite_path_rows_are_refused(tank_scene):
    paths = hand_made_paths(tank_scene)
    rows = paths.rows.copy()
    rows["geometric_gain"][2] = np.nan
    with pytest.raises(InputError, match="geometric_gain"):
        simulate(tank_scene, paths=Paths(rows, paths.surface_names))


def test_traced_free_sphere_echo_lands_at_its_delay(scene):
    # Integration with the propagation engine: the sphere's echo on the centre channel peaks
    # (matched filter against the file's template) at the traced delay.
    from support.waveforms import matched_filter

    chain = ReceiverChain(main_bang_peak_v=0.0, thermal_noise=False, electrical_noise_v_per_rthz=0.0,
                          interference_lines=())
    sim = simulate(scene, chain=chain)
    arrivals = sim.paths.arrivals()
    echo = arrivals[(arrivals["channel"] == 1) & (arrivals["kind"] == PathKind.SPECULAR)]
    delay = float(echo["delay_s"][np.argmax(echo["amplitude"])])
    template = sim.recording.template
    window = slice(int((delay - 20e-6) * 20e6), int((delay + 20e-6) * 20e6))
    tof, _ = matched_filter(sim.clean[1, window], template.samples, 20e6, template.t0_s)
    assert abs(tof + window.start / 20e6 - delay) < 2e-9  # 2 ns: the sphere's echo is its own shape


def test_a_planned_synthesiser_is_reused_across_poses(tank_scene):
    from acoustisim.synthesis import PingSynthesiser

    paths = hand_made_paths(tank_scene)
    planned = PingSynthesiser.create(tank_scene.sonar, tank_scene.medium)
    moved = tank_scene.sonar.with_pose((2.0, 1.0, 0.4), yaw_deg=30.0)
    reused = simulate(tank_scene, moved, paths=paths, synthesiser=planned, seed=2)
    fresh = simulate(tank_scene, moved, paths=paths, seed=2)
    assert np.array_equal(reused.recording.waveforms, fresh.recording.waveforms)
    assert reused.recording.pose[0, 3] == 30.0
    other = PingSynthesiser.create(SonarHead(record_length_s=1e-3), tank_scene.medium)
    with pytest.raises(InputError, match="another sonar"):
        simulate(tank_scene, paths=paths, synthesiser=other)
