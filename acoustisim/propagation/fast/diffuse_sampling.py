"""Compiled random draws of the diffuse tracer: the counter-based stream, speckle, directions.

Each function evaluates, operation for operation, what its namesake in
:mod:`acoustisim.propagation.reference.diffuse` evaluates with numpy (the same SplitMix64
numbers, the same lobe table, the same frames and azimuth rotation), so that both engines put
every ray and hit point on the same bits; here the random numbers are drawn inside the loops
that use them, with no array of them.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.reference.diffuse import (
    COS_CELLS,
    GUIDE_BINS,
    SPATIAL_HASH_PRIMES,
    SPLITMIX_GAMMA,
    SPLITMIX_MULTIPLIERS,
    azimuth_table,
    cell_solid_angles,
    lobe_power,
)

_GAMMA = SPLITMIX_GAMMA
_MIX1, _MIX2 = SPLITMIX_MULTIPLIERS
_PRIME_X, _PRIME_Y, _PRIME_Z = SPATIAL_HASH_PRIMES
_S11, _S27, _S30, _S31, _S32 = np.uint64(11), np.uint64(27), np.uint64(30), np.uint64(31), np.uint64(32)
_LOW32 = np.uint64(0xFFFFFFFF)
_TWO_PI = 2.0 * math.pi


class LobeTable(NamedTuple):
    """The transmitted rays' sampling table (the reference's
    :class:`~acoustisim.propagation.reference.diffuse.TransmitSampler`, in compiled form).

    ``guide`` (GUIDE_BINS,) int16: the cell of each equiprobable bin; ``solid_angle``
    (COS_CELLS,): dOmega of a ray in each cell (sr); ``width``: the cells' width in cos(theta);
    ``azimuth`` (1024, 2): :func:`~acoustisim.propagation.reference.diffuse.azimuth_table`.
    """

    guide: NDArray[np.int16]
    solid_angle: NDArray[np.float64]
    width: float
    azimuth: NDArray[np.float64]


def lobe_table(context: SolveContext, counts: tuple[int, int]) -> LobeTable:
    """The table for ``context``'s piston and ``counts`` = (N_u, N_l) rays (uniform, lobe)."""
    guide = np.empty(GUIDE_BINS, dtype=np.int16)  # 128 KiB: gathered at random once per lobe ray
    bins = np.empty(COS_CELLS, dtype=np.int64)
    guide_table(np.cumsum(lobe_power(context)), guide, bins)
    return LobeTable(guide, cell_solid_angles(bins, counts), 2.0 / COS_CELLS, azimuth_table())


@njit(cache=True, nogil=True, error_model="numpy")
def guide_table(mass: NDArray[np.float64], guide: NDArray[np.int16], bins: NDArray[np.int64]) -> None:
    """The equiprobable bins of a tabulated density: bin i (of ``guide.size``) gets the first
    cell whose cumulative ``mass`` (non-decreasing) exceeds (i + 1/2) mass[-1] / guide.size
    (at most the last cell), as ``numpy.searchsorted(mass, quantiles, side="right")`` would,
    in one linear merge of the sorted quantiles with the cells; ``bins`` (n_cells,) gets the
    bins of each cell."""
    n_cells = mass.size
    step = mass[n_cells - 1] / guide.size
    bins[:] = 0
    cell = 0
    for i in range(guide.size):
        quantile = (i + 0.5) * step
        while cell < n_cells and mass[cell] <= quantile:
            cell += 1
        chosen = min(cell, n_cells - 1)
        guide[i] = chosen
        bins[chosen] += 1


@njit(cache=True, nogil=True, error_model="numpy")
def splitmix64(x: np.uint64) -> np.uint64:
    """SplitMix64's output function of the state ``x`` (wrapping arithmetic)."""
    z = x + _GAMMA
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


def stream_key(seed_hash: np.uint64, chunk: int) -> np.uint64:
    """The key of chunk ``chunk``'s stream, splitmix64(seed_hash ^ splitmix64(chunk)) (as
    :func:`~acoustisim.propagation.reference.diffuse.stream_key`, here from compiled scalars)."""
    return np.uint64(splitmix64(np.uint64(seed_hash) ^ np.uint64(splitmix64(np.uint64(chunk)))))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def stream_uniform(key: np.uint64, k: int) -> float:
    """Number ``k`` of the stream ``key``, uniform in [0, 1) (53 random bits)."""
    return np.float64(splitmix64(key + np.uint64(k) * _GAMMA) >> _S11) * 2.0**-53


