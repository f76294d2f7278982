"""Several pings from known poses: batch least squares makes a small post's radius observable."""

import numpy as np
import pytest

from binsonar.bounds import tof_crlb_s
from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.circle import circle_path_lengths
from binsonar.localization.estimate import target_from_path_lengths
from binsonar.localization.frames import head_to_tank
from binsonar.localization.fusion import PoseObservation, fuse, group_across_pings, observations_of

G = ArrayGeometry.seed(0.065)
C_WATER = 1482.0
# TOF noise from the CRLB at 2E/N0 = 20 dB with the Gaussian pulse's envelope RMS bandwidth 118.2 kHz
# (physics.md section 6): 135 ns, i.e. 0.20 mm of path.
SIGMA_L = C_WATER * float(tof_crlb_s(10 ** (20 / 10), 118.2e3))
POST_XY, POST_R = np.array([4.5, 2.5]), 0.025
POSES = [np.array([x, 1.5, 0.5, 90.0, 0.0, 0.0]) for x in np.linspace(4.0, 5.0, 20)]  # 1 m track, post 1 m away


def _clean_paths(centre=POST_XY, rc=POST_R):
    out = []
    for pose in POSES:
        t = head_to_tank(G.transmitter_m, pose)
        r = head_to_tank(G.receivers_m, pose)
        out.append(circle_path_lengths(centre, rc, np.broadcast_to(t, (3, 3)), r)[0])
    return out


def _trials(n, seed):
    rng = np.random.default_rng(seed)
    clean = _clean_paths()
    radii, stds, results = [], [], []
    for _ in range(n):
        obs = [PoseObservation(p, L + SIGMA_L * rng.standard_normal(3), np.full(3, SIGMA_L), k)
               for k, (p, L) in enumerate(zip(POSES, clean))]
        f = fuse(obs, G)
        radii.append(f.radius_m)
        stds.append(f.radius_std_m)
        results.append(f)
    return np.array(radii), np.array(stds), results


def test_sigma_is_the_crlb_figure():
    assert SIGMA_L == pytest.approx(2.0e-4, rel=0.01)


def test_noise_free_fusion_is_exact():
    obs = [PoseObservation(p, L, np.full(3, SIGMA_L), k) for k, (p, L) in enumerate(zip(POSES, _clean_paths()))]
    f = fuse(obs, G)
    assert f.cls == "cylinder" and f.status == "ok"
    np.testing.assert_allclose(f.position_tank_m[:2], POST_XY, atol=1e-9)
    assert f.radius_m == pytest.approx(POST_R, abs=1e-9)


def test_single_ping_radius_not_observable_but_fused_radius_is():
    L = _clean_paths()[10]
    # In the head frame of the middle pose the post is straight ahead at about 1 m.
    single = target_from_path_lengths(L, np.full(3, SIGMA_L), G)
    assert single.radius_std_m > 0.1 and single.status == "radius-not-observable"
    radii, stds, results = _trials(1, 0)
    assert stds[0] < 0.002


def test_post_radius_within_5_mm_and_std_agrees_with_scatter():
    # 40 trials: every radius within 5 mm; the scatter's std has relative sampling error
    # 1 / sqrt(2 x 39) = 11 %, so a 30 % band (2.7 sigma). The slow test repeats with 300 trials at 10 %.
    radii, stds, results = _trials(40, 1)
    assert np.all(np.abs(radii - POST_R) < 0.005)
    assert np.std(radii, ddof=1) == pytest.approx(np.mean(stds), rel=0.30)
    assert all(r.cls == "cylinder" for r in results)
    assert abs(np.mean(radii) - POST_R) < 3 * np.mean(stds) / np.sqrt(40)  # unbiased within 3 sigma


@pytest.mark.slow
def test_post_radius_std_agrees_with_scatter_slow():
    # 300 trials: relative sampling error of the std 4.1 %; the 10 % is 2.4 sigma
    # (measured ratio 1.04 with this seed).
    radii, stds, results = _trials(300, 2)
    assert np.all(np.abs(radii - POST_R) < 0.005)
    assert np.std(radii, ddof=1) == pytest.approx(np.mean(stds), rel=0.10)
    # The circle's chi2 over 60 paths and 3 parameters follows chi-square(57): mean 57, and the
    # mean of 300 has std sqrt(2 x 57 / 300) = 0.6; 3 % (1.7) is ~3 sigma.
    assert np.mean([r.fit("circle").chi2 for r in results]) == pytest.approx(57.0, rel=0.03)


def test_grouping_across_pings_separates_two_posts():
    rng = np.random.default_rng(4)
    other = np.array([4.2, 2.2])
    targets = []
    for k, pose in enumerate(POSES):
        t = head_to_tank(G.transmitter_m, pose)
        r = head_to_tank(G.receivers_m, pose)
        for centre in (POST_XY, other):
            L = circle_path_lengths(centre, POST_R, np.broadcast_to(t, (3, 3)), r)[0]
            L = L + SIGMA_L * rng.standard_normal(3)
            targets.append(target_from_path_lengths(L, np.full(3, SIGMA_L), G, ping=k).with_pose(pose))
    groups = group_across_pings(targets, gate_m=0.15)
    assert sorted(len(g) for g in groups) == [20, 20]
    fused = sorted((fuse(observations_of(g), G) for g in groups), key=lambda f: f.position_tank_m[1])
    np.testing.assert_allclose(fused[0].position_tank_m[:2], other, atol=0.003)
    np.testing.assert_allclose(fused[1].position_tank_m[:2], POST_XY, atol=0.003)


def test_bad_observation_shape_raises_value_error():
    with pytest.raises(ValueError, match="lengths_m"):
        PoseObservation(np.zeros(6), np.zeros(2), np.zeros(3))


def test_too_few_paths_is_a_status():
    f = fuse([PoseObservation(POSES[0], [np.nan, np.nan, 1.0], [1e-4] * 3)], G)
    assert f.cls == "unknown" and f.status in ("fit-failed", "no-model-fits")
