"""Head and tank frames: the head pose as a rotation and a translation.

Conventions (``conventions.md``): the head frame has x toward the right receiver, y along the
boresight, z up; the tank frame has z up. The pose is (x_m, y_m, z_m, yaw_deg, pitch_deg,
roll_deg): yaw about +z from the tank +x axis to the boresight (counter-clockwise seen from
above), pitch about the head x axis (nose up positive), roll about the boresight (right side
down positive).

Derivation of the yaw-0 mapping R0: at yaw = pitch = roll = 0 the boresight (head +y) points
along tank +x and up stays up, so the head's right-hand axis is boresight x up = (1, 0, 0) x
(0, 0, 1) = (0, -1, 0). The columns of R0 are the images of the head axes::

    R0 = [[0, 1, 0],        head x -> tank (0, -1, 0)
          [-1, 0, 0],       head y -> tank (1, 0, 0)
          [0, 0, 1]]        head z -> tank (0, 0, 1)

i.e. a head vector (x, y, z) has tank components (y, -x, z). The full head-to-tank rotation is
R = Rz(yaw) R0 Rx(pitch) Ry(roll) (pitch and roll act in the head frame first).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

R0_HEAD_TO_TANK: NDArray[np.float64] = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
R0_HEAD_TO_TANK.setflags(write=False)


def _check_pose(pose: ArrayLike) -> NDArray[np.float64]:
    p = np.asarray(pose, dtype=float)
    if p.shape != (6,) or not np.all(np.isfinite(p)):
        raise ValueError(f"pose must be 6 finite numbers (x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg), got {pose!r}")
    return p


def head_to_tank_rotation(yaw_deg: float, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> NDArray[np.float64]:
    """Rotation matrix (3, 3) taking head-frame vectors to the tank frame.

    Parameters
    ----------
    yaw_deg, pitch_deg, roll_deg : float
        Head orientation (degrees), conventions in the module docstring.
    """
    y, p, r = (math.radians(v) for v in (yaw_deg, pitch_deg, roll_deg))
    rz = np.array([[math.cos(y), -math.sin(y), 0.0], [math.sin(y), math.cos(y), 0.0], [0.0, 0.0, 1.0]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(p), -math.sin(p)], [0.0, math.sin(p), math.cos(p)]])
    ry = np.array([[math.cos(r), 0.0, math.sin(r)], [0.0, 1.0, 0.0], [-math.sin(r), 0.0, math.cos(r)]])
    return rz @ R0_HEAD_TO_TANK @ rx @ ry


def pose_rotation(pose: ArrayLike) -> NDArray[np.float64]:
    """Head-to-tank rotation (3, 3) of a pose (6,) = (x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg)."""
    p = _check_pose(pose)
    return head_to_tank_rotation(p[3], p[4], p[5])


def head_to_tank(points_head: ArrayLike, pose: ArrayLike) -> NDArray[np.float64]:
    """Head-frame points (..., 3) (m) to tank-frame points (..., 3) (m)."""
    p = _check_pose(pose)
    return np.asarray(points_head, dtype=float) @ pose_rotation(p).T + p[:3]


def tank_to_head(points_tank: ArrayLike, pose: ArrayLike) -> NDArray[np.float64]:
    """Tank-frame points (..., 3) (m) to head-frame points (..., 3) (m)."""
    p = _check_pose(pose)
    return (np.asarray(points_tank, dtype=float) - p[:3]) @ pose_rotation(p)


def covariance_to_tank(covariance_head: ArrayLike, pose: ArrayLike) -> NDArray[np.float64]:
    """A position covariance (3, 3) (m^2) from the head frame to the tank frame: R C R^T."""
    rot = pose_rotation(pose)
    return rot @ np.asarray(covariance_head, dtype=float) @ rot.T
