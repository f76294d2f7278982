"""Cylinders (circles in the horizontal plane): the seed's tri-aural approximation and the exact model.

Seed approximation (Peremans; eqs. 4.37-4.44, kept as written): each side ellipse (foci at the
transmitter and a receiver d away, major axis M) is replaced by a circle of radius equal to its
semi-minor axis, centred on a virtual monostatic sensor at -d/2, 0, +d/2::

    r1 = sqrt(Ml^2 - d^2) / 2,  r2 = Mc / 2,  r3 = sqrt(Mr^2 - d^2) / 2
    rc = (r1^2 + r3^2 - 2 r2^2 - d^2 / 2) / (4 r2 - 2 r1 - 2 r3)
    xc = (r1 - r3)(2 rc + r1 + r3) / (2 d),   yc = sqrt((rc + r2)^2 - xc^2)

It is exact algebra for the three virtual sensors but the semi-minor axis is the reflection
distance only when the reflection point is equidistant from transmitter and receiver; its radius
bias is about D tan^2(theta) + d^2 / (4 D) (``physics.md`` section 7).

Exact model (Fermat / Alhazen): the path T -> circle -> R is the shortest over the circle's points
P(phi) = C + rc (cos(phi), sin(phi)); Newton on phi from the bisector normal converges in 2-3
steps. At the reflection point with normal n and incidence angle theta_i, dL/dC = -2 cos(theta_i) n
and dL/drc = -2 cos(theta_i). A vertical cylinder seen from different heights unfolds:
L = sqrt(Lh^2 + (zT - zR)^2) with Lh the horizontal Fermat path.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.fit import INVALID_INPUT, ModelFit, weighted_least_squares
from binsonar.localization.point import fit_point

CIRCLE_PARAMETERS: tuple[str, str, str] = ("xc_m", "yc_m", "rc_m")


def tri_aural_approximation(left_m: ArrayLike, centre_m: ArrayLike, right_m: ArrayLike,
                            separation_m: float) -> tuple[NDArray[np.float64], ...]:
    """The seed's approximate circle, eqs. 4.37-4.44 as written (vectorised).

    Parameters
    ----------
    left_m, centre_m, right_m : array_like
        Ml, Mc, Mr path lengths (m).
    separation_m : float
        d, transmitter to side receiver (m).

    Returns
    -------
    xc_m, yc_m, rc_m : ndarray
        Centre and radius (m); rc may be negative and yc NaN for noisy or inconsistent data.
    """
    ml, mc, mr = (np.asarray(v, dtype=float) for v in (left_m, centre_m, right_m))
    d = float(separation_m)
    with np.errstate(invalid="ignore", divide="ignore"):
        r1 = np.sqrt(ml * ml - d * d) / 2
        r3 = np.sqrt(mr * mr - d * d) / 2
        r2 = mc / 2
        rc = (r1 * r1 + r3 * r3 - 2 * r2 * r2 - d * d / 2) / (4 * r2 - 2 * r1 - 2 * r3)
        xc = (r1 - r3) * (2 * rc + r1 + r3) / (2 * d)
        yc = np.sqrt((rc + r2) ** 2 - xc * xc)
    return xc, yc, rc


def circle_path_lengths(centre_xy_m: ArrayLike, radius_m: float, transmitters_m: ArrayLike,
                        receivers_m: ArrayLike, n_newton: int = 8) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Specular path lengths via a vertical cylinder (a circle in x, y), and their gradient.

    Parameters
    ----------
    centre_xy_m : array_like, shape (2,)
        Circle centre (m), in the frame of the transducer positions.
    radius_m : float
        Circle radius (m), >= 0.
    transmitters_m, receivers_m : array_like, shape (m, 3)
        Transmitter and receiver of each path (m).
    n_newton : int
        Newton steps on the reflection angle (quadratic convergence: 3 suffice to rounding).

    Returns
    -------
    lengths_m : ndarray, shape (m,)
        NaN where a transducer is inside the circle.
    gradient : ndarray, shape (m, 3)
        dL / d(xc, yc, rc).
    """
    c = np.asarray(centre_xy_m, dtype=float)
    rc = float(radius_m)
    tx = np.atleast_2d(np.asarray(transmitters_m, dtype=float))
    rx = np.atleast_2d(np.asarray(receivers_m, dtype=float))
    # Components relative to the centre (small arrays: explicit arithmetic, no stacking).
    tx_x, tx_y = tx[:, 0] - c[0], tx[:, 1] - c[1]
    rx_x, rx_y = rx[:, 0] - c[0], rx[:, 1] - c[1]
    dz = tx[:, 2] - rx[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        dt0, dr0 = np.hypot(tx_x, tx_y), np.hypot(rx_x, rx_y)
        phi = np.arctan2(tx_y / dt0 + rx_y / dr0, tx_x / dt0 + rx_x / dr0)   # bisector normal
        for _ in range(n_newton if rc > 0 else 0):
            cs, sn = np.cos(phi), np.sin(phi)
            atx, aty = rc * cs - tx_x, rc * sn - tx_y
            arx, ary = rc * cs - rx_x, rc * sn - rx_y
            da, db = np.hypot(atx, aty), np.hypot(arx, ary)
            ts = (-sn * atx + cs * aty) / da
            tr = (-sn * arx + cs * ary) / db
            nn = (cs * atx + sn * aty) / da + (cs * arx + sn * ary) / db
            f1 = rc * (ts + tr)
            f2 = rc * rc * ((1 - ts * ts) / da + (1 - tr * tr) / db) - rc * nn
            step = np.clip(-f1 / f2, -0.5, 0.5)
            step = np.where(np.isfinite(step), step, 0.0)
            phi = phi + step
            if np.all(np.abs(step) < 1e-15):
                break
        cs, sn = np.cos(phi), np.sin(phi)
        atx, aty = rc * cs - tx_x, rc * sn - tx_y
        arx, ary = rc * cs - rx_x, rc * sn - rx_y
        da, db = np.hypot(atx, aty), np.hypot(arx, ary)
        gx, gy = atx / da + arx / db, aty / da + ary / db
        lh = da + db
        length = np.sqrt(lh * lh + dz * dz)
        scale = lh / length
        g = np.empty((lh.size, 3))
        g[:, 0] = gx * scale                      # = -2 cos(theta_i) n at the reflection point
        g[:, 1] = gy * scale
        g[:, 2] = (cs * gx + sn * gy) * scale     # = -2 cos(theta_i)
        inside = (dt0 <= rc) | (dr0 <= rc)
    length = np.where(inside, np.nan, length)
    g[inside] = np.nan
    return length, g


def initial_circle(lengths_m: ArrayLike, sigma_m: ArrayLike, geometry: ArrayGeometry) -> NDArray[np.float64]:
    """Start (xc, yc, rc) for the exact fit: the tri-aural estimate with rc clipped to [0, 10 Mc/2].

    Falls back to the point solution with rc = 0 when the approximation has no real solution.
    """
    L = np.asarray(lengths_m, dtype=float)
    d = geometry.half_baseline_m
    xc, yc, rc = (float(v) for v in tri_aural_approximation(L[0], L[1], L[2], d))
    r2 = 0.5 * L[1]
    if np.isfinite(rc) and np.isfinite(r2):
        rc0 = float(np.clip(rc, 0.0, 10.0 * r2))
        r1 = np.sqrt(L[0] ** 2 - d * d) / 2
        r3 = np.sqrt(L[2] ** 2 - d * d) / 2
        xc0 = (r1 - r3) * (2 * rc0 + r1 + r3) / (2 * d)
        yc0 = np.sqrt(max((rc0 + r2) ** 2 - xc0 * xc0, 0.0))
        if np.all(np.isfinite([xc0, yc0])) and yc0 > 0:
            return np.array([geometry.transmitter_m[0] + xc0, geometry.transmitter_m[1] + yc0, rc0])
    pf = fit_point(L, sigma_m, geometry)
    if pf.ok:
        return np.array([pf.parameters[0], pf.parameters[1], 0.0])
    return np.full(3, np.nan)


def fit_circle(lengths_m: ArrayLike, sigma_m: ArrayLike, geometry: ArrayGeometry,
               initial: ArrayLike | None = None) -> ModelFit:
    """Exact bistatic circle (vertical cylinder) fitted to the three path lengths of one ping.

    Parameters
    ----------
    lengths_m, sigma_m : array_like, shape (3,)
        Path lengths left, centre, right and their standard deviations (m).
    geometry : ArrayGeometry
    initial : array_like, shape (3,), optional
        Start (xc, yc, rc); default ``initial_circle``.

    Returns
    -------
    ModelFit
        model "circle", parameters (xc_m, yc_m, rc_m) in the head frame, rc >= 0. With three
        path lengths the model has zero degrees of freedom; the radius's variance shows how
        (un)observable it is.
    """
    L = np.asarray(lengths_m, dtype=float)
    s = np.asarray(sigma_m, dtype=float)
    if L.shape != (3,) or not np.all(np.isfinite(L)):
        return ModelFit.failed("circle", CIRCLE_PARAMETERS, int(np.isfinite(L).sum()), INVALID_INPUT,
                               "circle fit needs all three path lengths")
    if np.any(L <= geometry.direct_distance_m()):
        return ModelFit.failed("circle", CIRCLE_PARAMETERS, 3, INVALID_INPUT,
                               "a path length is shorter than its transmitter-receiver distance")
    x0 = initial_circle(L, s, geometry) if initial is None else np.asarray(initial, dtype=float)
    tx = np.broadcast_to(geometry.transmitter_m, (3, 3))
    return fit_circle_paths(L, s, tx, geometry.receivers_m, x0)


def fit_circle_paths(lengths_m: ArrayLike, sigma_m: ArrayLike, transmitters_m: ArrayLike,
                     receivers_m: ArrayLike, initial: ArrayLike, max_nfev: int = 200) -> ModelFit:
    """Exact circle fitted to any set of bistatic paths (one ping or many poses), rc >= 0.

    Parameters
    ----------
    lengths_m, sigma_m : array_like, shape (m,)
    transmitters_m, receivers_m : array_like, shape (m, 3)
        Endpoints of each path, in one common frame (m).
    initial : array_like, shape (3,)
        Start (xc, yc, rc).
    """
    tx = np.asarray(transmitters_m, dtype=float)
    rx = np.asarray(receivers_m, dtype=float)
    ends = np.concatenate([tx[:, :2], rx[:, :2]])

    def predict(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        # Keep every transducer outside the circle: beyond, the radius is frozen (zero slope).
        near = float(np.min(np.linalg.norm(ends - x[:2], axis=1)))
        limit = near * (1 - 1e-9)
        rc = min(x[2], limit)
        lengths, grad = circle_path_lengths(x[:2], rc, tx, rx)
        if x[2] > limit:
            grad = grad.copy()
            grad[:, 2] = 0.0
        return lengths, grad

    return weighted_least_squares("circle", CIRCLE_PARAMETERS, predict, lengths_m, sigma_m, initial,
                                  lower=[-np.inf, -np.inf, 0.0], max_nfev=max_nfev)
