"""The sonar head: frames, pose and the default thesis sonar."""

import math

import numpy as np
import pytest

from acoustisim.sonar import SonarHead
from scenes.builders import default_sonar


def test_default_sonar_is_the_thesis_head():
    sonar = default_sonar()
    assert sonar.position_m == (1.0, 1.5, 0.5)
    assert sonar.separation_m == 0.065
    assert sonar.piston_radius_m == pytest.approx(0.0095)
    assert sonar.centre_frequency_hz == 500e3
    assert sonar.pulse_duration_s == 5e-6
    assert sonar.sample_rate_hz == 20e6
    assert sonar.adc_bits == 12
    assert sonar.n_samples == 250_000  # 12.5 ms at 20 MS/s
    assert [t.role for t in sonar.transducers] == ["receive", "transmit-receive", "receive"]


def test_yaw_zero_looks_down_the_tank_and_right_is_minus_y():
    sonar = default_sonar()
    np.testing.assert_allclose(sonar.boresight, [1.0, 0.0, 0.0], atol=1e-15)
    rx = sonar.receiver_positions
    np.testing.assert_allclose(rx[1], sonar.position_m)
    np.testing.assert_allclose(rx[0] - rx[1], [0.0, 0.065, 0.0], atol=1e-15)  # left is +y
    np.testing.assert_allclose(rx[2] - rx[1], [0.0, -0.065, 0.0], atol=1e-15)  # right is -y
    np.testing.assert_allclose(sonar.transmitter_position, sonar.position_m)


def test_rotation_is_proper_and_frames_invert():
    sonar = SonarHead(position_m=(2.0, 1.0, 0.4), yaw_deg=37.0, pitch_deg=-8.0, roll_deg=15.0)
    r = sonar.rotation
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-14)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-14)
    points = np.array([[0.1, 0.2, 0.3], [-1.0, 2.0, 0.5]])
    np.testing.assert_allclose(sonar.tank_to_head(sonar.head_to_tank(points)), points, atol=1e-14)


def test_yaw_is_counter_clockwise_from_x():
    sonar = default_sonar().with_pose((1.0, 1.0, 0.5), yaw_deg=90.0)
    np.testing.assert_allclose(sonar.boresight, [0.0, 1.0, 0.0], atol=1e-15)


def test_pitch_up_raises_boresight_and_roll_lowers_right_side():
    pitched = default_sonar().with_pose((1.0, 1.5, 0.5), pitch_deg=10.0)
    assert pitched.boresight[2] == pytest.approx(math.sin(math.radians(10.0)))
    rolled = default_sonar().with_pose((1.0, 1.5, 0.5), roll_deg=10.0)
    assert rolled.receiver_positions[2, 2] < 0.5 < rolled.receiver_positions[0, 2]


def test_bearing_positive_toward_right_receiver():
    sonar = default_sonar()
    target_tank = sonar.head_to_tank(np.array([[0.0, 2.0, 0.0]]))[0] + np.array([0.0, -0.2, 0.0])
    x, y, _ = sonar.tank_to_head(target_tank[None])[0]
    bearing = math.degrees(math.atan2(x, y))
    assert bearing > 0  # a target toward tank -y (the right receiver's side) has positive bearing
    distances = np.linalg.norm(sonar.receiver_positions - target_tank, axis=1)
    assert distances[2] < distances[0]


@pytest.mark.parametrize(
    "kwargs",
    [{"separation_m": 0.0}, {"position_m": (1.0, float("nan"), 0.5)}, {"adc_bits": 40}, {"yaw_deg": float("inf")},
     {"sample_rate_hz": -1.0}, {"channel_positions_m": ((0.0, 0.0),)}],
)
def test_bad_sonar_is_rejected(kwargs):
    with pytest.raises(ValueError):
        SonarHead(**kwargs)
