"""The transducers' beam as a filter on an echo: piston directivity and the echo's expected spectrum.

A real sonar's echo is not the transmitted pulse: per frequency f it is filtered by the
transmitter's and the receiver's far-field directivities at the angles they see the target,

    E_c(f) = Q(f) D_tx(f, theta_tx) D_c(f, theta_c),     D(f, theta) = 2 J1(x) / x,
    x = (2 pi f / c) a sin(theta)

for a baffled circular piston of radius a (``physics.md`` section 2; 0 behind the face). Off
axis this low-passes the echo and, past the 500 kHz first null (11.1 deg for a 19 mm piston),
changes the sign of part of its band: the envelope peak of the correlation with the plain
template moves by microseconds. A vertical edge is an extended target: its echo is the
line integral (Biot-Tolstoy-Medwin, ``physics.md`` section 4)

    E_c(f) = Q(f) Int beta D_tx(f, theta_tx(z)) D_c(f, theta_c(z)) exp(-j 2 pi f (tau_c(z) - tau_c*)) / (m l) dz

over the points z of the edge, m and l their distances to the transmitter and the receiver,
tau_c(z) = (m + l) / c and tau_c* its least value (the geometric time of flight). Without
directivity it is the half-integrated pulse, whose envelope peaks at tau_c* exactly (a constant
-45 deg phase and a real spectral tilt do not move it); the beam trims the edge's late,
off-axis part (its Fresnel zone's outer rings), which moves the plain matched filter's peak
early by nanoseconds at 1-2.5 m. ``expected_response`` returns the factor H_c(f) = E_c(f) / Q(f)
referred to tau_c*, so that a template filtered by it peaks at the geometric time of flight.

The wedge factor beta depends on z through cosh(eta) = (m l + (z - z_S)(z - z_R)) / (r_S r_R)
(1 + 2 z^2 / r^2 for source and receiver at the head's height, range r). By default it is taken
constant: over the 16 us of excess delay the integral covers (z < (c r 16 us)^(1/2), 0.15 r at
1 m) nu eta stays below 0.19 for the 60-degree prism (nu = 0.6) and beta changes by under 4 %
(7 % at 0.5 m), smoothly and symmetrically in z, most of it where the tail's taper already
weighs the points down. At closer range the covered part of the edge
reaches z ~ 0.5 r and beta falls by up to 30 % along it: ``BeamModelConfig.wedge_interior_angle_deg``
then weighs each point by the rigid wedge's beta (``wedge_beta``, the wedge's bisector toward
the transmitter). Measured on the simulator's noise-free edge echo: without it the refined TOF
is within 7.5 ns at 0.1 m, 1 ns at 0.3 m, 0.35 ns from 0.6 m on; with it within 0.7 ns at every
range.

binsonar never imports the simulator: this is the pipeline's own model of its transducers,
described by the user (``PistonTransducers``, e.g. from the V318's datasheet), the same formula
as the simulator's (a test of the experiments checks they agree).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.localization.beam_types import EdgePoints, FrequencyLattice, JincTable, PistonRadii
from binsonar.errors import InputError

TargetClass = Literal["point", "vertical-edge"]
TARGET_CLASSES: tuple[str, ...] = ("point", "vertical-edge")


def _unit(vector: ArrayLike, where: str) -> tuple[float, float, float]:
    v = np.asarray(vector, dtype=float).ravel()
    if v.shape != (3,) or not np.all(np.isfinite(v)) or float(np.linalg.norm(v)) == 0.0:
        raise InputError(f"{where} must be a non-zero 3-vector, got {vector!r}")
    v = v / np.linalg.norm(v)
    return float(v[0]), float(v[1]), float(v[2])


@dataclass(frozen=True)
class PistonTransducers:
    """The head's three transducers as baffled circular pistons (a user description, e.g. a datasheet).

    Attributes
    ----------
    diameters_m : tuple of 3 float
        Active diameter 2a of each channel's piston (m), left, centre, right (the Panametrics V318:
        19 mm).
    axes_head : tuple of three 3-tuples
        Unit acoustic axis of each channel in the head frame (normalised on construction);
        default the boresight (0, 1, 0) for all.
    transmitter_channel : int
        The channel whose transducer transmits (its piston is D_tx).
    """

    diameters_m: tuple[float, float, float]
    axes_head: tuple[tuple[float, float, float], ...] = ((0.0, 1.0, 0.0),) * 3
    transmitter_channel: int = 1

    def __post_init__(self) -> None:
        diameters = tuple(float(v) for v in np.asarray(self.diameters_m, dtype=float).ravel())
        if len(diameters) != 3 or not all(math.isfinite(v) and v > 0.0 for v in diameters):
            raise InputError(f"transducers: diameters_m must be 3 finite numbers > 0 (m), got {self.diameters_m!r}")
        object.__setattr__(self, "diameters_m", diameters)
        axes = tuple(self.axes_head)
        if len(axes) != 3:
            raise InputError(f"transducers: axes_head must hold 3 axes, got {self.axes_head!r}")
        object.__setattr__(self, "axes_head", tuple(_unit(a, f"transducers: axes_head[{i}]") for i, a in enumerate(axes)))
        if self.transmitter_channel not in (0, 1, 2):
            raise InputError(f"transducers: transmitter_channel must be 0, 1 or 2, got {self.transmitter_channel!r}")

    @classmethod
    def uniform(cls, diameter_m: float, axis_head: tuple[float, float, float] = (0.0, 1.0, 0.0),
                transmitter_channel: int = 1) -> "PistonTransducers":
        """Three equal pistons of diameter ``diameter_m`` (m) sharing one axis (head frame)."""
        return cls((diameter_m,) * 3, (tuple(axis_head),) * 3, transmitter_channel)  # type: ignore[arg-type]

    @property
    def radii_m(self) -> NDArray[np.float64]:
        """Piston radii a (3,) (m)."""
        return 0.5 * np.asarray(self.diameters_m)

    @property
    def axes(self) -> NDArray[np.float64]:
        """Unit axes (3, 3), rows left, centre, right (head frame)."""
        return np.asarray(self.axes_head, dtype=float)


@dataclass(frozen=True)
class BeamModelConfig:
    """How the expected echo is modelled.

    Attributes
    ----------
    target : {"point", "vertical-edge"}
        "point": one reflecting point (posts, spheres seen as points: the directivities at its
        angles); "vertical-edge": the beam-weighted line integral along a straight edge through
        the point (a prism's sharp edge).
    edge_direction_head : tuple of 3 float
        Direction of the edge in the head frame (normalised); (0, 0, 1) for a vertical edge and
        a level head.
    edge_tail_s : float
        The line integral covers the edge's points whose delay exceeds the least one by up to
        this (s); a cos^2 taper over its second half ends it smoothly. Past ~15 us the band-passed
        half-integrator's tail is a few % of its onset and the pulse-long correlation peak no longer
        sees it.
    phase_step_cycles : float
        Largest change of the phase f (tau(z) - tau*) between neighbouring points of the line
        integral at the highest frequency (cycles): 1/16 keeps the midpoint rule's error below
        (2 pi / 16)^2 / 24 = 0.6 % per cell at that frequency, far less in the band's centre.
    step_frequency_hz : float or None
        The frequency (Hz) ``phase_step_cycles`` refers to; None: the highest one asked for.
        ``refine_tofs`` sets the template's -30 dB top: above it the template weighs the
        midpoint rule's larger phase error by less than 3 %.
    wedge_interior_angle_deg : float or None
        The edge is a rigid wedge of this interior angle (deg) whose bisector points at the
        transmitter (a prism's edge facing the sonar): the BTM factor beta(eta, theta_S, theta_R)
        then weighs each point of the line integral (``wedge_beta``). None: beta constant
        (module docstring), enough beyond about 0.5 m.
    """

    target: TargetClass = "vertical-edge"
    edge_direction_head: tuple[float, float, float] = (0.0, 0.0, 1.0)
    edge_tail_s: float = 16e-6
    phase_step_cycles: float = 1.0 / 16.0
    step_frequency_hz: float | None = None
    wedge_interior_angle_deg: float | None = None

    def __post_init__(self) -> None:
        if self.target not in TARGET_CLASSES:
            raise InputError(f"beam model: target must be one of {', '.join(TARGET_CLASSES)}, got {self.target!r}")
        object.__setattr__(self, "edge_direction_head", _unit(self.edge_direction_head, "beam model: edge_direction_head"))
        if not (math.isfinite(self.edge_tail_s) and self.edge_tail_s > 0.0):
            raise InputError(f"beam model: edge_tail_s must be > 0 (s), got {self.edge_tail_s!r}")
        if not (math.isfinite(self.phase_step_cycles) and 0.0 < self.phase_step_cycles <= 0.25):
            raise InputError(f"beam model: phase_step_cycles must be in (0, 0.25], got {self.phase_step_cycles!r}")
        if self.step_frequency_hz is not None and not (math.isfinite(self.step_frequency_hz)
                                                      and self.step_frequency_hz > 0.0):
            raise InputError(f"beam model: step_frequency_hz must be > 0 (Hz), got {self.step_frequency_hz!r}")
        if self.wedge_interior_angle_deg is not None and not (math.isfinite(self.wedge_interior_angle_deg)
                                                             and 0.0 < self.wedge_interior_angle_deg < 180.0):
            raise InputError("beam model: wedge_interior_angle_deg must be in (0, 180) deg, got "
                                 f"{self.wedge_interior_angle_deg!r}")


def piston_directivity(angle_rad: ArrayLike, frequency_hz: ArrayLike, radius_m: ArrayLike,
                       sound_speed_m_s: float) -> NDArray[np.float64]:
    """One-way far-field pressure directivity 2 J1(x)/x, x = (2 pi f / c) a sin(angle), of a baffled piston.

    Parameters
    ----------
    angle_rad : array_like
        Angle off the piston's axis (rad); 0 beyond 90 deg (nothing radiates behind the baffle).
    frequency_hz : array_like
        Frequency (Hz), broadcast with ``angle_rad`` and ``radius_m``.
    radius_m : array_like
        Piston radius a (m).
    sound_speed_m_s : float

    Returns
    -------
    ndarray
        Signed directivity, the broadcast shape.
    """
    from scipy.special import j1

    angle = np.asarray(angle_rad, dtype=float)
    x = 2.0 * np.pi * np.asarray(frequency_hz, dtype=float) * np.asarray(radius_m, dtype=float) * np.sin(angle)
    x = x / float(sound_speed_m_s)
    small = np.abs(x) < 1e-8
    safe = np.where(small, 1.0, x)
    # 2 J1(x)/x = 1 - x^2/8 + O(x^4): the series is exact to 1e-17 below |x| = 1e-8.
    value = np.where(small, 1.0 - 0.125 * x * x, 2.0 * j1(safe) / safe)
    return np.where(np.cos(angle) >= 0.0, value, 0.0)


JINC_STEP = 1.0 / 64.0
"""Spacing of the 2 J1(x)/x table in x: linear interpolation's error is below h^2 max|J''| / 8 = 1e-5."""


def jinc_table(x_max: float) -> JincTable:
    """2 J1(x)/x on [0, x_max + 2 steps] every ``JINC_STEP``."""
    grid = np.arange(int(math.ceil(max(x_max, 0.0) / JINC_STEP)) + 3) * JINC_STEP
    return JincTable(JINC_STEP, grid, piston_directivity(0.5 * np.pi, grid, 1.0, 2.0 * np.pi))


def off_axis_angles(points_m: NDArray[np.float64], origin_m: NDArray[np.float64],
                    axis: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angles (rad) between ``axis`` (unit, (3,)) and the directions from ``origin_m`` (3,) to ``points_m`` (..., 3)."""
    v = np.asarray(points_m, dtype=float) - origin_m
    cos = (v @ axis) / np.linalg.norm(v, axis=-1)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def expected_response(frequency_hz: NDArray[np.float64], target_m: ArrayLike, transmitter_m: ArrayLike,
                      receivers_m: ArrayLike, transducers: PistonTransducers, sound_speed_m_s: float,
                      config: BeamModelConfig = BeamModelConfig()) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """The beam's (and for an edge, the line integral's) factor on each channel's echo, and its reference delays.

    Parameters
    ----------
    frequency_hz : ndarray, shape (k,)
        Frequencies (Hz, >= 0).
    target_m : array_like, shape (3,)
        The hypothesised point (head frame, m): the point target, or the edge's point nearest the
        head (any point of the edge's line: the least-time point is found per channel).
    transmitter_m : array_like, shape (3,)
        Transmitter face centre (head frame, m).
    receivers_m : array_like, shape (3, 3)
        Receiver face centres, rows left, centre, right (head frame, m).
    transducers : PistonTransducers
    sound_speed_m_s : float
    config : BeamModelConfig

    Returns
    -------
    response : ndarray, shape (3, k), complex
        H_c(f): the echo of channel c is the template filtered by it and delayed by
        ``delay_s[c]``. For a point, D_tx D_c (real); for an edge, the line integral normalised by
        its value without directivity at the centre frequency of the band (only its shape matters).
    delay_s : ndarray, shape (3,)
        The geometric (least-time) time of flight of each channel (s).
    """
    f = np.asarray(frequency_hz, dtype=float)
    p = np.asarray(target_m, dtype=float)
    tx = np.asarray(transmitter_m, dtype=float)
    rx = np.asarray(receivers_m, dtype=float)
    c = float(sound_speed_m_s)
    radii = transducers.radii_m
    axes = transducers.axes
    itx = transducers.transmitter_channel
    if config.target == "point":
        delay = (np.linalg.norm(p - tx) + np.linalg.norm(p - rx, axis=1)) / c
        d_tx = piston_directivity(off_axis_angles(p, tx, axes[itx]), f, radii[itx], c)  # (k,)
        angles = np.array([off_axis_angles(p, rx[ch], axes[ch]) for ch in range(3)])
        d_rx = piston_directivity(angles[:, np.newaxis], f, radii[:, np.newaxis], c)  # (3, k)
        return (d_tx * d_rx).astype(complex), delay
    return _edge_response(f, p, tx, rx, radii, axes, itx, c, config)


def _edge_response(f: NDArray[np.float64], p: NDArray[np.float64], tx: NDArray[np.float64], rx: NDArray[np.float64],
                   radii: NDArray[np.float64], axes: NDArray[np.float64], itx: int, c: float,
                   config: BeamModelConfig) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """The vertical-edge line integral per channel (see ``expected_response``)."""
    e = np.asarray(config.edge_direction_head, dtype=float)
    # Distances of the transmitter and receivers from the edge's line and their positions along it.
    z_tx = float((tx - p) @ e)
    r_tx = float(np.linalg.norm(tx - p - z_tx * e))
    z_rx = (rx - p) @ e  # (3,)
    r_rx = np.linalg.norm(rx - p - z_rx[:, np.newaxis] * e, axis=1)
    # Least time: unfold the two legs into a plane (Fermat): z* = z_S + (z_R - z_S) r_S / (r_S + r_R).
    z_star = z_tx + (z_rx - z_tx) * r_tx / (r_tx + r_rx)
    delay = np.sqrt((r_tx + r_rx) ** 2 + (z_rx - z_tx) ** 2) / c
    # Excess delay ~ s^2 / (2 c rho), 1/rho = 1/r_S + 1/r_R (s = z - z*): the tail ends at
    # s_max; the grid step keeps f_max d(tau)/ds h below phase_step_cycles at s_max.
    rho = 1.0 / (1.0 / r_tx + 1.0 / r_rx)
    tail = config.edge_tail_s
    s_max = np.sqrt(2.0 * c * rho * tail) * 1.05  # a little past the taper's end (the parabola overstates s)
    f_step = config.step_frequency_hz if config.step_frequency_hz is not None else (float(f.max()) if f.size else 0.0)
    slope_max = s_max / (c * rho)  # d(tau)/ds at s_max (s/m), an upper bound of the true slope
    step = config.phase_step_cycles / max(f_step * float(slope_max.max()), 1e-30)
    n_side = max(int(np.ceil(float(s_max.max()) / step)), 4)
    u = (np.arange(-n_side, n_side) + 0.5) / n_side  # midpoints on [-1, 1], (n,)
    s = u[np.newaxis, :] * s_max[:, np.newaxis]  # (3, n) per channel
    z = z_star[:, np.newaxis] + s
    points = p + z[..., np.newaxis] * e  # (3, n, 3)
    m = np.linalg.norm(points - tx, axis=-1)
    l = np.linalg.norm(points - rx[:, np.newaxis, :], axis=-1)
    excess = (m + l) / c - delay[:, np.newaxis]  # (3, n) >= 0
    taper = np.clip((tail - excess) / (0.5 * tail), 0.0, 1.0)
    taper = np.sin(0.5 * np.pi * taper) ** 2  # 1 up to tail / 2, 0 from tail on
    weight = taper * (s_max / n_side)[:, np.newaxis] / (m * l)  # (3, n): BTM's 1 / (m l) dz
    if config.wedge_interior_angle_deg is not None:
        weight = weight * wedge_beta(config.wedge_interior_angle_deg, e, p, tx, rx, z, m, l, z_tx, r_tx, z_rx, r_rx)
    sin_tx = np.sin(off_axis_angles(points, tx, axes[itx]))  # (3, n)
    sin_rx = np.sin(np.stack([off_axis_angles(points[ch], rx[ch], axes[ch]) for ch in range(3)]))  # (3, n)
    front = ((points - tx) @ axes[itx] >= 0.0) & (np.einsum("cnj,cj->cn", points - rx[:, np.newaxis, :], axes) >= 0.0)
    weight = np.where(front, weight, 0.0)  # nothing behind a baffle
    jinc = jinc_table(2.0 * np.pi * (float(f.max()) if f.size else 1.0) * float(radii.max()) / c)
    edge = EdgePoints(*(np.ascontiguousarray(a, dtype=float) for a in (weight, excess, sin_tx, sin_rx)))
    piston_radii = PistonRadii(float(radii[itx]), np.ascontiguousarray(radii, dtype=float))
    df = np.diff(f)
    if f.size > 1 and np.allclose(df, df[0], rtol=1e-9, atol=0.0) and df[0] > 0:
        from binsonar.localization.beam_kernels import edge_line_integral

        response = edge_line_integral(edge, piston_radii, FrequencyLattice(float(f[0]), float(df[0]), int(f.size)),
                                      float(c), jinc)
    else:
        response = edge_line_integral_numpy(edge, piston_radii, f, c, jinc)
    # Scale: the integral without directivity at the band's middle frequency (shape is what matters).
    f_mid = 0.5 * float(f.max()) if f.size else 1.0
    scale = np.abs(np.einsum("cn,cn->c", weight, np.exp(-2j * np.pi * excess * f_mid)))
    return response / np.maximum(scale, 1e-300)[:, np.newaxis], delay


def wedge_beta(interior_angle_deg: float, e: NDArray[np.float64], p: NDArray[np.float64], tx: NDArray[np.float64],
               rx: NDArray[np.float64], z: NDArray[np.float64], m: NDArray[np.float64], l: NDArray[np.float64],
               z_tx: float, r_tx: float, z_rx: NDArray[np.float64], r_rx: NDArray[np.float64]) -> NDArray[np.float64]:
    """The rigid wedge's BTM factor beta (3, n) along the edge (``physics.md`` section 4), its bisector toward the transmitter.

    beta = sum over phi in {pi +/- theta_S +/- theta_R} of sin(nu phi) / (cosh(nu eta) - cos(nu phi)),
    nu = pi / theta_w (theta_w = 360 deg - the interior angle, the water side), angles from one
    face through the water (the transmitter on the bisector: theta_S = theta_w / 2; a receiver at
    azimuth psi about the edge from it: theta_w / 2 + psi), and
    cosh(eta) = (m l + (z - z_S)(z - z_R)) / (r_S r_R). The denominator is computed as
    2 sinh^2(nu eta / 2) + 2 sin^2(nu phi / 2) (no cancellation).

    Parameters
    ----------
    interior_angle_deg : float
    e, p, tx : ndarray, shape (3,)
        Edge direction (unit), a point of the edge, the transmitter (head frame, m).
    rx : ndarray, shape (3, 3)
    z : ndarray, shape (3, n)
        Positions along the edge from p (m), per channel.
    m, l : ndarray, shape (3, n)
        Distances to the transmitter and the receiver (m).
    z_tx, r_tx : float
        The transmitter's position along the edge and distance from it (m).
    z_rx, r_rx : ndarray, shape (3,)
    """
    theta_w = 2.0 * np.pi - math.radians(interior_angle_deg)
    nu = np.pi / theta_w
    perp_tx = (tx - p) - ((tx - p) @ e) * e
    b = perp_tx / np.linalg.norm(perp_tx)
    side = np.cross(e, b)
    perp_rx = (rx - p) - ((rx - p) @ e)[:, np.newaxis] * e
    psi = np.arctan2(perp_rx @ side, perp_rx @ b)  # (3,) receivers' azimuths from the bisector
    theta_s = 0.5 * theta_w
    theta_r = 0.5 * theta_w + psi
    cosh_eta = (m * l + (z - z_tx) * (z - z_rx[:, np.newaxis])) / (r_tx * r_rx[:, np.newaxis])
    eta = np.arccosh(np.maximum(cosh_eta, 1.0))
    total = np.zeros_like(eta)
    for sign_s, sign_r in ((1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)):  # the four images, not data
        phi = np.pi + sign_s * theta_s + sign_r * theta_r[:, np.newaxis]
        den = 2.0 * np.sinh(0.5 * nu * eta) ** 2 + 2.0 * np.sin(0.5 * nu * phi) ** 2
        total += np.sin(nu * phi) / np.maximum(den, 1e-300)
    return total


def edge_line_integral_numpy(points: EdgePoints, radii: PistonRadii, frequency_hz: NDArray[np.float64],
                             sound_speed_m_s: float, jinc: JincTable) -> NDArray[np.complex128]:
    """H (c, k) = sum_n w D(x_tx) D(x_rx) exp(-j 2 pi f e) with (c, n, k) temporaries, any frequencies.

    The definition ``beam_kernels.edge_line_integral`` computes on equally spaced frequencies
    (same table, same interpolation); arguments as there, ``frequency_hz`` of shape (k,).
    """
    kappa = 2.0 * np.pi * np.asarray(frequency_hz, dtype=float) / sound_speed_m_s
    grid, table = jinc.grid, jinc.values
    beam = np.interp((radii.transmitter_m * points.sin_tx)[..., np.newaxis] * kappa, grid, table)
    beam *= np.interp((radii.receivers_m[:, np.newaxis] * points.sin_rx)[..., np.newaxis] * kappa, grid, table)
    phase = np.exp(-2j * np.pi * points.excess_s[..., np.newaxis] * np.asarray(frequency_hz, dtype=float))
    return np.einsum("cn,cnk->ck", points.weight, beam * phase)


__all__ = (
    "BeamModelConfig", "PistonTransducers", "TARGET_CLASSES", "edge_line_integral_numpy", "expected_response",
    "jinc_table", "off_axis_angles", "piston_directivity", "wedge_beta",
)
