"""Lambert diffuse reverberation: Monte Carlo rays from the transmitter, next-event estimation.

Physics
-------
A rough surface scatters part of the incident sound in every direction. Lambert's law
(``physics.md`` section 5; Lambert 1760, Mackenzie 1961 for the sea floor) gives the intensity
scattered by a patch dA, at distance r2 from it, relative to the incident intensity:

    I_s / I_i = mu sin(g_i) sin(g_s) dA / r2^2,

with g_i and g_s the grazing angles of the incident and the scattered leg and mu the surface
material's Lambert coefficient (``Material.diffuse_mu``, 0 <= mu <= 1/pi: mu = 1/pi re-radiates
all the incident power). With the source's pressure 1 at 1 m (incident intensity 1 / r1^2 at
range r1), the mean-square pressure of the first-order reverberation at a receiver is

    E = Int mu sin(g_i) sin(g_s) / (r1^2 r2^2) dA                                       (1)

over the surfaces seen from both the transmitter and the receiver. Directivities and
absorption multiply each contribution as they do every other path (the derived columns,
:mod:`acoustisim.propagation.reference.columns`).

**Estimator.** N rays leave the transmitter with directions w drawn from a density p(w) (per
steradian); each carries the solid angle dOmega = 1 / (N p(w)). A ray meeting a surface at
range r1 and grazing angle g_i covers the footprint dA = r1^2 dOmega / sin(g_i), so its hit
contributes to (1)

    mu sin(g_s) dOmega / r2^2                                                           (2)

independently of r1 and g_i: each hit is a point scatterer (next-event estimation) whose
pressure factor toward a receiver in front of the surface, with the leg clear, is

    geometric_gain = |X| sqrt(mu sin(g_s) dOmega) / r2,        phase_rad = arg X,

relative to the source's pressure at 1 m (units 1/m times the 1 m reference: dimensionless
like the direct path's 1 / r). X is a circular complex Gaussian speckle factor (E|X|^2 = 1,
|X|^2 exponential, arg X uniform) frozen to the hit's world position: a hash of the
:data:`SPECKLE_CELL_M` cube holding the point and of the solver seed, so that every receiver and
every ping sees the same scatterer. The sum of geometric_gain^2 over the hits is an unbiased
estimate of (1).

**Further bounces** (``SolverConfig.diffuse_bounces`` > 1). A Lambert surface re-radiates the
power it receives with radiance proportional to cos(theta) about its normal; the ray continues
from the hit in a direction drawn from the density cos(theta) / pi, which multiplies its weight
dOmega by pi mu (the surface's albedo), and scatters again to every receiver through (2). A
surface with mu = 0 (the free surface, the ideal materials) ends the ray; coherent (specular)
reflection is the image-source solver's business.

**Rough surfaces** (``Material.roughness_rms_m`` h > 0). A rough surface's coherent reflection
keeps exp(-2 (k h sin g_i)^2) of its pressure (:mod:`acoustisim.propagation.roughness`); the
energy it loses, the fraction |R(g_i)|^2 (1 - exp(-4 (k h sin g_i)^2)) of the incident power
(R the material's plane-wave coefficient at the incidence angle), is scattered (Kirchhoff
approximation; Eckart 1953; ``physics.md`` section 8). A Lambert patch scatters pi mu of the
power incident on it (the integral of sin(g_s) over the half space is pi), so the tracer
carries that energy by scattering each hit on a rough surface with

    mu = mu_material + |R(g_i)|^2 (1 - exp(-4 (k0 h sin g_i)^2)) / pi                 (3)

(:func:`acoustisim.scattering.roughness.rough_reflection`'s Lambert mu; :func:`rough_lambert_mu`),
in the estimator (2) and in the albedo of further bounces alike, evaluated at the centre
frequency f0 (k0 = 2 pi f0 / c): the tracer is broadband, one weight per event, and the
arrivals table's levels are at f0. Energy is then conserved at f0: coherent |R|^2 chi^2 plus
diffuse |R|^2 (1 - chi^2) is the smooth surface's |R|^2 (the material's own mu scatters on
top, as on a smooth surface). Across the band the coherent loss grows with f^2 while the
diffuse weight keeps its f0 value: for the seed's pulse (rms bandwidth 118 kHz about 500 kHz)
the pulse-energy average of 1 - chi^2 differs from its f0 value by +5 % (small roughness, where
1 - chi^2 grows as f^2) to -3 % (h = 0.5 mm: the loss saturates), 0.2 dB at most.

**Sampling density.** Rays follow the mixture (``physics.md`` section 5: rays serve diffuse
energy and visibility, so the main lobe must be dense but the back and the side lobes covered)

    p(w) = s / (4 pi) + (1 - s) p_lobe(w),    p_lobe proportional to D(theta)^2, theta < 90 deg,

s = :data:`UNIFORM_FRACTION`, D = 2 J1(x) / x (x = k a sin(theta), a the piston radius) the transmit directivity at
the centre frequency. p_lobe is tabulated: D^2 at the centres of :data:`COS_CELLS` cells of
equal width in cos(theta), quantised to :data:`GUIDE_BINS` equiprobable bins (bin i goes to
the cell holding the quantile (i + 1/2) / GUIDE_BINS of the cumulative D^2), so that a cell's
probability is exactly its bins' share and each ray's pdf is known exactly. The two shares are
drawn in fixed numbers per chunk of rays (the first ``round(s n)`` uniformly), and each ray's
solid angle is the balance heuristic of multiple importance sampling (Veach 1997, eq. 9.13),

    dOmega = 1 / (N_u / (4 pi) + N_l p_lobe(w)),

N_u and N_l the rays drawn from each share over the solve: unbiased, with less variance than
drawing each ray's share at random.

**Random numbers.** The rays are taken in chunks of :data:`CHUNK_RAYS`; chunk c draws from the
SplitMix64 sequence (Steele, Lea and Flood 2014) keyed by ``splitmix64(splitmix64(seed) ^
splitmix64(c))``, number k being ``splitmix64(key + k * 0x9E3779B97F4A7C15) >> 11`` times
2^-53. The sequence is counter-based: any stretch of it is computed directly, and the fast
engine draws exactly the same numbers in its compiled loops. A chunk of n rays draws 2n numbers
for its transmitted directions (ray i: cos(theta) from number i, the azimuth from number n + i)
and, after each bounce with h hits that continue, 2h more (hit i: the radius from number i,
the azimuth from number h + i).

Method
------
Per chunk of rays, per bounce, in plain numpy:

1. the rays' directions from their random numbers (:class:`TransmitSampler`,
   :func:`lambert_directions`), in the transmitter's frame (:func:`transmitter_frame`) or the
   hit's (:func:`tangent_frame`);
2. one batched Embree INTERSECT query names each ray's hit triangle
   (:meth:`~acoustisim.propagation.raycast.RayCaster.intersect`); the hit point is solved on
   the triangle's plane in float64; rays that miss, hit a surface with mu = 0 (with (3)) or hit
   a face from behind end there;
3. every (hit, receiver) pair with the receiver in front of the face is a candidate reception;
   its leg is tested for occlusion by one batched Embree query
   (:meth:`~acoustisim.propagation.raycast.RayCaster.occluded`: the leg shrunk by
   ``DEFAULT_EPS_M`` at both ends, the scattering point's own patch excluded, since a face or a
   convex object cannot shadow a leg leaving it from its front). A first hit's leg back to a
   receiver at the transmitter (the centre transducer) retraces the ray and is not tested.
   With ``SolverConfig.diffuse_visibility = "centre"`` only the leg to the receiver nearest the
   receivers' centroid is tested, and a point hidden from it is hidden from all;
4. the hits continue (step 1) with their weights times pi mu, from 2e-5 m (:data:`OFFSET_M`)
   off the surface along the normal (not added to the path length: 14 ps).

Rows: one per (hit, receiver) reception, ``kind = DIFFUSE``, ``order`` the bounce, ``path_id``
``context.first_path_id`` plus the hit's index (chunks, then bounces, then rays, in order),
shared by the receivers of one hit; ``object_ids`` and ``points_m`` the ray's hits from the
first (:data:`~acoustisim.propagation.paths.MAX_INTERACTIONS` at most).

Accuracy
--------
Monte Carlo noise: speckle (|X|^2 exponential) doubles the variance of each hit's contribution;
rays are independent, so the relative standard deviation falls as N^-1/2. Measured: a channel's
total diffuse energy scatters by 0.9 % at 100,000 rays on a 4 m x 4 m Lambert plate 1 m ahead,
and by 2.2 % at the default 20,000 rays in the thesis tank (24 seeds). Binned in delay, the
estimate is much noisier: at 20,000 rays, between 2 and 8 ms, the centre channel's energy in a
13 us bin (1 cm of range, the pulse's length) holds about 3 hits and scatters by 115 %; in 0.1
ms bins, 22 hits and 41 %; in 1 ms bins, 280 hits and 14 %. The reverberation of one ping is
one realisation of a random field, so this is speckle of the kind a real tank shows, not an
error of the mean; averaging pings with different seeds reduces it.

Neglected: coherent scattering from facets (the Kirchhoff term; specular reflection is the
image-source solver's), the frequency and angle dependence of mu beyond Lambert's sin sin law
and (3) (the rough surfaces' scattered energy goes out by Lambert's law, where the Kirchhoff
incoherent field of a long-correlation roughness is concentrated about the specular direction),
shadowing by the roughness itself, diffraction around obstacles (a leg is clear or blocked),
the speckle's correlation length (fixed at 1 mm, a third of a wavelength at 500 kHz, instead of
following the roughness spectrum), and bounces beyond ``diffuse_bounces``.

Agreement with the fast engine (:mod:`acoustisim.propagation.fast.diffuse`): the same random
numbers, sampling tables, frames and azimuth rotation (:func:`azimuth_cos_sin`) and the same
float64 steps to every hit point, so the hit points agree to the bit and the gains to rounding
(the parity suite holds delays to 1 ps and gains to 1e-9 relative). The one possible difference:
the fast engine finds first hits and convex-object occlusion in float64 without Embree in a box
tank, where this module asks Embree, which works in float32; the two may disagree for a ray or
leg passing within ~1e-6 m of an edge (no such ray in the parity suite's thesis-tank poses).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.materials import Material
from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.directivity import piston_directivity
from acoustisim.propagation.paths import MAX_INTERACTIONS, PathKind, empty_paths_array
from acoustisim.propagation.raycast import DEFAULT_EPS_M, RayCaster

CHUNK_RAYS = 1 << 14
"""Rays per chunk: each chunk draws from its own random stream keyed by (seed, chunk index),
so the rows do not depend on how (or on how many threads) the chunks are traced."""

UNIFORM_FRACTION = 0.5
"""Share s of each chunk's rays drawn uniformly over the sphere; the rest follow D^2."""

