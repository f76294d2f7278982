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

    Uses atan2(|d x a|, d . a), accurate near 0 and pi (arccos is not). Written per component
    (the same products and sums as ``np.cross`` / ``np.linalg.norm``) so that a strided
    ``directions`` (a structured-array field) is read once, without temporaries of shape (n, 3).
    """
    d = np.asarray(directions, dtype=float)
    a = np.asarray(axis, dtype=float)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    ax, ay, az = float(a[0]), float(a[1]), float(a[2])
    cx = y * az - z * ay
    cy = z * ax - x * az
    cz = x * ay - y * ax
    sin_part = np.sqrt(cx * cx + cy * cy + cz * cz)
    cos_part = x * ax + y * ay + z * az
    return np.arctan2(sin_part, cos_part)


_DERIVED = ("angle_tx_rad", "angle_rx_rad", "directivity_tx", "directivity_rx", "absorption_db", "amplitude")
"""Derived float64 columns written together (consecutive in ``PATH_DTYPE``)."""


def _float_block(rows: NDArray[Any], names: tuple[str, ...]) -> NDArray[np.float64] | None:
    """A writable (n, len(names)) float64 view of consecutive float64 fields of ``rows``, or None
    if the fields are not laid out back to back."""
    fields = rows.dtype.fields
    if fields is None or any(name not in fields or fields[name][0] != np.float64 for name in names):
        return None
    offsets = [fields[name][1] for name in names]
    if any(b - a != 8 for a, b in zip(offsets, offsets[1:])):
        return None
    overlay = np.dtype({"names": ["block"], "formats": [(np.float64, (len(names),))], "offsets": [offsets[0]],
                        "itemsize": rows.dtype.itemsize})
    return rows.view(overlay)["block"]


def _run_starts(directions: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Whether each row (n, 3) differs from the previous one (True for the first row).

    Rows of one diffuse scattering event (or of one edge element) going to several receivers
    share their departure direction and sit next to each other, so the transmitter-side columns
    are computed once per run of equal directions.
    """
    start = np.ones(directions.shape[0], dtype=bool)
    if directions.shape[0] > 1:
        same = directions[1:] == directions[:-1]
        start[1:] = ~(same[:, 0] & same[:, 1] & same[:, 2])
    return start


def complete_columns(rows: NDArray[Any], context: SolveContext) -> NDArray[Any]:
    """Fill the derived columns of ``rows`` in place and return it.

    ``delay_s = path_length_m / c``; ``angle_tx_rad`` is the departure direction's angle off the
    boresight, ``angle_rx_rad`` the angle off the boresight of the direction the wave comes from
    (``-arrival_dir``); directivities are 2 J1(x)/x at the centre frequency; ``absorption_db`` is
    the medium's absorption at the centre frequency (``context.absorption_db_per_m``, evaluated
    once per solve) times the path length; ``amplitude`` is
    |geometric_gain| D_tx D_rx 10^(-absorption_db / 20) (absolute value: a side lobe's sign is
    kept in the directivity columns).

    Each source field is read once into a contiguous array and each derived field written once;
    the transmitter angle and directivity are evaluated once per run of consecutive rows with
    the same departure direction (the receivers of one scattering event) and repeated.
    """
    n = rows.size
    if n == 0:
        return rows
    c = context.sound_speed_m_s
    f0 = context.centre_frequency_hz
    a = context.piston_radius_m
    length = np.ascontiguousarray(rows["path_length_m"])
    departure = np.ascontiguousarray(rows["departure_dir"])
    start = _run_starts(departure)
    heads = np.flatnonzero(start)
    if heads.size < n:
        angle_tx_heads = off_axis_angle(departure[heads], context.boresight)
        directivity_tx_heads = piston_directivity(angle_tx_heads, f0, a, c)
        run = np.cumsum(start) - 1
        angle_tx = angle_tx_heads[run]
        directivity_tx = directivity_tx_heads[run]
    else:
        angle_tx = off_axis_angle(departure, context.boresight)
        directivity_tx = piston_directivity(angle_tx, f0, a, c)
    angle_rx = off_axis_angle(-np.ascontiguousarray(rows["arrival_dir"]), context.boresight)
    directivity_rx = piston_directivity(angle_rx, f0, a, c)
    absorption = context.absorption_db_per_m * length
    amplitude = np.abs(rows["geometric_gain"] * directivity_tx * directivity_rx) * 10.0 ** (-absorption / 20.0)
    derived = np.column_stack([angle_tx, angle_rx, directivity_tx, directivity_rx, absorption, amplitude])
    block = _float_block(rows, _DERIVED)
    if block is not None:  # one strided pass over the rows instead of one per field
        block[:] = derived
    else:
        for j, name in enumerate(_DERIVED):
            rows[name] = derived[:, j]
    rows["delay_s"] = length / c
    return rows


__all__ = ["complete_columns", "off_axis_angle"]