@njit(cache=True, nogil=True, error_model="numpy")
def speckle_of(x: float, y: float, z: float, per_cell: float, seed_hash: np.uint64) -> tuple[float, float]:
    """|X| and arg X (rad) of the speckle factor of the point (x, y, z) (m); ``per_cell`` =
    1 / SPECKLE_CELL_M (1/m), ``seed_hash`` = splitmix64(seed)."""
    kx = np.uint64(np.int64(math.floor(x * per_cell)))
    ky = np.uint64(np.int64(math.floor(y * per_cell)))
    kz = np.uint64(np.int64(math.floor(z * per_cell)))
    h = splitmix64(((kx * _PRIME_X) ^ (ky * _PRIME_Y) ^ (kz * _PRIME_Z)) ^ seed_hash)
    u1 = np.float64(h >> _S32) * 2.0**-32
    u2 = np.float64(h & _LOW32) * 2.0**-32
    # u1 is a multiple of 2^-32 below 1: 1 - u1 is exact and log gives -log(1 - u1) as
    # accurately as log1p would
    return math.sqrt(-math.log(1.0 - u1)), _TWO_PI * u2 - math.pi


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def unit_azimuth(u: float, table: NDArray[np.float64]) -> tuple[float, float]:
    """cos(phi) and sin(phi) of phi = 2 pi u (u in [0, 1)), without a trigonometric call: the
    table row k = floor(1024 u) rotated by delta = 2 pi u - phi_k with Taylor series to delta^4
    and delta^5 (as :func:`~acoustisim.propagation.reference.diffuse.azimuth_cos_sin`)."""
    x = u * table.shape[0]  # exact for a power of two
    k = int(x)
    delta = (x - k) * (_TWO_PI / table.shape[0])
    d2 = delta * delta
    cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0))
    sd = delta * (1.0 - d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0)))
    ck, sk = table[k, 0], table[k, 1]
    return ck * cd - sk * sd, sk * cd + ck * sd


@njit(cache=True, nogil=True, error_model="numpy")
def draw_transmit_directions(key: np.uint64, start: int, n_uniform: int, lobe: LobeTable, frame: NDArray[np.float64],
                             directions: NDArray[np.float64], solid_angle: NDArray[np.float64]) -> None:
    """Directions (3, n) and solid angles (n,) (sr) of one chunk's n transmitted rays, from the
    numbers ``start`` to ``start + 2n - 1`` of the stream ``key`` (ray i: cos(theta) from number
    ``start + i``, the azimuth from ``start + n + i``; the first ``n_uniform`` rays uniform, the
    others from the lobe; see
    :meth:`~acoustisim.propagation.reference.diffuse.TransmitSampler.draw`).

    ``frame`` (3, 3): rows e1, e2 and the axis of the transmitter's frame. ``n`` is
    ``directions.shape[1]``.
    """
    n = directions.shape[1]
    n_cells = lobe.solid_angle.shape[0]
    width = lobe.width
    for i in range(n):
        u_theta = stream_uniform(key, start + i)
        u_phi = stream_uniform(key, start + n + i)
        if i < n_uniform:
            cos_t = 1.0 - 2.0 * u_theta
            cell = min(int((1.0 - cos_t) * (n_cells / 2.0)), n_cells - 1)
        else:
            x = u_theta * lobe.guide.size  # exact for a power of two
            b = int(x)
            cell = np.int64(lobe.guide[b])
            cos_t = (1.0 - cell * width) - (x - b) * width
        sin_t = math.sqrt(max(1.0 - cos_t * cos_t, 0.0))
        cp, sp = unit_azimuth(u_phi, lobe.azimuth)
        a = sin_t * cp
        c = sin_t * sp
        for k in range(3):
            directions[k, i] = a * frame[0, k] + c * frame[1, k] + cos_t * frame[2, k]
        solid_angle[i] = lobe.solid_angle[cell]


@njit(cache=True, nogil=True, error_model="numpy")
def draw_lambert_directions(key: np.uint64, start: int, normal: NDArray[np.float64], azimuth: NDArray[np.float64],
                            directions: NDArray[np.float64]) -> None:
    """Cosine-weighted directions (3, h) about the unit normals (3, h), from the numbers
    ``start`` to ``start + 2h - 1`` of the stream ``key`` (hit i: the squared radius from number
    ``start + i``, the azimuth from ``start + h + i``), in the tangent frame t1 = n x x / |n x x|
    (n x y where |n_x| >= 0.9), t2 = n x t1, as
    :func:`~acoustisim.propagation.reference.diffuse.lambert_directions`."""
    h = normal.shape[1]
    for i in range(h):
        u_radius = stream_uniform(key, start + i)
        u_phi = stream_uniform(key, start + h + i)
        nx, ny, nz = normal[0, i], normal[1, i], normal[2, i]
        if abs(nx) < 0.9:  # n x (1, 0, 0)
            ax, ay, az = 0.0, nz, -ny
        else:  # n x (0, 1, 0)
            ax, ay, az = -nz, 0.0, nx
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        ax, ay, az = ax / norm, ay / norm, az / norm
        bx, by, bz = ny * az - nz * ay, nz * ax - nx * az, nx * ay - ny * ax
        radius = math.sqrt(u_radius)
        cp, sp = unit_azimuth(u_phi, azimuth)
        along_1, along_2 = radius * cp, radius * sp
        along_n = math.sqrt(max(1.0 - u_radius, 0.0))
        directions[0, i] = along_1 * ax + along_2 * bx + along_n * nx
        directions[1, i] = along_1 * ay + along_2 * by + along_n * ny
        directions[2, i] = along_1 * az + along_2 * bz + along_n * nz


__all__ = ("LobeTable", "draw_lambert_directions", "draw_transmit_directions", "guide_table", "lobe_table",
           "speckle_of", "splitmix64", "stream_key", "stream_uniform", "unit_azimuth")
