"""One ping -> classified Target: point / cylinder / plane / unknown, statuses, covariances."""

import math

import numpy as np
import pytest

from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.circle import circle_path_lengths
from binsonar.localization.classify import chi2_threshold
from binsonar.localization.estimate import EstimationConfig, target_from_path_lengths
from binsonar.localization.plane import plane_path_lengths
from binsonar.localization.point import point_path_lengths

G65 = ArrayGeometry.seed(0.065)
SIG = np.full(3, 2e-4)  # 0.2 mm: the CRLB at 2E/N0 = 20 dB for the 118.2 kHz envelope bandwidth


def test_chi2_threshold_values():
    # Table values of the chi-square 99 % quantile.
    assert chi2_threshold(1, 0.01) == pytest.approx(6.6349, abs=1e-4)
    assert chi2_threshold(57, 0.01) == pytest.approx(84.733, abs=1e-3)


def test_point_target_classified_point_with_unobservable_radius():
    lengths, _ = point_path_lengths([0.3, 1.2, 0.0], G65)
    t = target_from_path_lengths(lengths, SIG, G65)
    assert t.cls == "point"
    assert t.status == "radius-not-observable"  # sigma_rc ~ 0.4 m from one ping
    assert t.range_m == pytest.approx(np.hypot(0.3, 1.2), rel=1e-12)
    assert t.bearing_deg == pytest.approx(np.degrees(np.arctan2(0.3, 1.2)), rel=1e-10)
    assert t.radius_std_m > 0.1
    np.testing.assert_allclose(t.position_head_m, [0.3, 1.2, 0.0], atol=1e-12)
    assert t.range_std_m > 0 and t.bearing_std_deg > 0


def test_wall_classified_plane():
    lengths, _ = plane_path_lengths(np.radians(10.0), 1.5, np.zeros((3, 3)), G65.receivers_m)
    t = target_from_path_lengths(lengths, SIG, G65)
    assert t.cls == "plane" and t.status == "ok"
    assert math.isinf(t.radius_m)
    assert t.range_m == pytest.approx(1.5, abs=1e-9) and t.bearing_deg == pytest.approx(10.0, abs=1e-7)


def test_large_cylinder_classified_cylinder_with_radius():
    # rc = 0.5 m at 1 m with d = 15 cm (Peremans' sensor) and sigma = 2 um: sigma_rc ~ few mm.
    g = ArrayGeometry.seed(0.15)
    lengths, _ = circle_path_lengths((0.2, 1.5), 0.5, np.zeros((3, 3)), g.receivers_m)
    t = target_from_path_lengths(lengths, np.full(3, 2e-6), g)
    assert t.cls == "cylinder" and t.status == "ok"
    assert t.radius_m == pytest.approx(0.5, abs=1e-9)
    assert t.radius_std_m < 0.05
    np.testing.assert_allclose(t.position_head_m[:2], [0.2, 1.5], atol=1e-9)
    assert t.range_m == pytest.approx(np.hypot(0.2, 1.5) - 0.5, abs=1e-9)


def test_classification_rates_follow_the_significance():
    # A true point with noise: the point model is rejected about alpha of the time (chi-square 1 dof).
    rng = np.random.default_rng(5)
    lengths, _ = point_path_lengths([-0.2, 0.9, 0.0], G65)
    cfg = EstimationConfig(alpha=0.05)
    classes = [target_from_path_lengths(lengths + SIG * rng.standard_normal(3), SIG, G65, config=cfg).cls
               for _ in range(200)]
    rejected = sum(c != "point" for c in classes) / 200
    # Binomial(200, 0.05): std 1.5 %; [0.5 %, 11 %] is a generous band that still fails if the noise
    # model were off by sqrt(2) (rate would be ~ 17 %).
    assert 0.005 <= rejected <= 0.11


@pytest.mark.parametrize(
    "lengths, status",
    [
        ([1.0, 1.0, 1.5], "invalid-path-lengths"),        # |R1 - R2| > 2 d
        ([0.05, 0.1, 0.06], "invalid-path-lengths"),      # shorter than the baseline allows
        ([np.nan, 1.0, 1.0], "invalid-path-lengths"),     # missing side channel
        ([1.0, np.inf, 1.0], "invalid-path-lengths"),
        ([2.0, 2.0, 2.0], "no-model-fits"),               # centre as long as the sides: nothing fits
    ],
)
def test_bad_inputs_give_status(lengths, status):
    t = target_from_path_lengths(lengths, SIG, G65)
    assert t.status == status and t.message
    if status == "invalid-path-lengths":
        assert t.cls == "unknown" and np.all(np.isnan(t.position_head_m))


def test_missing_centre_gives_point_estimate_and_unknown_class():
    lengths, _ = point_path_lengths([0.1, 2.0, 0.0], G65)
    lengths[1] = np.nan
    t = target_from_path_lengths(lengths, SIG, G65)
    assert t.cls == "unknown" and t.status == "no-centre-echo"
    assert t.range_m == pytest.approx(np.hypot(0.1, 2.0), rel=1e-12)


def test_nan_std_is_a_status():
    t = target_from_path_lengths([1.0, 1.0, 1.0], [np.nan, 1e-4, 1e-4], G65)
    assert t.status == "invalid-path-lengths"


def test_tank_position_from_pose():
    lengths, _ = point_path_lengths([0.0, 1.0, 0.0], G65)
    t = target_from_path_lengths(lengths, SIG, G65).with_pose([2.0, 1.5, 0.5, 90.0, 0.0, 0.0])
    # Yaw 90 deg: the boresight points along tank +y; a target 1 m ahead is at (2, 2.5, 0.5).
    np.testing.assert_allclose(t.position_tank_m, [2.0, 2.5, 0.5], atol=1e-12)
    # The range variance (head y) becomes tank y variance.
    assert t.covariance_tank[1, 1] == pytest.approx(t.covariance[1, 1], rel=1e-12)
    d = t.to_dict()
    assert d["class"] == "point" and d["position_tank_m"][1] == pytest.approx(2.5)
