"""Planes: a vertical wall seen by the three receivers (image-source model, exact).

The wall is the set of points x with n . x = p, n = (sin(psi), cos(psi), 0) its unit normal in
the head frame (psi the normal's bearing, positive toward the right receiver, as for points) and
p its distance from the head origin along n. The specular path T -> wall -> R has the length of
the straight line from the mirrored transmitter T' = T - 2 (n . T - p) n to R:

    L = |R - T'|,  dL/dp = -2 u . n,  dL/dpsi = 2 u . ((n' . T) n + (n . T - p) n'),

with u = (R - T') / L and n' = dn/dpsi = (cos(psi), -sin(psi), 0). A vertical wall keeps this
exact for receivers at different heights.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.fit import INVALID_INPUT, ModelFit, weighted_least_squares
from binsonar.localization.point import initial_point

PLANE_PARAMETERS: tuple[str, str] = ("normal_bearing_rad", "distance_m")


def plane_path_lengths(normal_bearing_rad: float, distance_m: float, transmitters_m: ArrayLike,
                       receivers_m: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Specular path lengths via a vertical plane, and their gradient.

    Parameters
    ----------
    normal_bearing_rad : float
        psi, bearing of the wall's normal (rad).
    distance_m : float
        p, the wall's distance from the frame origin along the normal (m).
    transmitters_m, receivers_m : array_like, shape (m, 3)
        Endpoints of each path (m).

    Returns
    -------
    lengths_m : ndarray, shape (m,)
        NaN where a transducer is on or behind the wall.
    gradient : ndarray, shape (m, 2)
        dL / d(psi, p).
    """
    tx = np.atleast_2d(np.asarray(transmitters_m, dtype=float))
    rx = np.atleast_2d(np.asarray(receivers_m, dtype=float))
    psi, p = float(normal_bearing_rad), float(distance_m)
    n = np.array([np.sin(psi), np.cos(psi), 0.0])
    dn = np.array([np.cos(psi), -np.sin(psi), 0.0])
    ht = tx @ n - p                      # signed height of T over the wall (< 0: in front)
    image = tx - 2 * ht[:, None] * n
    v = rx - image
    length = np.linalg.norm(v, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = v / length[:, None]
    grad = np.empty((length.size, 2))
    grad[:, 0] = 2 * (u @ n * (tx @ dn) + ht * (u @ dn))
    grad[:, 1] = -2 * (u @ n)
    behind = (ht >= 0) | (rx @ n - p >= 0)
    length = np.where(behind, np.nan, length)
    grad[behind] = np.nan
    return length, grad


def fit_plane_paths(lengths_m: ArrayLike, sigma_m: ArrayLike, transmitters_m: ArrayLike,
                    receivers_m: ArrayLike, initial: ArrayLike) -> ModelFit:
    """A vertical plane fitted to any set of bistatic paths (common frame), by least squares.

    Parameters
    ----------
    lengths_m, sigma_m : array_like, shape (m,)
    transmitters_m, receivers_m : array_like, shape (m, 3)
    initial : array_like, shape (2,)
        Start (psi_rad, p_m).
    """
    tx = np.asarray(transmitters_m, dtype=float)
    rx = np.asarray(receivers_m, dtype=float)

    def predict(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return plane_path_lengths(x[0], x[1], tx, rx)

    return weighted_least_squares("plane", PLANE_PARAMETERS, predict, lengths_m, sigma_m, initial,
                                  lower=[-np.pi, -np.inf], upper=[np.pi, np.inf])


def fit_plane(lengths_m: ArrayLike, sigma_m: ArrayLike, geometry: ArrayGeometry) -> ModelFit:
    """A vertical wall fitted to the path lengths of one ping (head frame).

    Parameters
    ----------
    lengths_m, sigma_m : array_like, shape (3,)
        Path lengths left, centre, right (NaN if missing) and their stds (m).
    geometry : ArrayGeometry

    Returns
    -------
    ModelFit
        model "plane", parameters (normal_bearing_rad, distance_m); one degree of freedom with
        three path lengths.
    """
    L = np.asarray(lengths_m, dtype=float)
    s = np.asarray(sigma_m, dtype=float)
    use = np.isfinite(L)
    if L.shape != (3,) or use.sum() < 2:
        return ModelFit.failed("plane", PLANE_PARAMETERS, int(use.sum()), INVALID_INPUT,
                               "plane fit needs at least two path lengths")
    if np.any(L[use] <= geometry.direct_distance_m()[use]):
        return ModelFit.failed("plane", PLANE_PARAMETERS, int(use.sum()), INVALID_INPUT,
                               "a path length is shorter than its transmitter-receiver distance")
    p0 = initial_point(L, geometry) - geometry.transmitter_m
    psi0 = float(np.arctan2(p0[0], p0[1]))
    n0 = np.array([np.sin(psi0), np.cos(psi0), 0.0])
    dist0 = float(geometry.transmitter_m @ n0 + 0.5 * np.mean(L[use]))
    tx = np.broadcast_to(geometry.transmitter_m, (3, 3))[use]
    return fit_plane_paths(L[use], s[use], tx, geometry.receivers_m[use], [psi0, dist0])


def plane_foot(fit: ModelFit, transmitter_m: ArrayLike) -> NDArray[np.float64]:
    """Foot (3,) of the perpendicular from the transmitter to a fitted wall (m)."""
    psi, p = fit.parameters
    n = np.array([np.sin(psi), np.cos(psi), 0.0])
    t = np.asarray(transmitter_m, dtype=float)
    return t + (p - t @ n) * n
