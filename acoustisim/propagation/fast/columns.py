"""The fast engine's derived columns: :func:`acoustisim.propagation.reference.columns.complete_columns`
in compiled passes.

The formulas are the reference's (delay L / c, off-axis angles atan2(|d x a|, d . a), piston
directivities 2 J1(x)/x at f0, absorption alpha(f0) L, amplitude |g D_tx D_rx| 10^(-A/20)).
Here :func:`column_inputs` reads the directions and lengths once: |d x a| and d . a once per run
of consecutive rows with the same departure direction (the receivers of one scattering event)
and once per row for the receiver, each row's sort keys (delay, channel) in the same pass;
numpy's arctan2 gives the angles and scipy's J1 the Bessel function (skipped behind the
pistons). :func:`fill_columns` then writes every derived field of each row in one pass, and can
move the rows as it fills them (:mod:`.assemble`). sin(angle) is |d x a| / hypot(|d x a|, d . a)
and 10^(-L/20) an exponential: directivities agree with the reference within a few ulp of the
argument (< 2e-14 absolute), amplitudes within that relative to |g| 10^(-A/20); delays, angles
and absorption are identical.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.fast.bundles import plain_tuple_arguments
from acoustisim.propagation.context import SolveContext


_NEPER_PER_DB = -math.log(10.0) / 20.0
"""10^(-L / 20) = exp(L * _NEPER_PER_DB)."""


class DirectionFields(NamedTuple):
    """The fields of some rows that the derived columns are read from (views, any strides)."""

    departure_dir: NDArray[np.float64]
    arrival_dir: NDArray[np.float64]
    path_length_m: NDArray[np.float64]
    channel: NDArray[np.int8]


class OffAxisParts(NamedTuple):
    """|d x a| and d . a of the departure directions once per run of equal ones (``run[i]`` is
    row i's run; ``head_sin``, ``head_cos`` per run) and of -arrival_dir per row (``rx_sin``,
    ``rx_cos``); each row's sort keys ``delay_s`` (L / c) and ``channel``, contiguous."""

    run: NDArray[np.intp]
    head_sin: NDArray[np.float64]
    head_cos: NDArray[np.float64]
    rx_sin: NDArray[np.float64]
    rx_cos: NDArray[np.float64]
    delay_s: NDArray[np.float64]
    channel: NDArray[np.int8]


class DerivedColumns(NamedTuple):
    """The derived fields :func:`fill_columns` writes (views of the rows)."""

    delay_s: NDArray[np.float64]
    angle_tx_rad: NDArray[np.float64]
    angle_rx_rad: NDArray[np.float64]
    directivity_tx: NDArray[np.float64]
    directivity_rx: NDArray[np.float64]
    absorption_db: NDArray[np.float64]
    amplitude: NDArray[np.float64]


@njit(cache=True, nogil=True, error_model="numpy")
def _parts(x: float, y: float, z: float, ax: float, ay: float, az: float) -> tuple[float, float]:
    """|d x a| and d . a (the products of ``np.cross``, summed x + y + z)."""
    cx = y * az - z * ay
    cy = z * ax - x * az
    cz = x * ay - y * ax
    return math.sqrt(cx * cx + cy * cy + cz * cz), x * ax + y * ay + z * az


@plain_tuple_arguments
@njit(cache=True, nogil=True, error_model="numpy")
def _parts_pass(rows_fields: tuple, boresight: tuple[float, float, float], c: float, out_fields: tuple) -> int:
    """Fill ``out`` (:class:`OffAxisParts`) from ``rows`` in one pass: -arrival_dir has the same
    |d x a| and exactly the negated cosine; the delay is the very division :func:`_row_pass`
    makes. Returns the number of runs."""
    rows, out = DirectionFields(*rows_fields), OffAxisParts(*out_fields)
    ax, ay, az = boresight
    departure, arrival = rows.departure_dir, rows.arrival_dir
    runs = -1
    px = py = pz = 0.0
    for i in range(out.run.size):
        x = departure[i, 0]
        y = departure[i, 1]
        z = departure[i, 2]
        if runs < 0 or x != px or y != py or z != pz:
            runs += 1
            px, py, pz = x, y, z
            out.head_sin[runs], out.head_cos[runs] = _parts(x, y, z, ax, ay, az)
        out.run[i] = runs
        sin_part, cos_part = _parts(arrival[i, 0], arrival[i, 1], arrival[i, 2], ax, ay, az)
        out.rx_sin[i] = sin_part
        out.rx_cos[i] = -cos_part
        out.delay_s[i] = rows.path_length_m[i] / c
        out.channel[i] = rows.channel[i]
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


class ColumnInputs(NamedTuple):
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


@plain_tuple_arguments
@njit(cache=True, nogil=True, error_model="numpy")
def _row_pass(length: NDArray[np.float64], gain: NDArray[np.float64], inputs_fields: tuple, out_fields: tuple,
              records: NDArray[np.uint8], destination: NDArray[np.int64]) -> None:
    """Every derived field of every row (``length``, ``gain``: its ``path_length_m`` and
    ``geometric_gain``), written into ``out`` in one pass; 10^(-L / 20) is exp(L * _NEPER_PER_DB)
    (within 2 ulp of numpy's power, several times cheaper).

    With a ``destination`` (increasing, ``destination[i] >= i``; empty: rows stay), record i of
    ``records`` (the same rows as raw bytes) is first moved to ``destination[i]``, from the last
    one back (no record is overwritten before it is moved), and its derived fields are written
    there: the move and the fill touch each row once (:func:`fill_columns`).
    """
    inputs, out = ColumnInputs(*inputs_fields), DerivedColumns(*out_fields)
    run = inputs.run
    head_angle, head_x, head_j1 = inputs.head_angle, inputs.head_argument, inputs.head_j1
    rx_angle, rx_x, rx_j1 = inputs.rx_angle, inputs.rx_argument, inputs.rx_j1
    c, alpha_db_per_m = inputs.sound_speed_m_s, inputs.absorption_db_per_m
    delay, angle_tx, angle_rx = out.delay_s, out.angle_tx_rad, out.angle_rx_rad
    directivity_tx, directivity_rx, absorption, amplitude = (out.directivity_tx, out.directivity_rx,
                                                              out.absorption_db, out.amplitude)
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
    runs = _parts_pass(DirectionFields(rows["departure_dir"], rows["arrival_dir"], rows["path_length_m"],
                                       rows["channel"]), (ax, ay, az), c,
                       OffAxisParts(run, head_x, head_cos, rx_x, rx_cos, delay, channel))
    head_x, head_cos = head_x[:runs], head_cos[:runs]
    # numpy's (vectorised) arctan2, as the reference engine's off_axis_angle
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
    _row_pass(rows["path_length_m"], rows["geometric_gain"], inputs,
              DerivedColumns(*(rows[name] for name in DerivedColumns._fields)), records, destination)


def complete_columns(rows: NDArray[Any], context: SolveContext) -> NDArray[Any]:
    """Fill the derived columns of ``rows`` (PATH_DTYPE, shape (n,), any view) in place and
    return it: :func:`acoustisim.propagation.reference.columns.complete_columns`, compiled
    (:func:`column_inputs` then :func:`fill_columns`)."""
    if rows.size:
        fill_columns(rows, column_inputs(rows, context))
    return rows


__all__ = ("ColumnInputs", "DerivedColumns", "DirectionFields", "OffAxisParts", "column_inputs", "complete_columns",
           "fill_columns")
