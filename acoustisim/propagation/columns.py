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


def _off_axis_parts(x: NDArray[np.float64], y: NDArray[np.float64], z: NDArray[np.float64],
                    axis: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """|d x a| and d . a of directions given by components x, y, z (any equal shapes) and a (3,).

    The same products and sums as ``np.cross`` / ``np.linalg.norm``. Negating d negates every
    product exactly, so -d gives the same |d x a| and exactly -(d . a).
    """
    ax, ay, az = float(axis[0]), float(axis[1]), float(axis[2])
    cx = y * az - z * ay
    cy = z * ax - x * az
    cz = x * ay - y * ax
    cx *= cx
    cy *= cy
    cz *= cz
    cx += cy
    cx += cz
    sin_part = np.sqrt(cx, out=cx)
    cos_part = x * ax
    cos_part += y * ay
    cos_part += z * az
    return sin_part, cos_part


def off_axis_angle(directions: NDArray[np.float64], axis: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angle (rad, in [0, pi]) between unit vectors (n, 3) and a unit axis (3,).

    Uses atan2(|d x a|, d . a), accurate near 0 and pi (arccos is not). Written per component
    (the same products and sums as ``np.cross`` / ``np.linalg.norm``) so that a strided
    ``directions`` (a structured-array field) is read once, without temporaries of shape (n, 3).
    """
    d = np.asarray(directions, dtype=float)
    sin_part, cos_part = _off_axis_parts(d[..., 0], d[..., 1], d[..., 2], np.asarray(axis, dtype=float))
    return np.arctan2(sin_part, cos_part)


def _components(directions: NDArray[np.float64]) -> NDArray[np.float64]:
    """Directions (n, 3) (e.g. a strided structured field) as contiguous component rows (3, n)."""
    return np.ascontiguousarray(np.asarray(directions, dtype=float).T)


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


def _run_starts(components: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Whether each direction, given as component rows (3, n), differs from the previous one
    (True for the first).

    Rows of one diffuse scattering event (or of one edge element) going to several receivers
    share their departure direction and sit next to each other, so the transmitter-side columns
    are computed once per run of equal directions.
    """
    n = components.shape[1]
    start = np.ones(n, dtype=bool)
    if n > 1:
        x, y, z = components
        same = x[1:] == x[:-1]
        same &= y[1:] == y[:-1]
        same &= z[1:] == z[:-1]
        np.logical_not(same, out=start[1:])
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
    # (6, n): the derived columns, each contiguous, written to the rows in one pass at the end
    derived = np.empty((len(_DERIVED), n))
    angle_tx, angle_rx, directivity_tx, directivity_rx, absorption, amplitude = derived
    departure = _components(rows["departure_dir"])
    start = _run_starts(departure)
    heads = np.flatnonzero(start)
    if heads.size < n:
        sin_part, cos_part = _off_axis_parts(*departure[:, heads], context.boresight)
        angle_heads = np.arctan2(sin_part, cos_part)
        run = np.cumsum(start) - 1
        np.take(angle_heads, run, out=angle_tx)
        np.take(piston_directivity(angle_heads, f0, a, c), run, out=directivity_tx)
    else:
        sin_part, cos_part = _off_axis_parts(*departure, context.boresight)
        np.arctan2(sin_part, cos_part, out=angle_tx)
        directivity_tx[:] = piston_directivity(angle_tx, f0, a, c)
    del departure
    # the wave comes from -arrival_dir: same |d x a|, cosine negated (exactly)
    sin_part, cos_part = _off_axis_parts(*_components(rows["arrival_dir"]), context.boresight)
    np.negative(cos_part, out=cos_part)
    np.arctan2(sin_part, cos_part, out=angle_rx)
    directivity_rx[:] = piston_directivity(angle_rx, f0, a, c)
    np.multiply(length, context.absorption_db_per_m, out=absorption)
    np.multiply(rows["geometric_gain"], directivity_tx, out=amplitude)
    amplitude *= directivity_rx
    np.abs(amplitude, out=amplitude)
    amplitude *= 10.0 ** (-absorption / 20.0)
    derived = derived.T
    block = _float_block(rows, _DERIVED)
    if block is not None:  # one strided pass over the rows instead of one per field
        block[:] = derived
    else:
        for j, name in enumerate(_DERIVED):
            rows[name] = derived[:, j]
    rows["delay_s"] = length / c
    return rows


__all__ = ["complete_columns", "off_axis_angle"]
