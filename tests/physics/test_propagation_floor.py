"""The amplitude floor judges each arrival by its strongest level across the pulse band."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.special import jn_zeros

from acoustisim.medium import Medium
from acoustisim.propagation import PathKind, SolverConfig, prepare, solve
from acoustisim.propagation.directivity import piston_directivity
from acoustisim.propagation.reference.floor import floor_frequencies, pulse_band_hz
from acoustisim.propagation.context import SolveContext
from acoustisim.scene import Scene
from acoustisim.sonar import SonarHead
from scenes.builders import sphere
from scenes.builtin import builtin_scene

RANGE_M = 2.0
RADIUS_M = 0.02


def _null_scene() -> tuple[Scene, float]:
    """Free field, sonar at the origin; sphere "axis" on the boresight and sphere "null" at the
    pistons' first null at f0 (x = k a sin(theta) = 3.8317, 10.97 deg for 19 mm at 500 kHz),
    both RANGE_M from the transmitter to their centres."""
    sonar = SonarHead(position_m=(0.0, 0.0, 0.0))
    c = Medium().sound_speed
    ka = 2.0 * np.pi * sonar.centre_frequency_hz / c * sonar.piston_radius_m
    theta = float(np.arcsin(jn_zeros(1, 1)[0] / ka))
    axis = sonar.boresight
    side = np.cross(axis, (0.0, 0.0, 1.0))
    side /= np.linalg.norm(side)
    tx = sonar.transmitter_position
    on_axis = sphere("axis", tx + RANGE_M * axis, RADIUS_M)
    at_null = sphere("null", tx + RANGE_M * (np.cos(theta) * axis + np.sin(theta) * side), RADIUS_M)
    return Scene("null", Medium(), sonar, None, (on_axis, at_null)), theta


@pytest.fixture(scope="module")
def null_scene():
    scene, theta = _null_scene()
    return prepare(scene), theta


def _centre_echo(paths, name: str):
    labels = np.array(paths.object_labels(), dtype=object)
    rows = paths.rows[(labels == name) & (paths["channel"] == 1)]
    return rows


def _config(floor_db, backend):
    return SolverConfig(max_order=1, mechanisms=("direct", "specular"), amplitude_floor_db=floor_db, backend=backend)


def test_pulse_band_is_the_gaussian_minus_20_db_band():
    # |Q(f)| ~ exp(-(pi (f - f0))^2 T^2 / 13.8): -20 dB at f0 +/- sqrt(13.8 ln 10) / (pi T)
    # (the negative-frequency image adds < 1e-30); the grid step is f0/1000 = 500 Hz
    sonar = SonarHead()
    half = np.sqrt(13.8 * np.log(10.0)) / (np.pi * sonar.pulse_duration_s)
    low, high = pulse_band_hz(sonar)
    assert low == pytest.approx(sonar.centre_frequency_hz - half, abs=500.0)
    assert high == pytest.approx(sonar.centre_frequency_hz + half, abs=500.0)


def test_echo_at_the_first_null_is_kept_across_the_band(null_scene, backend):
    prepared, theta = null_scene
    paths = solve(prepared, config=_config(-80.0, backend))
    axis, null = _centre_echo(paths, "axis"), _centre_echo(paths, "null")
    assert axis.size == 1 and null.size == 1
    assert null["angle_tx_rad"][0] == pytest.approx(theta, abs=1e-6)
    # a floor judged at the centre frequency alone (amplitude against -80 dB of the strongest)
    # would cull it: the f0 directivity at the null is ~0 (the echo is > 100 dB down at f0)
    assert null["amplitude"][0] < 1e-4 * axis["amplitude"][0]
    # at the band's lower frequencies it is only ~18 dB below the on-axis echo (same range):
    # max over the band frequencies of w(f) D(f)^2 A(f) / (D(f0)^2 A(f0)) of the axis echo
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    frequencies, weights = floor_frequencies(context, None)
    c, a = context.sound_speed_m_s, context.piston_radius_m
    relative = np.max(weights * piston_directivity(theta, frequencies, a, c) ** 2)
    assert 10 ** (-25 / 20) < relative < 10 ** (-12 / 20)


def test_echo_below_the_floor_at_every_band_frequency_is_culled(null_scene, backend):
    prepared, _ = null_scene
    # the null echo peaks ~18 dB down across the band (previous test): a -10 dB floor culls it,
    # keeps the on-axis echo; a -30 dB floor keeps both
    culled = solve(prepared, config=_config(-10.0, backend))
    assert _centre_echo(culled, "axis").size == 1 and _centre_echo(culled, "null").size == 0
    kept = solve(prepared, config=_config(-30.0, backend))
    assert _centre_echo(kept, "null").size == 1


def test_keep_all_keeps_every_row(null_scene, backend):
    prepared, _ = null_scene
    everything = solve(prepared, config=_config(None, backend))
    culled = solve(prepared, config=_config(-10.0, backend))
    assert _centre_echo(everything, "null").size == 1
    assert len(culled) < len(everything)


def _brute_force_levels(paths, context, frequencies, weights):
    """{(path_id, channel): band level}, summing each group's rows one frequency at a time."""
    c, a = context.sound_speed_m_s, context.piston_radius_m
    alpha = context.scene.medium.absorption_db_per_m(frequencies)
    rows = paths.rows
    keys = rows["path_id"].astype(np.int64) * 8 + rows["channel"]
    levels = {}
    for key in np.unique(keys):
        group = rows[keys == key]
        best = 0.0
        for f, w, al in zip(frequencies, weights, alpha):
            terms = (group["geometric_gain"] * piston_directivity(group["angle_tx_rad"], f, a, c)
                     * piston_directivity(group["angle_rx_rad"], f, a, c) * 10 ** (-al * group["path_length_m"] / 20)
                     * np.exp(1j * (group["phase_rad"] - 2 * np.pi * f * (group["delay_s"] - group["delay_s"].min()))))
            best = max(best, w * abs(terms.sum()))
        levels[(int(key) // 8, int(key) % 8)] = (best, int(group["kind"][0]))
    return levels


@pytest.mark.parametrize("floor_db", [-40.0, -80.0])
def test_floor_keeps_exactly_the_arrivals_above_it(floor_db, backend):
    """Against a per-arrival brute-force evaluation of the rule (no bounds, no shortcuts), on the
    thesis tank with specular paths, edge-element groups and diffuse rows."""
    scene = builtin_scene("thesis-tank")
    prepared = prepare(scene)
    base = SolverConfig(max_order=2, diffuse_rays=2000, amplitude_floor_db=None, backend=backend)
    everything = solve(prepared, config=base)
    culled = solve(prepared, config=replace(base, amplitude_floor_db=floor_db))
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    frequencies, weights = floor_frequencies(context, None)
    levels = _brute_force_levels(everything, context, frequencies, weights)
    strongest = max(level for level, kind in levels.values() if kind != PathKind.DIRECT)
    threshold = strongest * 10 ** (floor_db / 20)
    kept = set(zip(culled["path_id"].tolist(), culled["channel"].tolist()))
    near = 0
    for key, (level, kind) in levels.items():
        # levels within 1e-9 of the threshold may go either way with the summation order
        if abs(level - threshold) <= 1e-9 * threshold:
            near += 1
            continue
        assert (key in kept) == (kind == PathKind.DIRECT or level > threshold), (key, level, threshold)
    assert near <= 1
    assert 0 < len(culled) < len(everything)
    # whole edge groups: every kept group keeps all its elements
    for kind in (PathKind.EDGE,):
        mask = everything["kind"] == kind
        for key in set(zip(culled["path_id"][culled["kind"] == kind].tolist(),
                           culled["channel"][culled["kind"] == kind].tolist())):
            n_all = np.sum(mask & (everything["path_id"] == key[0]) & (everything["channel"] == key[1]))
            n_kept = np.sum((culled["path_id"] == key[0]) & (culled["channel"] == key[1]))
            assert n_all == n_kept
