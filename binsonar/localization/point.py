"""Point reflectors: exact range and bearing from two path lengths, and a general WLS solver.

Seed geometry (``physics.md`` section 7): transmitter at the origin, left receiver at x = -d,
right receiver at x = +d, target at (r sin(theta), r cos(theta)). The bistatic path lengths
(eq. 4.29) are

    R1 = r + sqrt(r^2 + d^2 + 2 r d sin(theta))     (left),
    R2 = r + sqrt(r^2 + d^2 - 2 r d sin(theta))     (right).

Derivation of the inverse: (R1 - r)^2 = r^2 + d^2 + 2 r d s gives R1^2 - 2 R1 r = d^2 + 2 r d s,
and likewise R2^2 - 2 R2 r = d^2 - 2 r d s (s = sin(theta)). Their sum gives the range

    r = (R1^2 + R2^2 - 2 d^2) / (2 (R1 + R2))                                       (4.30, exact)

and their difference (R1 - R2)(R1 + R2 - 2 r) = 4 r d s with R1 + R2 - 2 r =
2 (R1 R2 + d^2) / (R1 + R2), hence

    sin(theta) = (R1 - R2)(R1 R2 + d^2) / (d (R1^2 + R2^2 - 2 d^2)).

The seed's printed eq. 4.31 has the denominator d (R1 R2 - 2 d^2), about half the correct one:
it returns about twice sin(theta) (a true 5 deg reads 10.05 deg at r = 1 m, d = 65 mm).
``seed_bearing_eq_4_31`` keeps that erratum available for documentation and tests only.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.fit import INVALID_INPUT, ModelFit, weighted_least_squares

ArrayPair = tuple[NDArray[np.float64], NDArray[np.float64]]

# Status values of a seed-geometry point solution.
POINT_OK = "ok"
NOT_FINITE = "not-finite"
SHORTER_THAN_BASELINE = "shorter-than-baseline"
DIFFERENCE_TOO_LARGE = "path-difference-exceeds-baseline"


def seed_path_lengths(range_m: ArrayLike, bearing_rad: ArrayLike, separation_m: ArrayLike) -> ArrayPair:
    """Forward model, eq. 4.29: left and right bistatic path lengths (m) of a point target.

    Parameters
    ----------
    range_m : array_like
        Distance from the transmitter (m).
    bearing_rad : array_like
        Bearing (rad), positive toward the right receiver; broadcast with ``range_m``.
    separation_m : float or array_like
        d, the transmitter-to-side-receiver distance (m), broadcast with the others.
    """
    r = np.asarray(range_m, dtype=float)
    s = np.sin(np.asarray(bearing_rad, dtype=float))
    d = np.asarray(separation_m, dtype=float)
    return r + np.sqrt(r * r + d * d + 2 * r * d * s), r + np.sqrt(r * r + d * d - 2 * r * d * s)


def seed_point_status(left_m: ArrayLike, right_m: ArrayLike, separation_m: ArrayLike) -> NDArray[np.str_]:
    """Why a pair of path lengths has no point solution ("ok" where it has one), elementwise.

    A path is at least the transmitter-receiver distance d, and |R1 - R2| <= 2 d by the triangle
    inequality; more precisely |sin(theta)| <= 1 must hold.
    """
    r1 = np.asarray(left_m, dtype=float)
    r2 = np.asarray(right_m, dtype=float)
    d = np.asarray(separation_m, dtype=float)
    shape = np.broadcast(r1, r2).shape
    status = np.full(shape, POINT_OK, dtype="<U40")
    finite = np.isfinite(r1) & np.isfinite(r2)
    with np.errstate(invalid="ignore"):
        short = finite & ((r1 <= d) | (r2 <= d))
        diff = finite & ~short & (np.abs(r1 - r2) > 2 * d)
        _, s = _raw_range_sine(r1, r2, d)
        beyond = finite & ~short & ~diff & (np.abs(s) > 1.0 + 1e-12)
    status[~finite] = NOT_FINITE
    status[short] = SHORTER_THAN_BASELINE
    status[diff | beyond] = DIFFERENCE_TOO_LARGE
    return status


def _raw_range_sine(r1: NDArray[np.float64], r2: NDArray[np.float64], d: NDArray[np.float64] | float) -> ArrayPair:
    q = r1 * r1 + r2 * r2 - 2 * d * d
    with np.errstate(invalid="ignore", divide="ignore"):
        return q / (2 * (r1 + r2)), (r1 - r2) * (r1 * r2 + d * d) / (d * q)


def point_from_path_lengths(left_m: ArrayLike, right_m: ArrayLike, separation_m: ArrayLike) -> ArrayPair:
    """Exact range and bearing of a point target in the seed geometry (vectorised).

    Parameters
    ----------
    left_m, right_m : array_like
        R1 (left) and R2 (right) bistatic path lengths, c x TOF (m); broadcast together.
    separation_m : float or array_like
        d (m), broadcast with the path lengths.

    Returns
    -------
    range_m, bearing_rad : ndarray
        NaN where ``seed_point_status`` is not "ok".
    """
    r1 = np.asarray(left_m, dtype=float)
    r2 = np.asarray(right_m, dtype=float)
    d = np.asarray(separation_m, dtype=float)
    r, s = _raw_range_sine(r1, r2, d)
    good = seed_point_status(r1, r2, d) == POINT_OK
    with np.errstate(invalid="ignore"):
        theta = np.arcsin(np.clip(s, -1.0, 1.0))
    return np.where(good, r, np.nan), np.where(good, theta, np.nan)


def seed_bearing_eq_4_31(left_m: ArrayLike, right_m: ArrayLike, separation_m: ArrayLike) -> NDArray[np.float64]:
    """The seed's PRINTED eq. 4.31 (wrong; documentation and tests only): bearing (rad), NaN if |sin| > 1."""
    r1 = np.asarray(left_m, dtype=float)
    r2 = np.asarray(right_m, dtype=float)
    d = np.asarray(separation_m, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (r1 * r2 + d * d) * (r1 - r2) / (d * (r1 * r2 - 2 * d * d))
        return np.where(np.abs(s) <= 1, np.arcsin(np.clip(s, -1, 1)), np.nan)


def seed_point_covariance(range_m: ArrayLike, bearing_rad: ArrayLike, separation_m: float,
                          left_std_m: ArrayLike, right_std_m: ArrayLike) -> NDArray[np.float64]:
    """Covariance (..., 2, 2) of (range_m, bearing_rad) from independent path-length errors.

    Linearised: C = A^-1 diag(s1^2, s2^2) A^-T with A = d(R1, R2)/d(r, theta) from eq. 4.29.
    """
    r = np.asarray(range_m, dtype=float)
    th = np.asarray(bearing_rad, dtype=float)
    d = np.asarray(separation_m, dtype=float)
    s, c = np.sin(th), np.cos(th)
    rho1 = np.sqrt(r * r + d * d + 2 * r * d * s)
    rho2 = np.sqrt(r * r + d * d - 2 * r * d * s)
    a = np.empty(np.broadcast(r, th).shape + (2, 2))
    a[..., 0, 0] = 1 + (r + d * s) / rho1
    a[..., 0, 1] = r * d * c / rho1
    a[..., 1, 0] = 1 + (r - d * s) / rho2
    a[..., 1, 1] = -r * d * c / rho2
    with np.errstate(all="ignore"):
        ainv = np.linalg.inv(a)
    sig = np.zeros(a.shape)
    sig[..., 0, 0] = np.asarray(left_std_m, dtype=float) ** 2
    sig[..., 1, 1] = np.asarray(right_std_m, dtype=float) ** 2
    return ainv @ sig @ np.swapaxes(ainv, -1, -2)


def bistatic_path_lengths(position_m: ArrayLike, transmitters_m: ArrayLike, receivers_m: ArrayLike) -> ArrayPair:
    """Bistatic path lengths |p - T_k| + |p - R_k| of a point for m paths, and their gradient.

    Parameters
    ----------
    position_m : array_like, shape (3,)
        Reflector (m).
    transmitters_m, receivers_m : array_like, shape (m, 3)
        Endpoints of each path, in the same frame (m).

    Returns
    -------
    lengths_m : ndarray, shape (m,)
    gradient : ndarray, shape (m, 3)
        d L_k / d p = u_T + u_R, with u the unit vectors from T_k and R_k to p.
    """
    p = np.asarray(position_m, dtype=float)
    vt = p - np.atleast_2d(np.asarray(transmitters_m, dtype=float))
    vr = p - np.atleast_2d(np.asarray(receivers_m, dtype=float))
    nt = np.linalg.norm(vt, axis=1)
    nr = np.linalg.norm(vr, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        grad = vt / nt[:, None] + vr / nr[:, None]
    return nt + nr, grad


def point_path_lengths(position_m: ArrayLike, geometry: ArrayGeometry) -> ArrayPair:
    """Bistatic path lengths (3,) of a point reflector for the head's receivers, and their gradient (3, 3).

    Parameters
    ----------
    position_m : array_like, shape (3,)
        Reflector (head frame, m).
    geometry : ArrayGeometry
    """
    return bistatic_path_lengths(position_m, np.broadcast_to(geometry.transmitter_m, (3, 3)), geometry.receivers_m)


def range_bearing_from_position(position_m: ArrayLike, covariance: ArrayLike,
                                geometry: ArrayGeometry) -> tuple[float, float, float, float]:
    """Range from the transmitter (m) and bearing atan2(x, y) (deg) of a head-frame point, with stds.

    ``covariance`` is the (3, 3) covariance of the position (m^2); the stds are linearised.
    """
    v = np.asarray(position_m, dtype=float) - geometry.transmitter_m
    cov = np.asarray(covariance, dtype=float)
    rng = float(np.linalg.norm(v))
    rho2 = v[0] ** 2 + v[1] ** 2
    g_r = v / rng
    g_b = np.array([v[1] / rho2, -v[0] / rho2, 0.0])
    with np.errstate(invalid="ignore"):
        var_r = float(g_r @ cov @ g_r) if np.all(np.isfinite(cov)) else float(np.inf)
        var_b = float(g_b @ cov @ g_b) if np.all(np.isfinite(cov)) else float(np.inf)
    bearing_deg = float(np.degrees(np.arctan2(v[0], v[1])))
    return rng, bearing_deg, float(np.sqrt(abs(var_r))), float(np.degrees(np.sqrt(abs(var_b))))


def initial_point(lengths_m: ArrayLike, geometry: ArrayGeometry) -> NDArray[np.float64]:
    """A start (3,) for the point solver: the seed solution from the side channels, else boresight."""
    L = np.asarray(lengths_m, dtype=float)
    d = geometry.half_baseline_m
    mid = 0.5 * (geometry.receivers_m[0] + geometry.receivers_m[2])
    if np.isfinite(L[0]) and np.isfinite(L[2]):
        r, th = point_from_path_lengths(L[0], L[2], d)
        if np.isfinite(r) and r > 0:
            height = mid[2] - geometry.transmitter_m[2]
            return geometry.transmitter_m + np.array([r * np.sin(th), r * np.cos(th), height])
    finite = L[np.isfinite(L)]
    half = 0.5 * float(np.mean(finite)) if finite.size else np.nan
    return geometry.transmitter_m + np.array([0.0, half, 0.0])


def fit_point(
    lengths_m: ArrayLike,
    sigma_m: ArrayLike,
    geometry: ArrayGeometry,
    *,
    solve_z: bool = False,
    z_m: float | None = None,
    initial_m: ArrayLike | None = None,
) -> ModelFit:
    """Weighted least-squares point position from any subset of the three path lengths.

    Works for any array geometry (unequal offsets, receivers at different heights). Unknowns are
    (x_m, y_m) with the target's height fixed at ``z_m`` (default: the transmitter's), or
    (x_m, y_m, z_m) with ``solve_z`` (needs three path lengths and an array that is not
    collinear with the transmitter; otherwise z is not observable and gets infinite variance).

    Parameters
    ----------
    lengths_m : array_like, shape (3,)
        Path lengths left, centre, right (m); NaN for a missing channel.
    sigma_m : array_like, shape (3,)
        Their standard deviations (m).
    geometry : ArrayGeometry
    solve_z : bool
    z_m : float, optional
    initial_m : array_like, shape (3,), optional
        Start (default from ``initial_point``).

    Returns
    -------
    ModelFit
        model "point", parameters ("x_m", "y_m"[, "z_m"]) in the head frame.
    """
    L = np.asarray(lengths_m, dtype=float)
    s = np.asarray(sigma_m, dtype=float)
    names = ("x_m", "y_m", "z_m") if solve_z else ("x_m", "y_m")
    use = np.isfinite(L)
    k = len(names)
    if L.shape != (3,) or s.shape != (3,):
        return ModelFit.failed("point", names, int(L.size), INVALID_INPUT, "need three path lengths and three stds")
    if np.any(np.isinf(L)) or np.any(np.isnan(s[use])):
        return ModelFit.failed("point", names, int(use.sum()), INVALID_INPUT,
                               f"path lengths must be finite (NaN marks a missing channel), got {L.tolist()}")
    if use.sum() < k:
        return ModelFit.failed("point", names, int(use.sum()), INVALID_INPUT,
                               f"point fit needs at least {k} path lengths, got {int(use.sum())}")
    short = L[use] <= geometry.direct_distance_m()[use]
    if np.any(short):
        return ModelFit.failed("point", names, int(use.sum()), INVALID_INPUT,
                               "a path length is shorter than its transmitter-receiver distance")
    p0 = np.asarray(initial_point(L, geometry) if initial_m is None else initial_m, dtype=float)
    z_fixed = geometry.transmitter_m[2] if z_m is None else float(z_m)
    if not solve_z:
        p0 = p0.copy()
        p0[2] = z_fixed

    def predict(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        p = x if solve_z else np.array([x[0], x[1], z_fixed])
        lengths, grad = point_path_lengths(p, geometry)
        return lengths[use], grad[use][:, :k]

    return weighted_least_squares("point", names, predict, L[use], s[use], p0[:k])
