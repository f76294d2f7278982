"""The columns every path row derives from its geometry, and the solve's assembled rows.

Physics
-------
For a row of path length L (m), geometric gain g, departure direction d (leaving the
transmitter) and arrival direction u (travelling into the receiver):

* delay tau = L / c;
* off-axis angles: theta_tx between d and the boresight a, theta_rx between -u (where the wave
  comes from) and a, each as atan2(|v x a|, v . a) (accurate near 0 and pi, where arccos is
  not);
* directivities D = 2 J1(x) / x, x = k a sin(theta), at the centre frequency f0, 0 behind the
  piston (:func:`~acoustisim.propagation.directivity.piston_directivity`; physics.md section 2);
* absorption A = alpha(f0) L (dB), alpha from the medium (Francois-Garrison; physics.md section 1);
* amplitude |g D_tx D_rx| 10^(-A / 20): the echo's pressure factor at f0, relative to the
  source's pressure at 1 m on axis.

Method
------
numpy, column by column. :func:`assemble_rows` joins the mechanisms' rows, fills these columns,
orders the rows by channel, then delay, then their order in the mechanisms' list (a stable
sort), and applies the amplitude floor (:mod:`acoustisim.propagation.reference.floor`).

Accuracy
--------
Exact to float64 rounding; these columns are what synthesis and the ground truth read, at f0
only (synthesis re-evaluates directivity and absorption per frequency bin).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.directivity import piston_directivity
from acoustisim.propagation.paths import PATH_DTYPE, empty_paths_array
from acoustisim.propagation.reference.floor import floor_mask


def off_axis_angle(directions: NDArray[np.float64], axis: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angle (rad, in [0, pi]) between unit vectors ``directions`` (n, 3) and a unit ``axis`` (3,)."""
    d = np.asarray(directions, dtype=float)
    a = np.asarray(axis, dtype=float)
    return np.arctan2(np.linalg.norm(np.cross(d, a), axis=-1), d @ a)


def complete_columns(rows: NDArray[Any], context: SolveContext) -> NDArray[Any]:
    """Fill the derived columns (delay, angles, directivities, absorption, amplitude) of ``rows``
    (PATH_DTYPE, shape (n,)) in place and return it."""
    if rows.size == 0:
        return rows
    c = context.sound_speed_m_s
    f0 = context.centre_frequency_hz
    a = context.piston_radius_m
    length = rows["path_length_m"]
    rows["delay_s"] = length / c
    rows["angle_tx_rad"] = off_axis_angle(rows["departure_dir"], context.boresight)
    rows["angle_rx_rad"] = off_axis_angle(-rows["arrival_dir"], context.boresight)
    rows["directivity_tx"] = piston_directivity(rows["angle_tx_rad"], f0, a, c)
    rows["directivity_rx"] = piston_directivity(rows["angle_rx_rad"], f0, a, c)
    rows["absorption_db"] = length * context.absorption_db_per_m
    rows["amplitude"] = np.abs(rows["geometric_gain"] * rows["directivity_tx"] * rows["directivity_rx"]) * 10.0 ** (
        -rows["absorption_db"] / 20.0)
    return rows


def assemble_rows(parts: Sequence[NDArray[Any]], context: SolveContext, floor_db: float | None,
                  band_hz: tuple[float, float] | None = None) -> NDArray[Any]:
    """The solve's rows from the mechanisms' parts.

    Parameters
    ----------
    parts : sequence of structured ndarray of PATH_DTYPE
        The mechanisms' rows, in the mechanisms' order (not modified).
    context : SolveContext
    floor_db : float or None
        ``SolverConfig.amplitude_floor_db``.
    band_hz : (float, float) or None
        ``SolverConfig.amplitude_floor_band_hz``.

    Returns
    -------
    structured ndarray of PATH_DTYPE, shape (k,)
        Every part's rows with their derived columns, sorted by channel, then delay, then their
        order in ``parts``, without those below the amplitude floor.
    """
    parts = [np.asarray(part, dtype=PATH_DTYPE) for part in parts]
    rows = np.concatenate(parts) if parts else empty_paths_array(0)
    complete_columns(rows, context)
    rows = rows[np.lexsort((rows["delay_s"], rows["channel"]))]
    return np.ascontiguousarray(rows[floor_mask(rows, floor_db, context, band_hz)])


__all__ = ["assemble_rows", "complete_columns", "off_axis_angle"]
