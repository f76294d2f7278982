"""Head <-> tank frames, re-derived in binsonar (no simulator import)."""

import numpy as np
import pytest

from binsonar.localization.frames import head_to_tank, head_to_tank_rotation, tank_to_head


def test_yaw_zero_boresight_along_tank_x_and_right_receiver_toward_minus_y():
    rot = head_to_tank_rotation(0.0)
    np.testing.assert_allclose(rot @ [0, 1, 0], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(rot @ [1, 0, 0], [0, -1, 0], atol=1e-15)  # right of +x with z up
    np.testing.assert_allclose(rot @ [0, 0, 1], [0, 0, 1], atol=1e-15)


def test_yaw_pitch_roll_directions():
    # Yaw 90 deg (counter-clockwise from above): boresight along tank +y.
    np.testing.assert_allclose(head_to_tank_rotation(90.0) @ [0, 1, 0], [0, 1, 0], atol=1e-15)
    # Pitch +30 deg: nose up.
    b = head_to_tank_rotation(0.0, 30.0) @ [0, 1, 0]
    np.testing.assert_allclose(b, [np.cos(np.radians(30)), 0, np.sin(np.radians(30))], atol=1e-15)
    # Roll +20 deg: right side down.
    right = head_to_tank_rotation(0.0, 0.0, 20.0) @ [1, 0, 0]
    assert right[2] == pytest.approx(-np.sin(np.radians(20)))


def test_rotation_is_proper_and_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        pose = np.concatenate([rng.uniform(0, 5, 3), rng.uniform(-180, 180, 3)])
        rot = head_to_tank_rotation(*pose[3:])
        np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-14)
        pts = rng.normal(size=(5, 3))
        np.testing.assert_allclose(tank_to_head(head_to_tank(pts, pose), pose), pts, atol=1e-13)


def test_bad_pose_rejected():
    with pytest.raises(ValueError, match="pose"):
        head_to_tank([0, 1, 0], [0, 0, 0, np.nan, 0, 0])


def test_as_poses_broadcasts_one_pose_and_names_bad_ones():
    # The one pose validation shared by Recording and localize.
    from binsonar.recording import RecordingError, as_poses

    one = [1.0, 2.0, 0.5, 90.0, 0.0, 0.0]
    poses = as_poses(one, 3, "here")
    assert poses.shape == (3, 6) and np.all(poses == np.array(one))
    poses[0, 0] = 7.0  # a new array: writable, the rows independent
    assert poses[1, 0] == 1.0
    per_ping = np.arange(12.0).reshape(2, 6)
    assert np.array_equal(as_poses(per_ping, 2, "here"), per_ping)
    for bad in ([0, 0, 0], np.zeros((3, 6)), [0, 0, 0, np.nan, 0, 0], "north"):
        with pytest.raises(RecordingError, match="here: pose must be"):
            as_poses(bad, 2, "here")
