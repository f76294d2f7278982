"""Columns every path row derives from its geometry: delay, angles, directivity, absorption,
amplitude.

Mechanisms fill ``path_id``, ``channel``, ``kind``, ``order``, ``path_length_m``,
``geometric_gain``, ``phase_rad``, ``departure_dir``, ``arrival_dir``, ``object_ids`` and
``points_m``; :func:`complete_columns` (called by :func:`acoustisim.propagation.solve` on every
mechanism's rows) computes the rest, so all mechanisms agree on them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.directivity import piston_directivity


def off_axis_angle(directions: NDArray[np.float64], axis: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angle (rad, in [0, pi]) between unit vectors (n, 3) and a unit axis (3,).

    Uses atan2(|d x a|, d . a), accurate near 0 and pi (arccos is not).
    """
    d = np.asarray(directions, dtype=float)
    a = np.asarray(axis, dtype=float)
    return np.arctan2(np.linalg.norm(np.cross(d, a), axis=-1), d @ a)


def complete_columns(rows: NDArray[Any], context: SolveContext) -> NDArray[Any]:
    """Fill the derived columns of ``rows`` in place and return it.

    ``delay_s = path_length_m / c``; ``angle_tx_rad`` is the departure direction's angle off the
    boresight, ``angle_rx_rad`` the angle off the boresight of the direction the wave comes from
    (``-arrival_dir``); directivities are 2 J1(x)/x at the centre frequency; ``absorption_db`` is
    the medium's absorption at the centre frequency times the path length; ``amplitude`` is
    |geometric_gain| D_tx D_rx 10^(-absorption_db / 20) (absolute value: a side lobe's sign is
    kept in the directivity columns).
    """
    if rows.size == 0:
        return rows
    c = context.sound_speed_m_s
    f0 = context.centre_frequency_hz
    a = context.piston_radius_m
    rows["delay_s"] = rows["path_length_m"] / c
    rows["angle_tx_rad"] = off_axis_angle(rows["departure_dir"], context.boresight)
    rows["angle_rx_rad"] = off_axis_angle(-rows["arrival_dir"], context.boresight)
    rows["directivity_tx"] = piston_directivity(rows["angle_tx_rad"], f0, a, c)
    rows["directivity_rx"] = piston_directivity(rows["angle_rx_rad"], f0, a, c)
    rows["absorption_db"] = context.absorption_db_per_m * rows["path_length_m"]
    rows["amplitude"] = np.abs(
        rows["geometric_gain"] * rows["directivity_tx"] * rows["directivity_rx"]
    ) * 10.0 ** (-rows["absorption_db"] / 20.0)
    return rows


__all__ = ["complete_columns", "off_axis_angle"]
