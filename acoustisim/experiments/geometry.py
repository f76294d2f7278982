"""Placing the sonar relative to a target, and the truth a localiser should return."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from acoustisim.sonar import SonarHead


def pose_for_target(
    sonar: SonarHead,
    target_m: tuple[float, float, float],
    range_m: float,
    bearing_deg: float,
    yaw_deg: float = 0.0,
) -> SonarHead:
    """The sonar moved so that ``target_m`` lies at ``range_m`` and ``bearing_deg`` in its head frame.

    The head keeps ``yaw_deg`` (no pitch or roll) and sits at the target's height, as the
    seed's motion system (x, y, yaw) did.

    Parameters
    ----------
    sonar : SonarHead
        The head to move (transducers, pulse and digitiser kept).
    target_m : tuple of 3 float
        Target point in the tank frame (m).
    range_m : float
        Horizontal distance from the transmitter to the target (m).
    bearing_deg : float
        Bearing of the target, positive toward the right receiver (deg).
    yaw_deg : float
        Yaw of the head (deg).
    """
    psi = math.radians(yaw_deg)
    theta = math.radians(bearing_deg)
    boresight = np.array([math.cos(psi), math.sin(psi), 0.0])
    right = np.array([math.sin(psi), -math.cos(psi), 0.0])
    target = np.asarray(target_m, dtype=float)
    position = target - range_m * (math.cos(theta) * boresight + math.sin(theta) * right)
    return sonar.with_pose(position, yaw_deg=yaw_deg, pitch_deg=0.0, roll_deg=0.0)


def range_bearing_of(sonar: SonarHead, point_m: NDArray[np.float64]) -> tuple[float, float]:
    """Range (m, from the transmitter) and bearing (deg) of a tank-frame point in the head frame."""
    head = sonar.tank_to_head(np.atleast_2d(point_m))[0] - sonar.channel_positions_head[1]
    return float(np.linalg.norm(head)), float(math.degrees(math.atan2(head[0], head[1])))
