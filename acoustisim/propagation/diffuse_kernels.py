"""Compiled per-hit loops of the diffuse tracer (numba, cached on disk, GIL released).

The diffuse tracer (:mod:`acoustisim.propagation.diffuse`) finds the hit triangles (without
Embree where it can, :mod:`~acoustisim.propagation.diffuse_hits`) and asks Embree for the
others and for the occlusion of the legs its box screen cannot decide; the arithmetic per ray,
per hit and per (hit, receiver) pair, which numpy can only express as dozens of passes over
temporary arrays, is compiled here:

0. :func:`draw_transmit_directions`: each chunk's transmitted directions and solid angles,
   its random numbers drawn from its SplitMix64 stream inside the loop (:func:`splitmix64`)
   and the azimuth rotated from a table (:func:`unit_azimuth`), no trigonometric call;
1. :func:`speckle_into`: the speckle factor frozen to each world position (a hash of the
   position's 1 mm cube and the seed);
2. :func:`scatter_and_pair`: the rays that hit a scattering surface from its front, compacted,
   with the hit point solved on the triangle's plane in float64, the distance travelled and
   the speckle amplitude |X| sqrt(mu dOmega); then, for every hit and receiver, the leg's
   length and r2 sin(g_s), whether the receiver is in front of the face, whether a convex
   object blocks the leg (its face planes, :mod:`~acoustisim.propagation.convex_occlusion`),
   and the legs left for an Embree occlusion query (crossing the box of a non-convex object,
   see :class:`~acoustisim.propagation.diffuse.ObjectScreen`), written as Embree's float32
   buffers;
4. :func:`clear_blocked` and :func:`write_receptions`: the pairs left in view, point-major,
   with their event, receiver and gain, written straight into the tracer's output (as
   :func:`scatter_and_pair` writes the events); :func:`copy_chunk` copies a chunk written
   into a scratch block (on another thread) to its final place;
5. :func:`reception_columns` and :func:`pack_rows`: the receptions' path lengths, phases and
   arrival directions, derived from their event and receiver, and the rows of the arrivals
   table.

Every loop runs in order over its inputs, so the output is deterministic; ``nogil=True`` lets
the tracer's threads run them in parallel; ``error_model="numpy"`` drops the per-division
zero checks (no divisor here can be 0: each is guarded by the test before it). ``cache=True`` stores the compiled code in
``__pycache__`` beside this file (or numba's per-user cache directory): the first call in a
fresh checkout compiles for a few seconds, later processes load the cache.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from acoustisim.propagation.convex_occlusion import segment_crosses_convex

GOLDEN = np.uint64(0x9E3779B97F4A7C15)
MIX1 = np.uint64(0xBF58476D1CE4E5B9)
MIX2 = np.uint64(0x94D049BB133111EB)
PRIME_X = np.uint64(0x8DA6B343)  # spatial-hash multipliers (Teschner et al. 2003), odd
PRIME_Y = np.uint64(0xD8163841)
PRIME_Z = np.uint64(0xCB1AB31F)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_S32 = np.uint64(32)
_LOW32 = np.uint64(0xFFFFFFFF)
_TWO_PI = 2.0 * math.pi


@njit(cache=True, nogil=True, error_model="numpy")
def splitmix64(x: np.uint64) -> np.uint64:
    """SplitMix64 finaliser of one uint64 (wrapping arithmetic)."""
    z = x + GOLDEN
    z = (z ^ (z >> _S30)) * MIX1
    z = (z ^ (z >> _S27)) * MIX2
    return z ^ (z >> _S31)


@njit(cache=True, nogil=True, error_model="numpy")
def splitmix_uniforms(key: np.uint64, start: int, out: NDArray[np.float64]) -> None:
    """Uniform numbers in [0, 1) (53 random bits each) number ``start`` onwards of the SplitMix64
    sequence whose state starts at ``key`` (Steele, Lea and Flood 2014: state k is
    ``key + (k + 1) GOLDEN``, output its finaliser), into ``out`` (n,). A counter-based stream:
    any stretch of it is computed independently of the others."""
    state = key + np.uint64(start) * GOLDEN
    for i in range(out.size):
        out[i] = np.float64(splitmix64(state) >> _S11) * 2.0**-53
        state += GOLDEN


@njit(cache=True, nogil=True, error_model="numpy")
def _speckle(x: float, y: float, z: float, per_cell: float, seed_hash: np.uint64) -> tuple[float, float]:
    """|X| and arg X of the speckle factor of the point (x, y, z) (m); ``per_cell`` = 1 / cell
    (1/m): the cube's integer coordinates are floor(x per_cell) (three products instead of
    three divisions; the cubes' faces move by an ulp, the factor stays a function of the
    position)."""
    kx = np.uint64(np.int64(math.floor(x * per_cell)))
    ky = np.uint64(np.int64(math.floor(y * per_cell)))
    kz = np.uint64(np.int64(math.floor(z * per_cell)))
    h = splitmix64(((kx * PRIME_X) ^ (ky * PRIME_Y) ^ (kz * PRIME_Z)) ^ seed_hash)
    # two independent 32-bit uniforms from the high and low halves of the 64-bit hash
    u1 = np.float64(h >> _S32) * 2.0**-32
    u2 = np.float64(h & _LOW32) * 2.0**-32
    # |X|^2 ~ Exp(1) (-log(1 - u1), u1 < 1), phase uniform in [-pi, pi). u1 is a multiple of
    # 2^-32, so 1 - u1 is exact in float64 and log (correctly rounded to < 1 ulp) gives
    # -log(1 - u1) as accurately as log1p would, at half its cost (log1p was 80 % of this
    # function's time)
    return math.sqrt(-math.log(1.0 - u1)), _TWO_PI * u2 - math.pi


@njit(cache=True, nogil=True, error_model="numpy")
def speckle_into(x: NDArray[np.float64], y: NDArray[np.float64], z: NDArray[np.float64], cell: float,
                 seed_hash: np.uint64, magnitude: NDArray[np.float64], phase: NDArray[np.float64]) -> None:
    """Speckle magnitude and phase (n,) of the points (n,) x 3 (m), written into the outputs.

    ``seed_hash`` is ``splitmix64(seed)``; ``cell`` the side of the cubes sharing a factor (m).
    """
    per_cell = 1.0 / cell
    for i in range(x.size):
        m, a = _speckle(x[i], y[i], z[i], per_cell, seed_hash)
        magnitude[i] = m
        phase[i] = a


@njit(cache=True, nogil=True, error_model="numpy")
def guide_table(mass: NDArray[np.float64], guide: NDArray[np.int16], counts: NDArray[np.int64]) -> None:
    """The equiprobable bins of a tabulated density: bin i (of ``guide.size``) gets the first
    cell whose cumulative ``mass`` (non-decreasing) exceeds (i + 1/2) mass[-1] / guide.size
    (at most the last cell), as ``numpy.searchsorted(mass, quantiles, side="right")`` would,
    in one linear merge of the sorted quantiles with the cells; ``counts`` (n_cells,) gets the
    bins of each cell (``numpy.bincount(guide, minlength=n_cells)``)."""
    n_cells = mass.size
    step = mass[n_cells - 1] / guide.size
    counts[:] = 0
    cell = 0
    for i in range(guide.size):
        quantile = (i + 0.5) * step
        while cell < n_cells and mass[cell] <= quantile:
            cell += 1
        chosen = min(cell, n_cells - 1)
        guide[i] = chosen
        counts[chosen] += 1


@njit(cache=True, nogil=True, error_model="numpy")
def cell_table(lobe_pdf: NDArray[np.float64], uniform_density: float, lobe_count: float,
               out: NDArray[np.float64]) -> None:
    """Per cell of the lobe table, the solid angle 1 / (N_u / 4 pi + N_l p_lobe) of a ray drawn
    in it, into ``out`` (n_cells,) (64 KiB for 8192 cells: the table a uniform ray gathers
    from at random, kept small for the cache).

    ``lobe_pdf`` (n_cells,): as in :class:`~acoustisim.propagation.diffuse._LobeTable`;
    ``uniform_density`` = N_u / (4 pi), ``lobe_count`` = N_l.
    """
    for cell in range(lobe_pdf.size):
        out[cell] = 1.0 / (uniform_density + lobe_count * lobe_pdf[cell])


AZIMUTH_BITS = 10
"""The azimuth table of :func:`unit_azimuth` has 2**AZIMUTH_BITS entries (16 KiB, in L1)."""


def azimuth_table() -> NDArray[np.float64]:
    """cos and sin of the azimuths 2 pi k / 2**AZIMUTH_BITS, shape (2**AZIMUTH_BITS, 2) (a new
    array: the table :func:`unit_azimuth` rotates from)."""
    phi = np.arange(1 << AZIMUTH_BITS) * (2.0 * math.pi / (1 << AZIMUTH_BITS))
    return np.ascontiguousarray(np.stack([np.cos(phi), np.sin(phi)], axis=1))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def unit_azimuth(u: float, table: NDArray[np.float64]) -> tuple[float, float]:
    """cos(phi) and sin(phi) of phi = 2 pi u (u in [0, 1)), without a trigonometric call.

    phi = phi_k + delta with phi_k = 2 pi k / 2**AZIMUTH_BITS (``table`` row k, from
    :func:`azimuth_table`) and 0 <= delta < 2 pi / 1024 = 6.1e-3; cos(delta) and sin(delta) by
    their Taylor series to delta^4 and delta^5 (truncation below delta^6 / 720 = 7.5e-17 and
    delta^7 / 5040 = 6.5e-20, under the float64 rounding), then the angle-sum rotation. The
    pair is within a few 1e-16 of (cos phi, sin phi) and of unit length to as much (tested
    against numpy's cos and sin): about 3 ns instead of about 30 for math.cos and math.sin.
    """
    x = u * table.shape[0]  # exact for a power of two
    k = int(x)
    delta = (x - k) * (_TWO_PI / table.shape[0])
    d2 = delta * delta
    cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0))
    sd = delta * (1.0 - d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0)))
    ck, sk = table[k, 0], table[k, 1]
    return ck * cd - sk * sd, sk * cd + ck * sd


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _transmit_direction(i: int, u_theta: float, u_phi: float, n_uniform: int, guide: NDArray[np.int16],
                        cells: NDArray[np.float64], width: float, azimuth: NDArray[np.float64],
                        e1: NDArray[np.float64], e2: NDArray[np.float64], axis: NDArray[np.float64],
                        directions: NDArray[np.float64], solid_angle: NDArray[np.float64]) -> None:
    """Ray ``i``'s direction and solid angle from its two uniform numbers (see
    :func:`transmit_directions`)."""
    n_cells = cells.shape[0]
    if i < n_uniform:
        cos_t = 1.0 - 2.0 * u_theta
        cell = min(int((1.0 - cos_t) * (n_cells / 2.0)), n_cells - 1)
    else:
        x = u_theta * guide.size  # exact for a power of two
        b = int(x)
        cell = np.int64(guide[b])
        # the cell's upper edge 1 - cell width (exact: width = 2 / n_cells, a power of two)
        cos_t = (1.0 - cell * width) - (x - b) * width
    sin_t = math.sqrt(max(1.0 - cos_t * cos_t, 0.0))
    cp, sp = unit_azimuth(u_phi, azimuth)
    a = sin_t * cp
    c = sin_t * sp
    for k in range(3):
        directions[k, i] = a * e1[k] + c * e2[k] + cos_t * axis[k]
    solid_angle[i] = cells[cell]


@njit(cache=True, nogil=True, error_model="numpy")
def transmit_directions(
    u: NDArray[np.float64], n_uniform: int, guide: NDArray[np.int16], cells: NDArray[np.float64], width: float,
    azimuth: NDArray[np.float64], e1: NDArray[np.float64], e2: NDArray[np.float64], axis: NDArray[np.float64],
    directions: NDArray[np.float64], solid_angle: NDArray[np.float64],
) -> None:
    """Directions of the transmitted rays from their random numbers, and their solid angles.

    Parameters
    ----------
    u : ndarray, shape (2, n)
        Uniform numbers in [0, 1). Row 0 places cos(theta): cos(theta) = 1 - 2u for the first
        ``n_uniform`` rays; for the others the integer part of u len(guide) picks a guide bin,
        hence a cell (cos(theta) descending from 1), and the fractional part the place in the
        cell. Row 1 is the azimuth in turns (:func:`unit_azimuth`).
    guide : ndarray of int16
        As in :class:`~acoustisim.propagation.diffuse._LobeTable`.
    cells : ndarray, shape (n_cells,)
        The solid angle of each cell's rays (:func:`cell_table`); cell k spans cos(theta)
        from 1 - k width downwards.
    width : float
        The cells' width in cos(theta) (2 / n_cells, a power of two).
    azimuth : ndarray, shape (2**AZIMUTH_BITS, 2)
        :func:`azimuth_table`.
    e1, e2, axis : ndarray, shape (3,)
        The transmitter's orthonormal frame.
    directions : output, shape (3, >= n)
    solid_angle : output, shape (>= n,)
    """
    n = u.shape[1]
    for i in range(n):
        _transmit_direction(i, u[0, i], u[1, i], n_uniform, guide, cells, width, azimuth, e1, e2, axis, directions,
                            solid_angle)


@njit(cache=True, nogil=True, error_model="numpy")
def draw_transmit_directions(
    key: np.uint64, start: int, n: int, n_uniform: int, guide: NDArray[np.int16], cells: NDArray[np.float64],
    width: float, azimuth: NDArray[np.float64], e1: NDArray[np.float64], e2: NDArray[np.float64],
    axis: NDArray[np.float64], directions: NDArray[np.float64], solid_angle: NDArray[np.float64],
) -> None:
    """:func:`transmit_directions` of the uniform numbers ``start`` to ``start + 2n - 1`` of
    the SplitMix64 stream ``key`` (as :func:`splitmix_uniforms` would write them into ``u``
    (2, n)), drawn in the same loop: no array of random numbers. Ray i's are numbers
    ``start + i`` and ``start + n + i``."""
    for i in range(n):
        u_theta = np.float64(splitmix64(key + np.uint64(start + i) * GOLDEN) >> _S11) * 2.0**-53
        u_phi = np.float64(splitmix64(key + np.uint64(start + n + i) * GOLDEN) >> _S11) * 2.0**-53
        _transmit_direction(i, u_theta, u_phi, n_uniform, guide, cells, width, azimuth, e1, e2, axis, directions,
                            solid_angle)


@njit(cache=True, nogil=True, error_model="numpy")
def scatter_and_pair(
    triangle: NDArray[np.int32], directions: NDArray[np.float64], origins: NDArray[np.float64],
    weight: NDArray[np.float64], travelled: NDArray[np.float64], parent: NDArray[np.int32],
    departure: NDArray[np.float64], tri_mu: NDArray[np.float64], tri_normal: NDArray[np.float64],
    tri_offset: NDArray[np.float64], tri_surface: NDArray[np.int64], cell: float, seed_hash: np.uint64,
    receivers: NDArray[np.float64], tested: NDArray[np.bool_], screen: int, lo: NDArray[np.float64],
    hi: NDArray[np.float64], own_box: NDArray[np.int64], wedges: NDArray[np.float64],
    point_wedges: NDArray[np.float64], plane_start: NDArray[np.int64],
    plane_normal: NDArray[np.float64], plane_offset: NDArray[np.float64], shift: NDArray[np.float64], eps: float,
    shared: bool, keep: bool, first_row: int,
    points: NDArray[np.float64], normal: NDArray[np.float64],
    out_departure: NDArray[np.float64], out_weight: NDArray[np.float64],
    out_travelled: NDArray[np.float64], out_parent: NDArray[np.int32], surface: NDArray[np.int32],
    out_bounce: NDArray[np.int32], bounce_number: int, mu: NDArray[np.float64], phase: NDArray[np.float64],
    state: NDArray[np.int8], pair_gain: NDArray[np.float64], leg_start: NDArray[np.float32],
    leg_unit: NDArray[np.float32], leg_length: NDArray[np.float32], leg_pair: NDArray[np.int64],
    reception_row: int, event: NDArray[np.int32], channel: NDArray[np.int8], gain: NDArray[np.float64],
) -> tuple[int, int, int, int]:
    """Compact the rays that scatter, solve their hits, and decide every (hit, receiver) pair:
    its geometry, exact occlusion by the convex objects, and the legs Embree must test.

    Parameters
    ----------
    triangle : ndarray of int32, shape (m,)
        Embree's hit triangle of each ray (-1: none).
    directions, departure : ndarray, shape (3, m)
        Unit ray directions; the direction each ray left the transmitter.
    origins : ndarray, shape (3, m) or (3, 1)
        Ray origins (m); one column is shared by every ray.
    weight, travelled : ndarray, shape (m,)
        Solid angle (x albedo products) and path length so far (m) of each ray.
    parent : ndarray of int32, shape (m,) or (1,)
        The event each ray comes from (-1: the transmitter); one entry is shared by every ray.
    tri_mu, tri_offset : ndarray, shape (n_triangles,)
        Lambert mu of each triangle's surface and its plane offset n . v0 (m).
    tri_normal : ndarray, shape (3, n_triangles)
    tri_surface : ndarray of int64, shape (n_triangles,)
    cell, seed_hash
        As in :func:`speckle_into`.
    receivers : ndarray, shape (n_rx, 3)
    tested : ndarray of bool, shape (n_rx,)
        Receivers whose legs are tested for occlusion.
    screen : int
        0: no leg can be blocked (no objects); 1: screen each leg with the boxes ``lo``, ``hi``
        (k, 3) and decide it with the face planes of the convex objects (see below); 2: every
        leg may be blocked (Embree tests it).
    own_box : ndarray of int64, shape (n_surfaces,)
        The box row skipped for a point on each surface (-1: none).
    wedges : ndarray, shape (n_rx, k, 6)
        Each receiver's wedges of the boxes
        (:func:`~acoustisim.propagation.diffuse.receiver_wedges`).
    point_wedges : ndarray, shape (k, 8)
        The boxes' wedges shared by all the receivers
        (:func:`~acoustisim.propagation.diffuse.shared_wedges`), tested once per point.
    plane_start, plane_normal, plane_offset
        Face planes of the box rows (row b's are ``plane_start[b]:plane_start[b + 1]``, see
        :class:`~acoustisim.propagation.convex_occlusion.ConvexPlanes`).
    shift : ndarray, shape (3,)
        Subtracted from the leg starts (Embree's frame).
    eps : float
        Each leg is shrunk by ``eps`` (m) at both ends; shorter than 2 eps: never blocked.
    shared : bool
        One receiver's leg decides for all (``"centre"`` visibility): a leg blocked by a
        convex object clears every pair of its point (Embree's answers are applied so by
        :func:`clear_blocked`).
    keep : bool
        The rays continue (another bounce follows): write ``normal``, ``out_weight`` and ``mu``.
    first_row : int
        The row of ``points``, ``out_departure``, ``out_travelled``, ``out_parent``,
        ``surface`` and ``phase`` (the tracer's output arrays) where the first kept ray goes.
    points, out_departure : outputs, shape (>= first_row + m, 3)
        The kept rays' hit points and departure directions, from row ``first_row`` on.
    normal : output, shape (3, >= m)
    out_weight, mu : outputs, shape (>= m,)
        The kept rays' normals, weights and mu, from index 0 (with ``keep`` only).
    out_travelled, out_parent, surface, out_bounce, phase : outputs, shape (>= first_row + m,)
        The kept rays' path lengths to the hit, parents, surfaces, scattering order
        (``bounce_number``) and speckle phases, from row ``first_row`` on.
    state : output, shape (>= m n_rx,), point-major
        Per pair: 0 (receiver behind the face, or leg blocked by a convex object), 1 (clear),
        2 (leg queued for Embree).
    pair_gain : output, shape (>= m n_rx,), point-major
        Per pair in front of the face (state > 0 on return): the reception's gain
        |X| sqrt(mu weight) sqrt(r2 sin(g_s) / r2^3) (other entries are left unwritten), for
        :func:`write_receptions`.
    leg_start, leg_unit : outputs of float32, shape (>= m n_rx, 3)
    leg_length : output of float32, shape (>= m n_rx,)
    leg_pair : output of int64, shape (>= m n_rx,)
        The queued legs (Embree buffers) and their pair index.
    reception_row : int
        >= 0 when no leg can be left to Embree (no leg buffers): each point's pairs in view are
        written as receptions (event ``first_row + point``, channel, gain; as
        :func:`write_receptions` would write them) into ``event``, ``channel`` and ``gain``
        from this index on, as soon as the point is decided (-1: left to
        :func:`write_receptions`, after Embree's answers).
    event, channel, gain : outputs, shape (>= reception_row + in_view,)

    With one box only (the union of too many objects to screen one by one), a leg crossing it
    goes to Embree. Otherwise each object's box (rows 1:, skipping the convex object the point
    lies on: a leg towards a receiver in front of the face cannot re-enter it) is tested: the
    point against the box's wedge shared by the receivers (once per point), then the leg's
    direction against the box's wedge seen from the receiver, then the slab test; a leg
    crossing the box of an object with face planes is decided exactly on the leg shrunk by
    ``eps`` at both ends (:func:`~acoustisim.propagation.convex_occlusion.segment_crosses_convex`);
    one crossing the box of any other object, unless a convex one blocks it, goes to Embree.

    Returns
    -------
    (int, int, int, int)
        The number h of kept rays (a surface with mu > 0 hit from its front), written first
        in the outputs, in ray order; the legs queued for Embree; the legs decided by the
        convex objects' face planes; the pairs with their receiver in view (state > 0).
    """
    one_origin = origins.shape[1] == 1
    n_rx = receivers.shape[0]
    n_boxes = lo.shape[0]
    per_cell = 1.0 / cell
    n_legs = 0
    n_exact = 0
    in_view = 0
    h = 0
    for ray in range(triangle.size):
        t = triangle[ray]
        if t < 0:
            continue
        m = tri_mu[t]
        if not m > 0.0:
            continue
        nx, ny, nz = tri_normal[0, t], tri_normal[1, t], tri_normal[2, t]
        dx, dy, dz = directions[0, ray], directions[1, ray], directions[2, ray]
        cos_in = dx * nx + dy * ny + dz * nz
        if not cos_in < 0.0:
            continue
        o = 0 if one_origin else ray
        ox, oy, oz = origins[0, o], origins[1, o], origins[2, o]
        # the hit on the triangle's plane, in float64 (Embree only chose the triangle)
        distance = (tri_offset[t] - (nx * ox + ny * oy + nz * oz)) / cos_in
        px, py, pz = ox + distance * dx, oy + distance * dy, oz + distance * dz
        row = first_row + h
        points[row, 0], points[row, 1], points[row, 2] = px, py, pz
        out_departure[row, 0], out_departure[row, 1], out_departure[row, 2] = (
            departure[0, ray], departure[1, ray], departure[2, ray])
        w = weight[ray]
        magnitude, angle = _speckle(px, py, pz, per_cell, seed_hash)
        phase[row] = angle
        point_amplitude = magnitude * math.sqrt(w * m)  # |X| sqrt(mu dOmega)
        out_travelled[row] = (travelled[0] if travelled.size == 1 else travelled[ray]) + distance
        out_parent[row] = parent[0] if parent.size == 1 else parent[ray]
        out_bounce[row] = bounce_number
        s = tri_surface[t]
        surface[row] = s
        if keep:
            normal[0, h], normal[1, h], normal[2, h] = nx, ny, nz
            out_weight[h] = w
            mu[h] = m
        # next-event estimation to every receiver
        i = h
        own = own_box[s]
        hidden = False  # a leg of this point blocked by a convex object
        # the boxes a leg from this point to some receiver may cross, as a bit mask (not the
        # convex object the point lies on)
        candidates = 0
        if screen == 1:
            for b in range(1, n_boxes):
                if (b != own
                        and point_wedges[b, 0] * px + point_wedges[b, 1] * py + point_wedges[b, 2] * pz
                        >= point_wedges[b, 3]
                        and point_wedges[b, 4] * px + point_wedges[b, 5] * py + point_wedges[b, 6] * pz
                        >= point_wedges[b, 7]):
                    candidates |= np.int64(1) << b
        for j in range(n_rx):
            pair = i * n_rx + j
            qx, qy, qz = receivers[j, 0], receivers[j, 1], receivers[j, 2]
            dx, dy, dz = qx - px, qy - py, qz - pz
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            c = dx * nx + dy * ny + dz * nz
            if not c > 0.0:
                state[pair] = 0
                continue
            state[pair] = 1
            pair_gain[pair] = point_amplitude * math.sqrt(c / (length * length * length))
            in_view += 1
            if not tested[j] or screen == 0 or not length > 2.0 * eps:
                continue
            if screen == 1:
                # 0: clear (no box crossed); 1: blocked by a convex object; 2: Embree must test
                # it; 3: clear, found so by the planes of the convex objects whose boxes it crosses
                verdict = 0
                if n_boxes == 1:  # the union of too many objects only
                    if _slab(px, py, pz, 1.0 / dx, 1.0 / dy, 1.0 / dz, lo[0, 0], lo[0, 1], lo[0, 2], hi[0, 0],
                             hi[0, 1], hi[0, 2]):  # +-inf for a zero component
                        verdict = 2
                for b in range(1, n_boxes if candidates else 1):
                    if not (candidates >> b) & 1:
                        continue
                    # the wedge seen from the receiver: e = -(dx, dy, dz), receiver -> point
                    if (wedges[j, b, 0] * dx + wedges[j, b, 1] * dy + wedges[j, b, 2] * dz > 0.0
                            or wedges[j, b, 3] * dx + wedges[j, b, 4] * dy + wedges[j, b, 5] * dz > 0.0):
                        continue
                    if not _slab(px, py, pz, 1.0 / dx, 1.0 / dy, 1.0 / dz, lo[b, 0], lo[b, 1], lo[b, 2], hi[b, 0],
                                 hi[b, 1], hi[b, 2]):
                        continue
                    first, last = plane_start[b], plane_start[b + 1]
                    if first == last:
                        verdict = 2
                    elif segment_crosses_convex(px, py, pz, dx / length, dy / length, dz / length, eps,
                                                length - eps, plane_normal, plane_offset, first, last):
                        verdict = 1
                        break
                    elif verdict == 0:
                        verdict = 3
                if verdict == 0:
                    continue
                if verdict != 2:  # decided by the convex objects' planes
                    n_exact += 1
                    if verdict == 1:
                        state[pair] = 0
                        in_view -= 1
                        hidden = True
                    continue
            state[pair] = 2
            if n_legs == leg_pair.size:  # the caller allocated no room: an internal error
                raise RuntimeError("scatter_and_pair: a leg left to Embree without a buffer for it")
            inverse = 1.0 / length
            ux, uy, uz = dx * inverse, dy * inverse, dz * inverse
            leg_start[n_legs, 0] = px + eps * ux - shift[0]
            leg_start[n_legs, 1] = py + eps * uy - shift[1]
            leg_start[n_legs, 2] = pz + eps * uz - shift[2]
            leg_unit[n_legs, 0], leg_unit[n_legs, 1], leg_unit[n_legs, 2] = ux, uy, uz
            leg_length[n_legs] = length - 2.0 * eps
            leg_pair[n_legs] = pair
            n_legs += 1
        if shared and hidden:
            for j in range(n_rx):
                if state[i * n_rx + j] != 0:
                    state[i * n_rx + j] = 0
                    in_view -= 1
        if reception_row >= 0:  # every pair of this point is decided: its receptions, as write_receptions
            for j in range(n_rx):
                pair = i * n_rx + j
                if state[pair] != 0:
                    event[reception_row] = row
                    channel[reception_row] = j
                    gain[reception_row] = pair_gain[pair]
                    reception_row += 1
        h += 1
    return h, n_legs, n_exact, in_view


@njit(cache=True, nogil=True, error_model="numpy")
def _near(px: float, py: float, pz: float, own: int, qx: float, qy: float, qz: float, lo: NDArray[np.float64],
          hi: NDArray[np.float64]) -> bool:
    """Whether the segment p -> q meets the union box lo[0], hi[0] and then one of the boxes
    lo[1:], hi[1:] other than row ``own`` (or the union alone when it is the only box): the
    slab test of :class:`~acoustisim.propagation.diffuse.ObjectScreen`, in float64."""
    sx, sy, sz = qx - px, qy - py, qz - pz
    for b in range(lo.shape[0]):
        if b == own:
            continue
        enter, leave = 0.0, 1.0
        for k in range(3):
            s = sx if k == 0 else (sy if k == 1 else sz)
            p = px if k == 0 else (py if k == 1 else pz)
            if abs(s) < 1e-30:  # parallel to the slab: inside it or not
                if p < lo[b, k] or p > hi[b, k]:
                    enter, leave = 1.0, 0.0
                continue
            t1 = (lo[b, k] - p) / s
            t2 = (hi[b, k] - p) / s
            if t1 > t2:
                t1, t2 = t2, t1
            enter = max(enter, t1)
            leave = min(leave, t2)
        crossing = enter <= leave
        if b == 0:
            if not crossing:
                return False
            if lo.shape[0] == 1:
                return True
        elif crossing:
            return True
    return False


@njit(cache=True, nogil=True, error_model="numpy")
def near_points(x: NDArray[np.float64], y: NDArray[np.float64], z: NDArray[np.float64], own: NDArray[np.int64],
                end: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64],
                out: NDArray[np.bool_]) -> None:
    """:func:`_near` of the segments from the points (n,) x 3 (each skipping box ``own`` (n,))
    to ``end`` (3,), into ``out`` (n,)."""
    for i in range(x.size):
        out[i] = _near(x[i], y[i], z[i], own[i], end[0], end[1], end[2], lo, hi)


@njit(cache=True, nogil=True, error_model="numpy")
def _slab(px: float, py: float, pz: float, ix: float, iy: float, iz: float, lx: float, ly: float, lz: float,
          hx: float, hy: float, hz: float) -> bool:
    """Whether the segment p + s t, 0 <= t <= 1, meets the box [l, h], given the inverses
    ``ix, iy, iz`` = 1 / s of the segment's components (+-inf for a 0: then the slab's bounds
    give +-inf, or NaN when p lies on the slab's face, which the comparisons ignore, a
    grazing contact). Scalar arguments only: array arguments would cost reference-count
    updates at every call."""
    t1 = (lx - px) * ix
    t2 = (hx - px) * ix
    enter = min(t1, t2)
    leave = max(t1, t2)
    t1 = (ly - py) * iy
    t2 = (hy - py) * iy
    enter = max(enter, min(t1, t2))
    leave = min(leave, max(t1, t2))
    t1 = (lz - pz) * iz
    t2 = (hz - pz) * iz
    enter = max(enter, min(t1, t2))
    leave = min(leave, max(t1, t2))
    return max(enter, 0.0) <= min(leave, 1.0)


@njit(cache=True, nogil=True, error_model="numpy")
def clear_blocked(state: NDArray[np.int8], leg_pair: NDArray[np.int64], blocked: NDArray[np.bool_], shared: bool,
                  n_rx: int, h: int) -> int:
    """Apply Embree's occlusion answers to the pair states; count the receptions.

    A queued leg found ``blocked`` clears its pair (state 0), or with ``shared`` (one
    receiver's leg decides for all) every pair of its point.

    Returns
    -------
    int
        The pairs of the first ``h`` points left with their receiver in view (state > 0).
    """
    for l in range(blocked.size):
        if blocked[l]:
            pair = leg_pair[l]
            if shared:
                point = pair // n_rx
                for j in range(n_rx):
                    state[point * n_rx + j] = 0
            else:
                state[pair] = 0
    count = 0
    for pair in range(h * n_rx):
        if state[pair] != 0:
            count += 1
    return count


@njit(cache=True, nogil=True, error_model="numpy")
def copy_chunk(n_events: int, n_receptions: int, first_event: int, first_reception: int,
               points: NDArray[np.float64], departure: NDArray[np.float64], surface: NDArray[np.int32],
               parent: NDArray[np.int32], bounce: NDArray[np.int32], travelled: NDArray[np.float64],
               phase: NDArray[np.float64], event: NDArray[np.int32], channel: NDArray[np.int8],
               gain: NDArray[np.float64], to_points: NDArray[np.float64], to_departure: NDArray[np.float64],
               to_surface: NDArray[np.int32], to_parent: NDArray[np.int32], to_bounce: NDArray[np.int32],
               to_travelled: NDArray[np.float64], to_phase: NDArray[np.float64], to_event: NDArray[np.int32],
               to_channel: NDArray[np.int8], to_gain: NDArray[np.float64]) -> None:
    """Copy one chunk's events (rows 0 to ``n_events``) and receptions (0 to ``n_receptions``),
    written into a scratch block, to rows ``first_event`` and ``first_reception`` onwards of
    the output (the ``to_`` arrays), shifting the event indices they hold (parents >= 0, the
    receptions' events) by ``first_event``.

    ``points``, ``departure`` and theirs: shape (M, 3); the others (M,) for the events, (N,)
    for the receptions.
    """
    for i in range(n_events):
        b = first_event + i
        for k in range(3):
            to_points[b, k] = points[i, k]
            to_departure[b, k] = departure[i, k]
        to_surface[b] = surface[i]
        p = parent[i]
        to_parent[b] = p + first_event if p >= 0 else p
        to_bounce[b] = bounce[i]
        to_travelled[b] = travelled[i]
        to_phase[b] = phase[i]
    for i in range(n_receptions):
        b = first_reception + i
        to_event[b] = event[i] + first_event
        to_channel[b] = channel[i]
        to_gain[b] = gain[i]


@njit(cache=True, nogil=True, error_model="numpy")
def write_receptions(h: int, n_rx: int, state: NDArray[np.int8], pair_gain: NDArray[np.float64], first_event: int,
                     start: int, event: NDArray[np.int32], channel: NDArray[np.int8],
                     gain: NDArray[np.float64]) -> int:
    """The pairs in view (state > 0), point-major, as receptions written from index ``start``.

    Each gives event ``first_event + point``, its channel and the gain
    |X| sqrt(mu dOmega) sqrt(r2 sin(g_s) / r2^3) that :func:`scatter_and_pair` computed for the
    pair (``pair_gain``); the path length, the speckle phase and the arrival direction follow
    from the event and the receiver (:func:`reception_columns`).

    Returns
    -------
    int
        The index after the last reception written.
    """
    k = start
    for i in range(h):
        for j in range(n_rx):
            pair = i * n_rx + j
            if state[pair] == 0:
                continue
            event[k] = first_event + i
            channel[k] = j
            gain[k] = pair_gain[pair]
            k += 1
    return k


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _leg(px: float, py: float, pz: float, qx: float, qy: float, qz: float) -> tuple[float, float, float, float]:
    """The length r2 (m) and unit direction of the leg p -> q, computed as the tracer computes
    them (the same operations: the same values)."""
    dx, dy, dz = qx - px, qy - py, qz - pz
    r = math.sqrt(dx * dx + dy * dy + dz * dz)
    inverse = 1.0 / r
    return r, dx * inverse, dy * inverse, dz * inverse


@njit(cache=True, nogil=True, error_model="numpy")
def reception_columns(points: NDArray[np.float64], travelled: NDArray[np.float64], event_phase: NDArray[np.float64],
                      event: NDArray[np.int32], channel: NDArray[np.int8], receivers: NDArray[np.float64],
                      length: NDArray[np.float64], phase: NDArray[np.float64], arrival: NDArray[np.float64]) -> None:
    """Per reception (n,): the path length travelled + r2 (m), the speckle phase (rad) and the
    unit arrival direction (n, 3) point -> receiver, from the events' points (m, 3), path
    lengths to the point and phases (m,) and the receivers (n_rx, 3); an output of size 0 is
    skipped."""
    for k in range(event.size):
        e, j = event[k], channel[k]
        r, ax, ay, az = _leg(points[e, 0], points[e, 1], points[e, 2], receivers[j, 0], receivers[j, 1],
                             receivers[j, 2])
        if length.size:
            length[k] = travelled[e] + r
        if phase.size:
            phase[k] = event_phase[e]
        if arrival.size:
            arrival[k, 0], arrival[k, 1], arrival[k, 2] = ax, ay, az


@njit(cache=True, nogil=True, error_model="numpy")
def pack_rows(
    rows: NDArray, start: int, stop: int, first_path_id: int, kind: int, event: NDArray[np.int32],
    channel: NDArray[np.int8], gain: NDArray[np.float64], travelled: NDArray[np.float64], phase: NDArray[np.float64],
    receivers: NDArray[np.float64], points: NDArray[np.float64], surface: NDArray[np.int32],
    parent: NDArray[np.int32], bounce: NDArray[np.int32], departure: NDArray[np.float64],
) -> None:
    """Write receptions ``start:stop`` as rows of the arrivals table (``paths.PATH_DTYPE``).

    Every field of each row is written once, row after row (the rows are 243 bytes wide: a
    numpy assignment per field would stream over all of them a dozen times): ``path_id`` =
    ``first_path_id`` + event, channel, ``kind``, ``order`` = the event's bounce, the path
    length, gain, phase, departure and arrival directions, and the interaction chain (the
    surfaces and points of the event and its parents, first hit first, -1 / NaN padded); the
    derived columns (delay, angles, directivities, absorption, amplitude) are zeroed, for
    ``complete_columns``.

    Parameters
    ----------
    rows : structured ndarray of PATH_DTYPE, shape (>= stop,)
    event, channel, gain : ndarray, shape (n,)
        The receptions (:class:`~acoustisim.propagation.diffuse.DiffuseEvents`).
    travelled, phase : ndarray, shape (m,)
        The events' path lengths to the point (m) and speckle phases (rad).
    receivers : ndarray, shape (n_rx, 3)
        For the path lengths and arrival directions (as :func:`reception_columns` computes
        them).
    points, departure : ndarray, shape (m, 3)
    surface, parent, bounce : ndarray of int32, shape (m,)
        The scattering events.
    """
    slots = rows[0].object_ids.size if rows.size else 0
    for i in range(start, stop):
        row = rows[i]
        e = event[i]
        j = channel[i]
        order = bounce[e]
        row.path_id = first_path_id + e
        row.channel = j
        row.kind = kind
        row.order = order
        row.delay_s = 0.0
        r, ax, ay, az = _leg(points[e, 0], points[e, 1], points[e, 2], receivers[j, 0], receivers[j, 1],
                             receivers[j, 2])
        row.path_length_m = travelled[e] + r
        row.geometric_gain = gain[i]
        row.phase_rad = phase[e]
        row.angle_tx_rad = 0.0
        row.angle_rx_rad = 0.0
        row.directivity_tx = 0.0
        row.directivity_rx = 0.0
        row.absorption_db = 0.0
        row.amplitude = 0.0
        row.arrival_dir[0], row.arrival_dir[1], row.arrival_dir[2] = ax, ay, az
        for k in range(3):
            row.departure_dir[k] = departure[e, k]
        for slot in range(slots):
            row.object_ids[slot] = -1
            for k in range(3):
                row.points_m[slot, k] = np.nan
        current, level = e, order - 1
        while current >= 0 and level >= 0:  # walk back to the first hit
            if level < slots:
                row.object_ids[level] = surface[current]
                for k in range(3):
                    row.points_m[level, k] = points[current, k]
            current = parent[current]
            level -= 1


__all__ = [
    "reception_columns",
    "guide_table",
    "pack_rows",
    "copy_chunk",
    "cell_table", "clear_blocked", "near_points", "scatter_and_pair", "speckle_into", "splitmix64", "splitmix_uniforms",
    "transmit_directions", "write_receptions", "AZIMUTH_BITS", "azimuth_table", "draw_transmit_directions",
    "unit_azimuth",
]
