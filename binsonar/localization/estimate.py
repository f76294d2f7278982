"""One ping's path lengths of one reflector -> a classified, localised Target with covariance."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.detection.echo import Echo
from binsonar.localization import target as tg
from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.circle import fit_circle
from binsonar.localization.classify import CYLINDER, PLANE, POINT, UNKNOWN, classify
from binsonar.localization.fit import ModelFit
from binsonar.localization.plane import fit_plane
from binsonar.localization.point import (
    POINT_OK, fit_point, point_from_path_lengths, range_bearing_from_position, seed_point_covariance,
    seed_point_status)


@dataclass(frozen=True)
class EstimationConfig:
    """Settings of the single-ping estimation and classification.

    Attributes
    ----------
    alpha : float
        Significance of the chi-square model tests (probability of rejecting a true model).
    radius_rel_std_max : float
        The radius counts as observable when its std is at most this fraction of the estimate...
    radius_std_floor_m : float
        ... or at most this absolute value (m).
    """

    alpha: float = 0.01
    radius_rel_std_max: float = 0.5
    radius_std_floor_m: float = 1e-3

    def __post_init__(self) -> None:
        if not 0.0 < self.alpha < 1.0:
            raise ValueError(f"alpha must be in (0, 1), got {self.alpha!r}")
        if not self.radius_rel_std_max > 0 or not self.radius_std_floor_m >= 0:
            raise ValueError("radius_rel_std_max must be > 0 and radius_std_floor_m >= 0")


def radius_observable(radius_m: float, radius_std_m: float, config: EstimationConfig) -> bool:
    """Whether a fitted radius is meaningfully determined (see ``EstimationConfig``)."""
    return bool(np.isfinite(radius_std_m) and (radius_std_m <= config.radius_rel_std_max * radius_m
                                               or radius_std_m <= config.radius_std_floor_m))


def _embed(cov2: NDArray[np.float64]) -> NDArray[np.float64]:
    cov = np.zeros((3, 3))
    cov[:2, :2] = cov2
    return cov


def _invalid_target(ping: int, lengths: NDArray[np.float64], sigma: NDArray[np.float64],
                    echoes: tuple[Echo | None, ...], status: str, message: str,
                    fits: tuple[ModelFit, ...] = ()) -> tg.Target:
    return tg.Target(ping, UNKNOWN, status, message, np.full(3, np.nan), np.full((3, 3), np.nan), np.nan, np.nan,
                     np.nan, np.nan, path_lengths_m=lengths, path_length_std_m=sigma, echoes=echoes, fits=fits)


def target_from_path_lengths(
    lengths_m: ArrayLike,
    sigma_m: ArrayLike,
    geometry: ArrayGeometry,
    *,
    ping: int = 0,
    echoes: tuple[Echo | None, ...] = (None, None, None),
    config: EstimationConfig | None = None,
    prefer: str | None = None,
) -> tg.Target:
    """Fit the point, circle and plane models to one reflector's path lengths and classify it.

    Parameters
    ----------
    lengths_m : array_like, shape (3,)
        Bistatic path lengths left, centre, right (m); NaN for a channel without an echo (the
        centre may be missing: the target is then localised as a point, class "unknown").
    sigma_m : array_like, shape (3,)
        Their standard deviations (m).
    geometry : ArrayGeometry
    ping : int
    echoes : tuple of 3 (Echo or None)
    config : EstimationConfig, optional
    prefer : {"point", "plane"}, optional
        The class to take when point and plane both fit (``classify``).

    Returns
    -------
    Target
        Never raises for bad numbers: invalid path lengths give status "invalid-path-lengths".
    """
    cfg = config or EstimationConfig()
    L = np.asarray(lengths_m, dtype=float).reshape(3)
    s = np.asarray(sigma_m, dtype=float).reshape(3)
    d = geometry.half_baseline_m
    if np.any(np.isinf(L)) or not (np.isfinite(L[0]) and np.isfinite(L[2])):
        return _invalid_target(ping, L, s, echoes, tg.STATUS_INVALID_PATH_LENGTHS,
                               "need finite left and right path lengths (NaN only for a missing centre), "
                               f"got {L.tolist()}")
    if not np.all(np.isfinite(s[np.isfinite(L)]) & (s[np.isfinite(L)] > 0)):
        return _invalid_target(ping, L, s, echoes, tg.STATUS_INVALID_PATH_LENGTHS,
                               f"path-length stds must be finite and > 0, got {s.tolist()}")
    direct = geometry.direct_distance_m()
    use = np.isfinite(L)
    if np.any(L[use] <= direct[use]):
        return _invalid_target(ping, L, s, echoes, tg.STATUS_INVALID_PATH_LENGTHS,
                               f"path lengths {L.tolist()} m are not longer than the transmitter-receiver "
                               f"distances {direct.tolist()} m")
    if abs(L[0] - L[2]) > geometry.max_path_difference_m + 3.0 * float(np.hypot(s[0], s[2])):
        return _invalid_target(ping, L, s, echoes, tg.STATUS_INVALID_PATH_LENGTHS,
                               f"|L_left - L_right| = {abs(L[0] - L[2]):.6g} m exceeds the receiver baseline "
                               f"{geometry.max_path_difference_m:.6g} m")

    point = fit_point(L, s, geometry)
    fits: list[ModelFit] = [point]
    circle = plane = None
    if np.isfinite(L[1]):
        circle = fit_circle(L, s, geometry)
        plane = fit_plane(L, s, geometry)
        fits += [circle, plane]
    cls, reason = classify(point, circle, plane, cfg.alpha, prefer)
    messages = [reason]
    status = tg.STATUS_OK
    t = geometry.transmitter_m

    pos = np.full(3, np.nan)
    cov = np.full((3, 3), np.nan)
    rng = brg = rng_sd = brg_sd = np.nan
    if cls == CYLINDER and circle is not None:
        xc, yc, rc = circle.parameters
        pos = np.array([xc, yc, t[2]])
        cov = _embed(circle.covariance[:2, :2])
        v = pos[:2] - t[:2]
        dist = float(np.hypot(*v))
        g = np.array([v[0] / dist, v[1] / dist, -1.0])
        rng = dist - rc
        rng_sd = float(np.sqrt(abs(g @ circle.covariance @ g)))
        _, brg, _, brg_sd = range_bearing_from_position(pos, cov, geometry)
    elif cls == PLANE and plane is not None:
        psi, p = plane.parameters
        n = np.array([np.sin(psi), np.cos(psi), 0.0])
        dn = np.array([np.cos(psi), -np.sin(psi), 0.0])
        pos = t + (p - t @ n) * n
        jac = np.stack([-(t @ dn) * n + (p - t @ n) * dn, n], axis=1)  # d foot / d(psi, p), (3, 2)
        cov = jac @ plane.covariance @ jac.T
        g = np.array([-(t @ dn), 1.0])
        rng = float(p - t @ n)
        rng_sd = float(np.sqrt(abs(g @ plane.covariance @ g)))
        brg, brg_sd = float(np.degrees(psi)), float(np.degrees(plane.std[0]))
    elif point.ok:
        pos = np.array([point.parameters[0], point.parameters[1], t[2]])
        cov = _embed(point.covariance)
        rng, brg, rng_sd, brg_sd = range_bearing_from_position(pos, cov, geometry)
    else:
        why = str(seed_point_status(L[0], L[2], d))
        if geometry.is_seed and why == POINT_OK:
            r, th = (float(v) for v in point_from_path_lengths(L[0], L[2], d))
            c2 = seed_point_covariance(r, th, d, s[0], s[2])
            pos = np.array([r * np.sin(th), r * np.cos(th), 0.0])
            jac = np.array([[np.sin(th), r * np.cos(th)], [np.cos(th), -r * np.sin(th)]])
            cov = _embed(jac @ c2 @ jac.T)
            rng, brg = r, float(np.degrees(th))
            rng_sd, brg_sd = float(np.sqrt(c2[0, 0])), float(np.degrees(np.sqrt(c2[1, 1])))
        else:
            return _invalid_target(ping, L, s, echoes, tg.STATUS_FIT_FAILED,
                                   f"point fit failed ({point.message}; seed solution: {why})", tuple(fits))

    radius = radius_sd = np.nan
    if cls == PLANE:
        radius = np.inf
    elif circle is not None and circle.ok:
        radius, radius_sd = circle.value("rc_m"), circle.std_of("rc_m")
    if cls == UNKNOWN:
        status = tg.STATUS_NO_CENTRE_ECHO if not np.isfinite(L[1]) else tg.STATUS_NO_MODEL_FITS
        if status == tg.STATUS_NO_CENTRE_ECHO:
            messages.append("no centre echo: localised as a point from the side channels, not classified")
    elif reason.startswith("ambiguous"):
        status = tg.STATUS_AMBIGUOUS
    if cls in (POINT, CYLINDER) and np.isfinite(radius) and not radius_observable(radius, radius_sd, cfg):
        if status == tg.STATUS_OK:
            status = tg.STATUS_RADIUS_NOT_OBSERVABLE
        messages.append(f"radius {radius:.4g} m is not observable from this ping (std {radius_sd:.3g} m)")
    return tg.Target(ping, cls, status, "; ".join(messages), pos, cov, float(rng), float(brg), float(rng_sd),
                     float(brg_sd), float(radius), float(radius_sd), L, s, tuple(echoes), tuple(fits))