COS_CELLS = 1 << 13
"""Cells of the tabulated lobe density, equal in cos(theta): 2.4e-4 wide, 1.3 degrees at the
axis (the main lobe's -3 dB half width is 4.6 degrees)."""

GUIDE_BINS = 1 << 16
"""Equiprobable bins of the lobe density: a cell's probability is a multiple of 1 / 65536
(D^2's share to 1.5e-5)."""

SPECKLE_CELL_M = 1e-3
"""Side of the cubes that share one speckle factor (m): a third of a wavelength at 500 kHz."""

OFFSET_M = 2e-5
"""A continuing ray starts this far off its surface, along the normal (m): 40 float32 ulps in
the tank, so that Embree does not find the surface it leaves."""

MAX_RAY_EVENTS = 10_000_000
"""Most rays x bounces one solve may trace (up to three rows each, about 250 bytes a row):
beyond it the configuration is refused rather than exhausting memory."""

SPLITMIX_GAMMA = np.uint64(0x9E3779B97F4A7C15)
"""SplitMix64's increment (the golden ratio in 64 bits)."""

SPLITMIX_MULTIPLIERS = (np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB))
"""SplitMix64's two mixing multipliers."""

SPATIAL_HASH_PRIMES = (np.uint64(0x8DA6B343), np.uint64(0xD8163841), np.uint64(0xCB1AB31F))
"""Multipliers of a speckle cube's integer coordinates (Teschner et al. 2003), odd."""


