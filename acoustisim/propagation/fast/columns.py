"""Columns every path row derives from its geometry: delay, angles, directivity, absorption,
amplitude.

Mechanisms fill ``path_id``, ``channel``, ``kind``, ``order``, ``path_length_m``,
``geometric_gain``, ``phase_rad``, ``departure_dir``, ``arrival_dir``, ``object_ids`` and
``points_m``; :func:`complete_columns` (called by :func:`acoustisim.propagation.solve` on every
mechanism's rows) computes the rest, so all mechanisms agree on them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.directivity import piston_directivity  # noqa: F401 (the formula reproduced)


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


_NEPER_PER_DB = -math.log(10.0) / 20.0
"""10^(-L / 20) = exp(L * _NEPER_PER_DB)."""


@njit(cache=True, nogil=True, error_model="numpy")
def _parts(x: float, y: float, z: float, ax: float, ay: float, az: float) -> tuple[float, float]:
    """|d x a| and d . a with the products and sums of :func:`_off_axis_parts`, in its order."""
    cx = y * az - z * ay
    cy = z * ax - x * az
    cz = x * ay - y * ax
    return math.sqrt(cx * cx + cy * cy + cz * cz), x * ax + y * ay + z * az


@njit(cache=True, nogil=True, error_model="numpy")
def _parts_pass(departure: NDArray[np.float64], arrival: NDArray[np.float64], ax: float, ay: float, az: float,
                run: NDArray[np.intp], head_sin: NDArray[np.float64], head_cos: NDArray[np.float64],
                rx_sin: NDArray[np.float64], rx_cos: NDArray[np.float64], length: NDArray[np.float64], c: float,
                channel: NDArray[np.int8], delay_out: NDArray[np.float64], channel_out: NDArray[np.int8]) -> int:
    """|d x a| and d . a of the departure directions once per run of equal ones (``run[i]`` is
    row i's run, ``head_*[run]`` its values) and of -arrival_dir per row (the same |d x a|,
    exactly the negated cosine); and, in the same pass, each row's sort keys: its delay
    ``length / c`` (the very division :func:`_row_pass` makes) and channel, contiguous. Returns
    the number of runs."""
    runs = -1
    px = py = pz = 0.0
    for i in range(run.size):
        x = departure[i, 0]
        y = departure[i, 1]
        z = departure[i, 2]
        if runs < 0 or x != px or y != py or z != pz:
            runs += 1
            px, py, pz = x, y, z
            head_sin[runs], head_cos[runs] = _parts(x, y, z, ax, ay, az)
        run[i] = runs
        sin_part, cos_part = _parts(arrival[i, 0], arrival[i, 1], arrival[i, 2], ax, ay, az)
        rx_sin[i] = sin_part
        rx_cos[i] = -cos_part
        delay_out[i] = length[i] / c
        channel_out[i] = channel[i]
    return runs + 1


@njit(cache=True, nogil=True, error_model="numpy")
def _arguments_into(angle: NDArray[np.float64], sin_part: NDArray[np.float64], cos_part: NDArray[np.float64],
                    ka: float) -> None:
    """Overwrite ``sin_part`` with the piston argument x = k a sin(angle) of each angle
    (= atan2(sin_part, cos_part)), or 0.0 where |x| < 1e-8 (where 2 J1(x)/x = 1 - x^2/8 rounds
    to 1.0), or NaN behind the piston (cos(angle) < 0: directivity 0, and scipy's J1 of NaN is
    cheap).

    cos(angle) < 0 is cos_part < 0, except within rounding of 90 deg, where the cosine
    decides; sin(atan2(s, c)) is s / hypot(s, c), without a sine (numpy's is not vectorised
    for float64 and costs more than this whole loop; the two differ by a few ulp).
    """
    for i in range(angle.size):
        s = sin_part[i]
        c = cos_part[i]
        if c < 0.0 and (c < -1e-12 or math.cos(angle[i]) < 0.0):
            sin_part[i] = math.nan
            continue
        arg = ka * (s / math.sqrt(s * s + c * c))
        sin_part[i] = 0.0 if abs(arg) < 1e-8 else arg


@njit(cache=True, nogil=True, error_model="numpy")
def _directivity(x: float, j1x: float) -> float:
    """2 J1(x)/x as :func:`piston_directivity` gives it, from the argument stored by
    :func:`_arguments_into` and J1 of it."""
    if math.isnan(x):
        return 0.0
    if x == 0.0:
        return 1.0
    return 2.0 * j1x / x


@njit(cache=True, nogil=True, error_model="numpy")
def _row_pass(length: NDArray[np.float64], gain: NDArray[np.float64], c: float, alpha_db_per_m: float,
              run: NDArray[np.intp], head_angle: NDArray[np.float64], head_x: NDArray[np.float64],
              head_j1: NDArray[np.float64], rx_angle: NDArray[np.float64], rx_x: NDArray[np.float64],
              rx_j1: NDArray[np.float64], delay: NDArray[np.float64], angle_tx: NDArray[np.float64],
              angle_rx: NDArray[np.float64], directivity_tx: NDArray[np.float64],
              directivity_rx: NDArray[np.float64], absorption: NDArray[np.float64],
              amplitude: NDArray[np.float64], records: NDArray[np.uint8], destination: NDArray[np.int64]) -> None:
    """Every derived field of every row, written in one pass over the rows; 10^(-L / 20) is
    exp(L * _NEPER_PER_DB) (within 2 ulp of numpy's power, several times cheaper).

    With a ``destination`` (increasing, ``destination[i] >= i``; empty: rows stay), record i of
    ``records`` (the same rows as raw bytes) is first moved to ``destination[i]``, from the last
    one back (no record is overwritten before it is moved), and its derived fields are written
    there: the move and the fill touch each row once (:func:`fill_columns`).
    """
    n = run.size
    moving = destination.size > 0
    width = records.shape[1]
    last = -1
    d_tx = 0.0
    for k in range(n):
        i = n - 1 - k if moving else k
        r = run[i]
        if r != last:
            last = r
            d_tx = _directivity(head_x[r], head_j1[r])
        d_rx = _directivity(rx_x[i], rx_j1[i])
        path = length[i]
        g = gain[i]
        j = i
        if moving:
            j = destination[i]
            if j != i:
                for b in range(width):
                    records[j, b] = records[i, b]
        loss = path * alpha_db_per_m
        delay[j] = path / c
        angle_tx[j] = head_angle[r]
        angle_rx[j] = rx_angle[i]
        directivity_tx[j] = d_tx
        directivity_rx[j] = d_rx
        absorption[j] = loss
        amplitude[j] = abs(g * d_tx * d_rx) * math.exp(loss * _NEPER_PER_DB)


@dataclass(frozen=True)
class ColumnInputs:
    """What the derived columns of some rows are computed from, read from them in one pass
    (:func:`column_inputs`), and their sort keys; :func:`fill_columns` writes the columns.

    Attributes
    ----------
    delay_s : ndarray of float64, shape (n,)
        ``path_length_m / c`` (s): the bits ``delay_s`` will hold.
    channel : ndarray of int8, shape (n,)
        The rows' channels.
    run : ndarray of intp, shape (n,)
        Each row's run of equal departure directions.
    head_angle, head_argument, head_j1 : ndarray of float64, shape (runs,)
        Per run: the angle off the boresight (rad), the piston argument x (0 on axis, NaN
        behind the piston; :func:`_arguments_into`) and J1(x).
    rx_angle, rx_argument, rx_j1 : ndarray of float64, shape (n,)
        The same of each row's -arrival_dir.
    sound_speed_m_s, absorption_db_per_m : float
    """

    delay_s: NDArray[np.float64]
    channel: NDArray[np.int8]
    run: NDArray[np.intp]
    head_angle: NDArray[np.float64]
    head_argument: NDArray[np.float64]
    head_j1: NDArray[np.float64]
    rx_angle: NDArray[np.float64]
    rx_argument: NDArray[np.float64]
    rx_j1: NDArray[np.float64]
    sound_speed_m_s: float
    absorption_db_per_m: float


def column_inputs(rows: NDArray[Any], context: SolveContext) -> ColumnInputs:
    """Read the directions, path lengths and channels of ``rows`` (PATH_DTYPE, shape (n,), any
    view) once, and evaluate the angles (numpy's arctan2) and J1 (scipy) on contiguous arrays."""
    from scipy.special import j1

    n = rows.size
    c = float(context.sound_speed_m_s)
    a = float(context.piston_radius_m)
    # k a as piston_directivity forms it: (2 pi f0 / c) a
    ka = float(2.0 * np.pi * np.asarray(context.centre_frequency_hz, dtype=float) / c) * a
    ax, ay, az = (float(v) for v in np.asarray(context.boresight, dtype=float))
    run = np.empty(n, dtype=np.intp)
    head_x, head_cos, rx_x, rx_cos, delay = np.empty((5, n))
    channel = np.empty(n, dtype=np.int8)
    runs = _parts_pass(rows["departure_dir"], rows["arrival_dir"], ax, ay, az, run, head_x, head_cos, rx_x, rx_cos,
                       rows["path_length_m"], c, rows["channel"], delay, channel)
    head_x, head_cos = head_x[:runs], head_cos[:runs]
    # numpy's (vectorised) arctan2, as the previous formulation
    head_angle = np.arctan2(head_x, head_cos)
    rx_angle = np.arctan2(rx_x, rx_cos)
    _arguments_into(head_angle, head_x, head_cos, ka)
    _arguments_into(rx_angle, rx_x, rx_cos, ka)
    return ColumnInputs(delay, channel, run, head_angle, head_x, j1(head_x), rx_angle, rx_x, j1(rx_x), c,
                        float(context.absorption_db_per_m))


def fill_columns(rows: NDArray[Any], inputs: ColumnInputs, destination: NDArray[np.int64] | None = None) -> None:
    """Write the derived columns of the rows ``inputs`` was read from, in one pass.

    Parameters
    ----------
    rows : structured ndarray of PATH_DTYPE, shape (n,)
        Without ``destination``: the rows themselves (any view). With it: a C-contiguous
        buffer whose first h = ``destination.size`` records are those rows.
    inputs : ColumnInputs
        :func:`column_inputs` of ``rows`` (of ``rows[:h]`` with a destination).
    destination : ndarray of int64, shape (h,), optional
        Increasing, ``destination[i] >= i``: record i is moved there first (from the last one
        back, so none is overwritten before it moves), and its columns written there; byte
        for byte what :func:`complete_columns` then the move would give at the destinations.
        The places vacated among the first h keep stale records (the moved rows without their
        derived columns): the caller fills them; other records are left as they are.
    """
    if destination is None or destination.size == 0:
        destination = np.empty(0, dtype=np.int64)
        records = np.empty((0, 1), dtype=np.uint8)  # nothing moves: any view of the rows will do
    else:
        destination = np.ascontiguousarray(destination, dtype=np.int64)
        records = rows.view(np.uint8).reshape(rows.size, rows.dtype.itemsize)
    _row_pass(rows["path_length_m"], rows["geometric_gain"], inputs.sound_speed_m_s, inputs.absorption_db_per_m,
              inputs.run, inputs.head_angle, inputs.head_argument, inputs.head_j1, inputs.rx_angle,
              inputs.rx_argument, inputs.rx_j1, rows["delay_s"], rows["angle_tx_rad"], rows["angle_rx_rad"],
              rows["directivity_tx"], rows["directivity_rx"], rows["absorption_db"], rows["amplitude"], records,
              destination)


def complete_columns(rows: NDArray[Any], context: SolveContext) -> NDArray[Any]:
    """Fill the derived columns of ``rows`` in place and return it.

    ``delay_s = path_length_m / c``; ``angle_tx_rad`` is the departure direction's angle off the
    boresight, ``angle_rx_rad`` the angle off the boresight of the direction the wave comes from
    (``-arrival_dir``); directivities are 2 J1(x)/x at the centre frequency
    (:func:`piston_directivity`); ``absorption_db`` is the medium's absorption at the centre
    frequency (``context.absorption_db_per_m``, evaluated once per solve) times the path
    length; ``amplitude`` is |geometric_gain| D_tx D_rx 10^(-absorption_db / 20) (absolute
    value: a side lobe's sign is kept in the directivity columns).

    Compiled passes: :func:`_parts_pass` reads the directions (in place, strided) into
    contiguous |d x a| and d . a, once per run of consecutive rows with the same departure
    direction (the receivers of one scattering event) and once per row for the receiver;
    numpy's arctan2 gives the angles (bit for bit those of :func:`off_axis_angle`);
    :func:`_arguments_into` the piston arguments, on which scipy's J1 is evaluated (skipped
    behind the pistons); :func:`_row_pass` writes every derived field of each row at once
    (:func:`column_inputs` and :func:`fill_columns`, which can also move the rows as it
    fills them).
    The operations are those of :func:`piston_directivity` in the same order, except that
    sin(angle) is |d x a| / hypot(|d x a|, d . a) and 10^(-L/20) an exponential: directivities
    agree with it within a few ulp of the argument (< 2e-14 absolute) and amplitudes within
    that relative to |geometric_gain| 10^(-absorption_db / 20); delays, angles and absorption
    are identical
    (tested in ``tests/parity/test_propagation_columns.py``).
    """
    if rows.size:
        fill_columns(rows, column_inputs(rows, context))
    return rows


__all__ = ["ColumnInputs", "column_inputs", "complete_columns", "fill_columns", "off_axis_angle"]