def _dot(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Row-wise a . b of (..., 3) arrays, summed x, y, z in that order (as the fast engine sums)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


# --------------------------------------------------------------------------- random numbers
def splitmix64(x: NDArray[np.uint64]) -> NDArray[np.uint64]:
    """The SplitMix64 output function of each state ``x`` (uint64 array, wrapping arithmetic).

    ``z = x + gamma; z = (z ^ z >> 30) * m1; z = (z ^ z >> 27) * m2; z ^ z >> 31``.
    """
    m1, m2 = SPLITMIX_MULTIPLIERS
    z = np.asarray(x, dtype=np.uint64) + SPLITMIX_GAMMA
    z = (z ^ (z >> np.uint64(30))) * m1
    z = (z ^ (z >> np.uint64(27))) * m2
    return z ^ (z >> np.uint64(31))


def seed_hash(seed: int) -> np.uint64:
    """``splitmix64(seed)``: the seed's part of every stream key and speckle hash."""
    return splitmix64(np.array([seed], dtype=np.uint64))[0]


def stream_key(seed: int, chunk: int) -> np.uint64:
    """The state chunk ``chunk``'s stream starts from: splitmix64(splitmix64(seed) ^ splitmix64(chunk))."""
    mixed = np.array([seed_hash(seed) ^ splitmix64(np.array([chunk], dtype=np.uint64))[0]], dtype=np.uint64)
    return splitmix64(mixed)[0]


def stream_uniforms(key: np.uint64, start: int, count: int) -> NDArray[np.float64]:
    """Numbers ``start`` to ``start + count - 1`` of the stream ``key``, uniform in [0, 1) (53 bits)."""
    states = np.uint64(key) + np.arange(start, start + count, dtype=np.uint64) * SPLITMIX_GAMMA
    return (splitmix64(states) >> np.uint64(11)).astype(np.float64) * 2.0**-53


class RayStream:
    """The uniform numbers one chunk of rays draws, in order (see the module docstring).

    Parameters
    ----------
    seed : int
        The solver seed (>= 0).
    chunk : int
        The chunk index (rays ``chunk * CHUNK_RAYS`` onwards).
    """

    def __init__(self, seed: int, chunk: int) -> None:
        self.key = stream_key(seed, chunk)
        self.drawn = 0

    def next(self, rows: int, n: int) -> NDArray[np.float64]:
        """The next ``rows * n`` numbers as an array (rows, n), filled row by row."""
        values = stream_uniforms(self.key, self.drawn, rows * n).reshape(rows, n)
        self.drawn += rows * n
        return values


# --------------------------------------------------------------------------- speckle
def speckle_polar(points_m: NDArray[np.float64], seed: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Magnitude |X| and phase arg X (rad, in [-pi, pi)) of the speckle factors of points (n, 3) (m).

    The cube of side :data:`SPECKLE_CELL_M` holding a point has integer coordinates
    ``k = floor(x / cell)`` (computed as ``floor(x * (1 / cell))``); its hash
    ``h = splitmix64((kx px) ^ (ky py) ^ (kz pz) ^ splitmix64(seed))`` gives two 32-bit uniforms
    u1 (high half) and u2 (low half): |X| = sqrt(-ln(1 - u1)) (|X|^2 exponential, mean 1) and
    arg X = 2 pi u2 - pi.
    """
    points = np.asarray(points_m, dtype=float).reshape(-1, 3)
    cube = np.floor(points * (1.0 / SPECKLE_CELL_M)).astype(np.int64).view(np.uint64)
    px, py, pz = SPATIAL_HASH_PRIMES
    h = splitmix64((cube[:, 0] * px) ^ (cube[:, 1] * py) ^ (cube[:, 2] * pz) ^ seed_hash(seed))
    u1 = (h >> np.uint64(32)).astype(np.float64) * 2.0**-32
    u2 = (h & np.uint64(0xFFFFFFFF)).astype(np.float64) * 2.0**-32
    return np.sqrt(-np.log(1.0 - u1)), 2.0 * math.pi * u2 - math.pi


def speckle(points_m: NDArray[np.float64], seed: int) -> NDArray[np.complex128]:
    """Complex speckle factors X (n,) of points (n, 3) (m): circular complex Gaussian, E|X|^2 = 1,
    equal for points in one cube of side :data:`SPECKLE_CELL_M` (see :func:`speckle_polar`)."""
    magnitude, phase = speckle_polar(points_m, seed)
    return magnitude * np.exp(1j * phase)


# --------------------------------------------------------------------------- directions
AZIMUTH_BITS = 10
"""The azimuth table of :func:`azimuth_cos_sin` has 2**AZIMUTH_BITS entries."""


def azimuth_table() -> NDArray[np.float64]:
    """cos and sin of the azimuths 2 pi k / 2**AZIMUTH_BITS, shape (2**AZIMUTH_BITS, 2)."""
    phi = np.arange(1 << AZIMUTH_BITS) * (2.0 * math.pi / (1 << AZIMUTH_BITS))
    return np.ascontiguousarray(np.stack([np.cos(phi), np.sin(phi)], axis=1))


def azimuth_cos_sin(u: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """cos(phi) and sin(phi) (n,) of the azimuths phi = 2 pi u, u (n,) in [0, 1) (turns).

    phi = phi_k + delta, phi_k = 2 pi k / 1024 from :func:`azimuth_table`, 0 <= delta < 6.1e-3
    rad; cos(delta) and sin(delta) by their Taylor series to delta^4 and delta^5 (truncation
    below 8e-17), then the angle-sum rotation: within 1e-15 of numpy's cos and sin of 2 pi u.
    Both engines evaluate the azimuth so, operation for operation, so that their hit points
    are the same to the bit: the speckle lattice's faces coincide with the tank's walls and
    floor (whole millimetres), where a difference of one rounding would change the cube.
    """
    table = azimuth_table()
    x = u * table.shape[0]  # exact: a power of two
    k = x.astype(np.int64)
    delta = (x - k) * (2.0 * math.pi / table.shape[0])
    d2 = delta * delta
    cos_delta = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0))
    sin_delta = delta * (1.0 - d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0)))
    cos_k, sin_k = table[k, 0], table[k, 1]
    return cos_k * cos_delta - sin_k * sin_delta, sin_k * cos_delta + cos_k * sin_delta


def transmitter_frame(boresight: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                                NDArray[np.float64]]:
    """(e1, e2, axis), each shape (3,): the transmitter's orthonormal frame about its unit axis.

    e1 = axis x h / |axis x h| with h = x (or y where |axis_x| >= 0.9), e2 = axis x e1.
    """
    axis = np.asarray(boresight, dtype=float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1), axis


def tangent_frame(normals: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unit tangents t1, t2 (n, 3) completing unit normals (n, 3) to orthonormal frames.

    t1 = n x h / |n x h| with h = x (or y where |n_x| >= 0.9), t2 = n x t1 (the fast engine
    builds the same frames).
    """
    n = np.asarray(normals, dtype=float)
    use_x = np.abs(n[:, 0]) < 0.9
    # n x (1, 0, 0) = (0, nz, -ny);  n x (0, 1, 0) = (-nz, 0, nx)
    t1 = np.where(use_x[:, None], np.stack([np.zeros(len(n)), n[:, 2], -n[:, 1]], axis=1),
                  np.stack([-n[:, 2], np.zeros(len(n)), n[:, 0]], axis=1))
    t1 /= np.sqrt(_dot(t1, t1))[:, None]
    t2 = np.stack([n[:, 1] * t1[:, 2] - n[:, 2] * t1[:, 1], n[:, 2] * t1[:, 0] - n[:, 0] * t1[:, 2],
                   n[:, 0] * t1[:, 1] - n[:, 1] * t1[:, 0]], axis=1)
    return t1, t2


def uniform_count(n: int) -> int:
    """Rays of a chunk of ``n`` drawn uniformly over the sphere (at least one: a lone ray is uniform)."""
    return max(1, int(round(UNIFORM_FRACTION * n))) if n else 0


def chunk_sizes(n_rays: int) -> list[int]:
    """The rays of each chunk of a solve of ``n_rays`` rays (all :data:`CHUNK_RAYS` but the last)."""
    return [min(CHUNK_RAYS, n_rays - first) for first in range(0, n_rays, CHUNK_RAYS)]


def ray_counts(n_rays: int) -> tuple[int, int]:
    """(N_u, N_l): the rays of a solve of ``n_rays`` drawn uniformly and from the lobe."""
    n_uniform = sum(uniform_count(n) for n in chunk_sizes(n_rays))
    return n_uniform, n_rays - n_uniform


def lobe_power(context: SolveContext) -> NDArray[np.float64]:
    """D(theta)^2 at the centres of the :data:`COS_CELLS` cells (cell k spans cos(theta) from
    1 - k width down, width = 2 / COS_CELLS), 0 behind the piston (the back is the uniform
    share's), shape (COS_CELLS,)."""
    edges = np.linspace(1.0, -1.0, COS_CELLS + 1)
    centres = np.arccos(0.5 * (edges[1:] + edges[:-1]))
    forward = centres < 0.5 * np.pi
    power = np.zeros(COS_CELLS)
    power[forward] = piston_directivity(centres[forward], context.centre_frequency_hz, context.piston_radius_m,
                                        context.sound_speed_m_s) ** 2
    return power


def lobe_pdf(bins: NDArray[np.int64]) -> NDArray[np.float64]:
    """p_lobe (1/sr) of a direction in each cell, shape (COS_CELLS,), from the number of
    equiprobable bins (of :data:`GUIDE_BINS`) each cell holds: a cell spans 2 pi width sr."""
    return (bins / GUIDE_BINS) / (2.0 * np.pi * (2.0 / COS_CELLS))


def cell_solid_angles(bins: NDArray[np.int64], counts: tuple[int, int]) -> NDArray[np.float64]:
    """dOmega = 1 / (N_u / 4 pi + N_l p_lobe) (sr) of a ray in each cell, shape (COS_CELLS,),
    for ``counts`` = (N_u, N_l) (the balance heuristic)."""
    n_uniform, n_lobe = counts
    return 1.0 / (n_uniform / (4.0 * np.pi) + float(n_lobe) * lobe_pdf(bins))


@dataclass(frozen=True, eq=False)
class TransmitSampler:
    """The transmitted rays' density (see the module docstring) and each ray's solid angle.

    Attributes
    ----------
    guide : ndarray of int64, shape (GUIDE_BINS,)
        The cell of each equiprobable bin of the lobe density; cell k spans cos(theta) from
        ``1 - k width`` down to ``1 - (k + 1) width``, width = 2 / COS_CELLS.
    lobe_pdf : ndarray, shape (COS_CELLS,)
        p_lobe of a direction in each cell (1/sr).
    solid_angle : ndarray, shape (COS_CELLS,)
        dOmega = 1 / (N_u / 4 pi + N_l p_lobe) of a ray in each cell (sr), uniform or lobe.
    counts : tuple of int
        (N_u, N_l): the rays drawn uniformly and from the lobe over the solve.
    """

    guide: NDArray[np.int64]
    lobe_pdf: NDArray[np.float64]
    solid_angle: NDArray[np.float64]
    counts: tuple[int, int]

    @classmethod
    def create(cls, context: SolveContext, n_rays: int) -> "TransmitSampler":
        """The sampler of ``n_rays`` rays for ``context``'s piston, centre frequency and sound speed."""
        mass = np.cumsum(lobe_power(context))
        quantiles = (np.arange(GUIDE_BINS) + 0.5) * (mass[-1] / GUIDE_BINS)
        guide = np.minimum(np.searchsorted(mass, quantiles, side="right"), COS_CELLS - 1)
        bins = np.bincount(guide, minlength=COS_CELLS)
        counts = ray_counts(n_rays)
        return cls(guide, lobe_pdf(bins), cell_solid_angles(bins, counts), counts)

    def draw(self, u: NDArray[np.float64], frame: tuple[NDArray[np.float64], ...]) -> tuple[
            NDArray[np.float64], NDArray[np.float64]]:
        """Directions (n, 3) and solid angles (n,) (sr) of one chunk's rays from their numbers.

        Parameters
        ----------
        u : ndarray, shape (2, n)
            The chunk's first 2n uniform numbers: row 0 places cos(theta), row 1 the azimuth.
            The first :func:`uniform_count` rays are uniform: cos(theta) = 1 - 2 u. The others
            follow the lobe: u GUIDE_BINS = b + f picks bin b (its cell) and, by f, the place in
            the cell.
        frame : tuple of ndarray, shape (3,)
            (e1, e2, axis) of :func:`transmitter_frame`.
        """
        n = u.shape[1]
        uniform = np.arange(n) < uniform_count(n)
        width = 2.0 / COS_CELLS
        cos_uniform = 1.0 - 2.0 * u[0]
        scaled = u[0] * GUIDE_BINS
        bins = scaled.astype(np.int64)
        lobe_cell = self.guide[bins]
        cos_lobe = (1.0 - lobe_cell * width) - (scaled - bins) * width
        cos_t = np.where(uniform, cos_uniform, cos_lobe)
        cell = np.where(uniform, np.minimum(((1.0 - cos_t) * (COS_CELLS / 2.0)).astype(np.int64), COS_CELLS - 1),
                        lobe_cell)
        sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
        cos_phi, sin_phi = azimuth_cos_sin(u[1])
        e1, e2, axis = frame
        directions = (sin_t * cos_phi)[:, None] * e1 + (sin_t * sin_phi)[:, None] * e2 + cos_t[:, None] * axis
        return directions, self.solid_angle[cell]


def lambert_directions(u: NDArray[np.float64], normals: NDArray[np.float64]) -> NDArray[np.float64]:
    """Cosine-weighted directions (n, 3) about unit normals (n, 3) (pdf cos(theta) / pi).

    ``u`` (2, n): row 0 the squared radius rho^2 of a uniform point of the unit disc (Malley's
    method: sin(theta) = rho), row 1 its azimuth in turns, in the frame of :func:`tangent_frame`.
    """
    radius = np.sqrt(u[0])
    cos_phi, sin_phi = azimuth_cos_sin(u[1])
    along_normal = np.sqrt(np.maximum(1.0 - u[0], 0.0))
    t1, t2 = tangent_frame(normals)
    return (radius * cos_phi)[:, None] * t1 + (radius * sin_phi)[:, None] * t2 + along_normal[:, None] * normals


# --------------------------------------------------------------------------- the tracer
class Rays(NamedTuple):
    """One bounce's rays (n of them).

    ``origin``, ``direction``, ``departure`` (n, 3): start (m), unit direction, and the
    direction the ray left the transmitter; ``weight`` (n,): dOmega times the albedos pi mu of
    the surfaces it left (sr); ``travelled`` (n,): path length so far (m); ``parent`` (n,): the
    hit it leaves (-1: the transmitter).
    """

    origin: NDArray[np.float64]
    direction: NDArray[np.float64]
    departure: NDArray[np.float64]
    weight: NDArray[np.float64]
    travelled: NDArray[np.float64]
    parent: NDArray[np.int64]


class Hits(NamedTuple):
    """One bounce's scattering events (h of them): the rays that hit a surface with mu > 0 from
    its front.

    ``point`` (h, 3) (m); ``normal`` (h, 3) the face's unit normal; ``surface`` and ``patch``
    (h,) the surface index (into ``scene.surface_names``) and the ray caster's patch; ``mu`` the
    hit's Lambert strength (the material's, plus (3) on a rough surface); ``weight`` (sr), ``travelled`` (m, to the point), ``departure`` (h, 3) and ``parent`` of
    the ray; ``magnitude`` and ``phase`` (rad) of the speckle factor; ``bounce`` (1 = first hit).
    """

    point: NDArray[np.float64]
    normal: NDArray[np.float64]
    surface: NDArray[np.int64]
    patch: NDArray[np.int64]
    mu: NDArray[np.float64]
    weight: NDArray[np.float64]
    travelled: NDArray[np.float64]
    departure: NDArray[np.float64]
    parent: NDArray[np.int64]
    magnitude: NDArray[np.float64]
    phase: NDArray[np.float64]
    bounce: int


class Receptions(NamedTuple):
    """The (hit, receiver) pairs heard: ``event`` (index of the hit among the solve's events),
    ``channel`` (receiver index) and ``gain`` (geometric_gain), each (k,)."""

    event: NDArray[np.int64]
    channel: NDArray[np.int64]
    gain: NDArray[np.float64]


def scatter(rays: Rays, raycaster: RayCaster, triangle_mu: NDArray[np.float64], seed: int, bounce: int,
            rough: "RoughScattering | None" = None) -> Hits:
    """The rays' scattering events: Embree names each ray's hit triangle, the point is solved on
    its plane in float64 (t = (n . v0 - n . o) / (n . d)); a ray that misses, meets a surface
    with mu = 0 (the rough surfaces' share (3) included, from ``rough``) or a face from behind
    makes no event."""
    hit = raycaster.intersect(rays.origin, rays.direction, unit_directions=True).triangle
    tri = np.where(hit >= 0, hit, 0)
    normal = raycaster.face_normals[tri]
    cos_in = _dot(rays.direction, normal)
    mu = triangle_mu[tri]
    if rough is not None:  # sin(g_i) = -cos_in on the face's front
        mu = mu + rough_lambert_mu(rough, raycaster.surface_index[tri], -cos_in)
    keep = np.flatnonzero((hit >= 0) & (mu > 0.0) & (cos_in < 0.0))
    tri, normal, cos_in, mu = tri[keep], normal[keep], cos_in[keep], mu[keep]
    origin, direction = rays.origin[keep], rays.direction[keep]
    distance = (raycaster.plane_offset[tri] - _dot(normal, origin)) / cos_in
    point = origin + distance[:, None] * direction
    magnitude, phase = speckle_polar(point, seed)
    return Hits(point, normal, raycaster.surface_index[tri], raycaster.patch_index[tri], mu,
                rays.weight[keep], rays.travelled[keep] + distance, rays.departure[keep], rays.parent[keep],
                magnitude, phase, bounce)


def receive(hits: Hits, first_event: int, receivers: NDArray[np.float64], tested: NDArray[np.bool_],
            shared: bool, raycaster: RayCaster) -> Receptions:
    """Next-event estimation: every hit's pressure factor at every receiver it can reach.

    Parameters
    ----------
    hits : Hits
        Events ``first_event`` onwards of the solve.
    receivers : ndarray, shape (n_rx, 3)
    tested : ndarray of bool, shape (n_rx,)
        The receivers whose legs are tested for occlusion (the others are clear).
    shared : bool
        A hit whose tested leg is blocked is heard by no receiver ("centre" visibility).
    raycaster : RayCaster
        For the batched occlusion query of the legs.
    """
    to_receiver = receivers[None, :, :] - hits.point[:, None, :]  # (h, n_rx, 3)
    r2 = np.sqrt(_dot(to_receiver, to_receiver))
    along_normal = _dot(to_receiver, hits.normal[:, None, :])  # r2 sin(g_s)
    facing = along_normal > 0.0
    sin_gs = along_normal / r2
    blocked = np.zeros(facing.shape, dtype=bool)
    hit_index, channel = np.nonzero(facing & tested[None, :])
    blocked[hit_index, channel] = raycaster.occluded(hits.point[hit_index], receivers[channel], eps=DEFAULT_EPS_M,
                                                     exclude_patches=hits.patch[hit_index])
    if shared:
        blocked = np.broadcast_to(np.any(blocked, axis=1, keepdims=True), blocked.shape)
    hit_index, channel = np.nonzero(facing & ~blocked)  # hit-major, as rows are ordered
    gain = (hits.magnitude[hit_index] * np.sqrt(hits.mu[hit_index] * hits.weight[hit_index]
                                                * sin_gs[hit_index, channel]) / r2[hit_index, channel])
    return Receptions(first_event + hit_index, channel, gain)


def continue_rays(hits: Hits, first_event: int, u: NDArray[np.float64]) -> Rays:
    """The hits' rays, continued in cosine-weighted directions (numbers ``u`` (2, h)) with their
    weights times pi mu, from :data:`OFFSET_M` off the surface."""
    return Rays(hits.point + OFFSET_M * hits.normal, lambert_directions(u, hits.normal), hits.departure,
                hits.weight * math.pi * hits.mu, hits.travelled,
                first_event + np.arange(hits.point.shape[0], dtype=np.int64))


def tested_receivers(context: SolveContext, visibility: str) -> NDArray[np.bool_]:
    """Whose legs are tested for occlusion, shape (2, n_rx): row 0 from first hits (not a
    receiver at the transmitter, whose leg retraces the ray), row 1 from later hits; with
    ``"centre"`` visibility only the receiver nearest the receivers' centroid."""
    tx, rx = context.transmitter_m, context.receivers_m
    tested = np.ones((2, rx.shape[0]), dtype=bool)
    tested[0] = ~np.all(rx == tx, axis=1)
    if visibility == "centre":
        reference = int(np.argmin(np.linalg.norm(rx - rx.mean(axis=0), axis=1)))
        tested[:, np.arange(rx.shape[0]) != reference] = False
    return tested


def check_ray_budget(config: SolverConfig) -> None:
    """Raise :class:`InputError` if ``diffuse_rays x diffuse_bounces`` exceeds :data:`MAX_RAY_EVENTS`."""
    if int(config.diffuse_rays) * int(config.diffuse_bounces) > MAX_RAY_EVENTS:
        raise InputError(
            f"solver.diffuse_rays = {config.diffuse_rays!r} with diffuse_bounces = {config.diffuse_bounces!r}: "
            f"more than {MAX_RAY_EVENTS} scattering events; use fewer rays"
        )


class RoughScattering(NamedTuple):
    """What the tracer needs of the rough surfaces for (3): the wavenumber ``k0`` = 2 pi f0 / c
    (1/m), each surface's ``rms_height_m`` and ``material`` (n_surfaces,: boundaries then
    objects, the ray caster's ``surface_index``), and the water's ``density_kg_m3`` and
    ``sound_speed_m_s`` for the reflection coefficients."""

    k0: float
    rms_height_m: NDArray[np.float64]
    material: tuple[Material, ...]
    density_kg_m3: float
    sound_speed_m_s: float


def rough_scattering(context: SolveContext) -> RoughScattering | None:
    """The :class:`RoughScattering` of ``context``'s scene at its centre frequency, or None when
    every surface is smooth (h = 0)."""
    scene = context.scene
    materials = tuple(b.material for b in scene.boundaries) + tuple(o.material for o in scene.objects)
    heights = np.array([m.roughness_rms_m for m in materials], dtype=float)
    if not np.any(heights > 0.0):
        return None
    c = float(context.sound_speed_m_s)
    return RoughScattering(2.0 * math.pi * float(context.centre_frequency_hz) / c, heights, materials,
                           float(context.density_kg_m3), c)


def rough_lambert_mu(rough: RoughScattering, surface: NDArray[np.int64],
                     sin_grazing: NDArray[np.float64]) -> NDArray[np.float64]:
    """The Lambert strength (3) that carries the coherent-roughness loss of hits on ``surface``
    (h,) at incidence grazing sines ``sin_grazing`` (h,): |R|^2 (1 - chi^2) / pi with
    chi = exp(-2 (k0 h sin g)^2), 0 on smooth surfaces; shape (h,).

    1 - chi^2 is evaluated as -expm1(-4 (k0 h sin g)^2), accurate for small roughness.
    """
    extra = np.zeros(np.shape(sin_grazing))
    sin_g = np.clip(np.asarray(sin_grazing, dtype=float), 0.0, 1.0)
    heights = rough.rms_height_m
    for s in np.flatnonzero(heights > 0.0):  # a loop over the rough surfaces (few)
        on = np.flatnonzero(surface == s)
        if on.size == 0:
            continue
        energy = np.abs(rough.material[s].reflection_coefficient(sin_g[on], rough.density_kg_m3,
                                                                 rough.sound_speed_m_s)) ** 2
        phase = rough.k0 * heights[s] * sin_g[on]
        extra[on] = energy * -np.expm1(-4.0 * phase * phase) / math.pi
    return extra


def triangle_mu(context: SolveContext) -> NDArray[np.float64]:
    """Lambert mu of each triangle's surface (n_triangles,)."""
    scene = context.scene
    mu_of_surface = np.array([b.material.diffuse_mu for b in scene.boundaries]
                             + [o.material.diffuse_mu for o in scene.objects], dtype=float)
    return mu_of_surface[context.raycaster.surface_index]


def diffuse_rows(context: SolveContext, config: SolverConfig, prepared: Any = None) -> NDArray[Any]:
    """Diffuse reverberation rows for one sonar pose (see the module docstring).

    Parameters
    ----------
    context : SolveContext
    config : SolverConfig
        ``diffuse_rays`` (0: no rows), ``diffuse_bounces``, ``seed``, ``diffuse_visibility``.
    prepared : PreparedScene, optional
        Unused (the tracer needs only the context's ray caster).

    Returns
    -------
    structured ndarray of PATH_DTYPE, shape (n,)
        One row per (scattering event, receiver) heard, geometric columns filled.

    Raises
    ------
    InputError
        If ``diffuse_rays x diffuse_bounces`` exceeds :data:`MAX_RAY_EVENTS`.
    """
    check_ray_budget(config)
    n_rays, bounces, seed = int(config.diffuse_rays), int(config.diffuse_bounces), int(config.seed)
    raycaster = context.raycaster
    mu = triangle_mu(context)
    rough = rough_scattering(context)
    if n_rays == 0 or raycaster.triangle_count == 0 or (rough is None and not np.any(mu > 0.0)):
        return empty_paths_array(0)
    receivers = np.asarray(context.receivers_m, dtype=float)
    tested = tested_receivers(context, config.diffuse_visibility)
    shared = config.diffuse_visibility == "centre"
    frame = transmitter_frame(context.boresight)
    sampler = TransmitSampler.create(context, n_rays)
    events: list[Hits] = []
    receptions: list[Receptions] = []
    n_events = 0
    for chunk, n in enumerate(chunk_sizes(n_rays)):
        stream = RayStream(seed, chunk)
        direction, solid_angle = sampler.draw(stream.next(2, n), frame)
        rays = Rays(np.broadcast_to(context.transmitter_m, (n, 3)), direction, direction, solid_angle, np.zeros(n),
                    np.full(n, -1, dtype=np.int64))
        for bounce in range(1, bounces + 1):
            hits = scatter(rays, raycaster, mu, seed, bounce, rough)
            h = hits.point.shape[0]
            if h == 0:
                break
            receptions.append(receive(hits, n_events, receivers, tested[min(bounce, 2) - 1], shared, raycaster))
            events.append(hits)
            if bounce < bounces:
                rays = continue_rays(hits, n_events, stream.next(2, h))
            n_events += h
    return _rows(events, receptions, receivers, context.first_path_id)


def _rows(events: list[Hits], receptions: list[Receptions], receivers: NDArray[np.float64],
          first_path_id: int) -> NDArray[Any]:
    """The arrivals-table rows of the receptions, their events' chains walked back to the first hit."""
    if not receptions:
        return empty_paths_array(0)
    point = np.concatenate([e.point for e in events])
    surface = np.concatenate([e.surface for e in events])
    parent = np.concatenate([e.parent for e in events])
    bounce = np.concatenate([np.full(e.point.shape[0], e.bounce) for e in events])
    event = np.concatenate([r.event for r in receptions])
    channel = np.concatenate([r.channel for r in receptions])
    rows = empty_paths_array(event.size)
    to_receiver = receivers[channel] - point[event]
    r2 = np.sqrt(_dot(to_receiver, to_receiver))
    rows["path_id"] = first_path_id + event
    rows["channel"] = channel
    rows["kind"] = PathKind.DIFFUSE
    rows["order"] = bounce[event]
    rows["path_length_m"] = np.concatenate([e.travelled for e in events])[event] + r2
    rows["geometric_gain"] = np.concatenate([r.gain for r in receptions])
    rows["phase_rad"] = np.concatenate([e.phase for e in events])[event]
    rows["departure_dir"] = np.concatenate([e.departure for e in events])[event]
    rows["arrival_dir"] = to_receiver / r2[:, None]
    # the chain: the event at slot order - 1, its parent before it, ... the first hit at slot 0
    current, slot = event.copy(), bounce[event] - 1
    for _ in range(int(bounce.max())):
        write = np.flatnonzero((current >= 0) & (slot < MAX_INTERACTIONS))
        rows["object_ids"][write, slot[write]] = surface[current[write]]
        rows["points_m"][write, slot[write]] = point[current[write]]
        current = np.where(current >= 0, parent[np.maximum(current, 0)], -1)
        slot = slot - 1
    return rows


__all__ = (
    "CHUNK_RAYS", "COS_CELLS", "GUIDE_BINS", "MAX_RAY_EVENTS", "OFFSET_M", "SPATIAL_HASH_PRIMES", "SPECKLE_CELL_M",
    "SPLITMIX_GAMMA", "SPLITMIX_MULTIPLIERS", "UNIFORM_FRACTION", "AZIMUTH_BITS",
    "Hits", "RayStream", "Rays", "Receptions", "RoughScattering", "TransmitSampler",
    "azimuth_cos_sin", "azimuth_table", "cell_solid_angles", "check_ray_budget", "chunk_sizes", "lobe_pdf",
    "lobe_power", "ray_counts", "continue_rays", "diffuse_rows", "lambert_directions", "receive",
    "rough_lambert_mu", "rough_scattering", "scatter",
    "seed_hash", "speckle", "speckle_polar", "splitmix64", "stream_key", "stream_uniforms", "tangent_frame",
    "tested_receivers", "transmitter_frame", "triangle_mu", "uniform_count",
)
