"""Several pings from several known poses -> one better estimate (the seed's future work, ch. 5).

Every ping's path lengths are modelled in the tank frame with the transducers moved by the
known poses, and the point, circle (vertical cylinder) and plane (vertical wall) models are
fitted to all of them at once by weighted least squares (batch over poses). The vantage points
spread along the track are what make a small cylinder's radius observable: from one ping it is
set by the 2 d baseline (std ~ 2 sqrt(6) sigma_L D^2 / d^2), from a track by the track's length.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from binsonar.localization import target as tg
from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.circle import CIRCLE_PARAMETERS, fit_circle_paths
from binsonar.localization.classify import CYLINDER, PLANE, POINT, UNKNOWN, classify
from binsonar.localization.estimate import EstimationConfig, radius_observable
from binsonar.localization.fit import INVALID_INPUT, ModelFit, weighted_least_squares
from binsonar.localization.frames import head_to_tank
from binsonar.localization.plane import fit_plane_paths
from binsonar.localization.point import bistatic_path_lengths, initial_point


@dataclass(frozen=True, eq=False)
class PoseObservation:
    """One ping of one reflector seen from a known pose.

    Attributes
    ----------
    pose : ndarray, shape (6,)
        Head pose in the tank (x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg).
    lengths_m : ndarray, shape (3,)
        Path lengths left, centre, right (m; NaN where missing).
    sigma_m : ndarray, shape (3,)
        Their standard deviations (m).
    ping : int
    """

    pose: NDArray[np.float64] = field(repr=False)
    lengths_m: NDArray[np.float64] = field(repr=False)
    sigma_m: NDArray[np.float64] = field(repr=False)
    ping: int = 0

    def __post_init__(self) -> None:
        for name, shape in (("pose", (6,)), ("lengths_m", (3,)), ("sigma_m", (3,))):
            a = np.array(getattr(self, name), dtype=float)
            if a.shape != shape:
                raise ValueError(f"PoseObservation.{name} must have shape {shape}, got {a.shape}")
            a.setflags(write=False)
            object.__setattr__(self, name, a)


@dataclass(frozen=True, eq=False)
class FusedTarget:
    """A reflector estimated from several pings, in the tank frame.

    Attributes
    ----------
    cls, status, message : str
        As for ``Target``.
    position_tank_m : ndarray, shape (3,)
        The point, the cylinder's centre, or the foot of the perpendicular from the mean
        transmitter position to the wall (m); height = the transmitters' mean height.
    covariance_tank : ndarray, shape (3, 3)
        Its covariance (m^2), zero for the fixed height.
    radius_m, radius_std_m : float
        Circle fit's radius and std (m); inf for a plane, NaN when not fitted.
    pings : tuple of int
        The pings fused.
    fits : tuple of ModelFit
        Point (x_m, y_m), circle (xc_m, yc_m, rc_m) and plane fits in the tank frame.
    """

    cls: str
    status: str
    message: str
    position_tank_m: NDArray[np.float64] = field(repr=False)
    covariance_tank: NDArray[np.float64] = field(repr=False)
    radius_m: float
    radius_std_m: float
    pings: tuple[int, ...]
    fits: tuple[ModelFit, ...] = field(default=(), repr=False)

    @property
    def position_tank_std_m(self) -> NDArray[np.float64]:
        """Standard deviations (3,) of the position (m)."""
        return np.sqrt(np.abs(np.diag(self.covariance_tank)))

    def fit(self, model: str) -> ModelFit | None:
        """The fit of one model, None if not attempted."""
        return next((f for f in self.fits if f.model == model), None)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready summary."""

        def num(v: float) -> float | None:
            return float(v) if np.isfinite(v) else None

        return {
            "class": self.cls, "status": self.status, "message": self.message,
            "position_tank_m": [num(v) for v in self.position_tank_m],
            "position_tank_std_m": [num(v) for v in self.position_tank_std_m],
            "radius_m": "inf" if np.isposinf(self.radius_m) else num(self.radius_m),
            "radius_std_m": num(self.radius_std_m), "pings": list(self.pings),
        }


def tank_paths(observations: Sequence[PoseObservation], geometry: ArrayGeometry
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Every finite path of the observations in the tank frame.

    Returns
    -------
    lengths_m, sigma_m : ndarray, shape (m,)
    transmitters_m, receivers_m : ndarray, shape (m, 3)
    """
    L, S, T, R = [], [], [], []
    for obs in observations:
        use = np.isfinite(obs.lengths_m)
        tx = head_to_tank(geometry.transmitter_m, obs.pose)
        rx = head_to_tank(geometry.receivers_m, obs.pose)
        L.append(obs.lengths_m[use])
        S.append(obs.sigma_m[use])
        T.append(np.broadcast_to(tx, (int(use.sum()), 3)))
        R.append(rx[use])
    if not L:
        return np.zeros(0), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))
    return np.concatenate(L), np.concatenate(S), np.concatenate(T), np.concatenate(R)


def _initial_tank_point(observations: Sequence[PoseObservation], geometry: ArrayGeometry) -> NDArray[np.float64]:
    starts = [head_to_tank(initial_point(o.lengths_m, geometry), o.pose) for o in observations]
    starts = [p for p in starts if np.all(np.isfinite(p))]
    return np.median(np.array(starts), axis=0) if starts else np.full(3, np.nan)


def fuse_point(observations: Sequence[PoseObservation], geometry: ArrayGeometry) -> ModelFit:
    """A point reflector (x_m, y_m) in the tank frame at the transmitters' mean height, from all pings."""
    L, S, T, R = tank_paths(observations, geometry)
    names = ("x_m", "y_m")
    if L.size < 3:
        return ModelFit.failed("point", names, L.size, INVALID_INPUT, "need at least three path lengths")
    z = float(np.mean(T[:, 2]))
    p0 = _initial_tank_point(observations, geometry)

    def predict(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        lengths, grad = bistatic_path_lengths([x[0], x[1], z], T, R)
        return lengths, grad[:, :2]

    return weighted_least_squares("point", names, predict, L, S, p0[:2])


def fuse_circle(observations: Sequence[PoseObservation], geometry: ArrayGeometry,
                point: ModelFit | None = None) -> ModelFit:
    """A vertical cylinder (xc_m, yc_m, rc_m) in the tank frame from all pings, rc >= 0.

    Starts from the fused point pushed away from the mean transmitter by a small radius
    (1 % of the mean range).
    """
    L, S, T, R = tank_paths(observations, geometry)
    if L.size < 4:
        return ModelFit.failed("circle", CIRCLE_PARAMETERS, L.size, INVALID_INPUT, "need at least four path lengths")
    pt = point if point is not None and point.ok else fuse_point(observations, geometry)
    if not pt.ok:
        return ModelFit.failed("circle", CIRCLE_PARAMETERS, L.size, INVALID_INPUT, "no starting point")
    p = pt.parameters[:2]
    away = p - np.mean(T[:, :2], axis=0)
    dist = float(np.linalg.norm(away))
    rc0 = 0.01 * dist
    c0 = p + rc0 * away / dist
    return fit_circle_paths(L, S, T, R, [c0[0], c0[1], rc0], max_nfev=400)


def fuse_plane(observations: Sequence[PoseObservation], geometry: ArrayGeometry,
               point: ModelFit | None = None) -> ModelFit:
    """A vertical wall (normal_bearing_rad = atan2(n_x, n_y) in the tank frame, distance_m from the
    tank origin) from all pings."""
    L, S, T, R = tank_paths(observations, geometry)
    names = ("normal_bearing_rad", "distance_m")
    if L.size < 3:
        return ModelFit.failed("plane", names, L.size, INVALID_INPUT, "need at least three path lengths")
    pt = point if point is not None and point.ok else fuse_point(observations, geometry)
    if not pt.ok:
        return ModelFit.failed("plane", names, L.size, INVALID_INPUT, "no starting point")
    v = pt.parameters[:2] - np.mean(T[:, :2], axis=0)
    psi0 = float(np.arctan2(v[0], v[1]))
    n0 = np.array([np.sin(psi0), np.cos(psi0)])
    # The wall's point nearest the mean transmitter is about half the mean monostatic path away.
    p0 = float(np.mean(T[:, :2], axis=0) @ n0 + 0.5 * np.mean(L))
    return fit_plane_paths(L, S, T, R, [psi0, p0])


def fuse(observations: Sequence[PoseObservation], geometry: ArrayGeometry,
         config: EstimationConfig | None = None) -> FusedTarget:
    """Fit point, circle and plane to all pings of one reflector, classify, and report.

    Parameters
    ----------
    observations : sequence of PoseObservation
        The reflector's path lengths from each pose.
    geometry : ArrayGeometry
        The head (same for every ping).
    config : EstimationConfig, optional

    Returns
    -------
    FusedTarget
    """
    cfg = config or EstimationConfig()
    pings = tuple(o.ping for o in observations)
    point = fuse_point(observations, geometry)
    circle = fuse_circle(observations, geometry, point)
    plane = fuse_plane(observations, geometry, point)
    fits = (point, circle, plane)
    cls, reason = classify(point, circle, plane, cfg.alpha)
    _, _, T, _ = tank_paths(observations, geometry)
    z = float(np.mean(T[:, 2])) if T.size else np.nan
    pos = np.full(3, np.nan)
    cov = np.full((3, 3), np.nan)
    chosen = {POINT: point, CYLINDER: circle}.get(cls)
    if cls == PLANE:
        psi, p = plane.parameters
        n = np.array([np.sin(psi), np.cos(psi), 0.0])
        dn = np.array([np.cos(psi), -np.sin(psi), 0.0])
        t = np.array([*np.mean(T[:, :2], axis=0), z])
        pos = t + (p - t @ n) * n
        jac = np.stack([-(t @ dn) * n + (p - t @ n) * dn, n], axis=1)
        cov = jac @ plane.covariance @ jac.T
    elif chosen is not None or point.ok:
        src = chosen if chosen is not None else point
        pos = np.array([src.parameters[0], src.parameters[1], z])
        cov = np.zeros((3, 3))
        cov[:2, :2] = src.covariance[:2, :2]
    radius = radius_sd = np.nan
    if cls == PLANE:
        radius = np.inf
    elif circle.ok:
        radius, radius_sd = circle.value("rc_m"), circle.std_of("rc_m")
    status = tg.STATUS_OK
    messages = [reason]
    if cls == UNKNOWN:
        status = tg.STATUS_NO_MODEL_FITS if any(f.ok for f in fits) else tg.STATUS_FIT_FAILED
    elif reason.startswith("ambiguous"):
        status = tg.STATUS_AMBIGUOUS
    if cls in (POINT, CYLINDER) and np.isfinite(radius) and not radius_observable(radius, radius_sd, cfg):
        if status == tg.STATUS_OK:
            status = tg.STATUS_RADIUS_NOT_OBSERVABLE
        messages.append(f"radius {radius:.4g} m is not observable from these pings (std {radius_sd:.3g} m)")
    return FusedTarget(cls, status, "; ".join(messages), pos, cov, float(radius), float(radius_sd), pings, fits)


def group_across_pings(targets: Sequence[tg.Target], gate_m: float) -> list[list[tg.Target]]:
    """Group targets of different pings that are the same reflector (tank positions within a gate).

    Greedy nearest-neighbour: each target (in ping order) joins the group whose mean tank
    position is nearest, if within ``gate_m`` and the group has no target of that ping yet;
    otherwise it starts a group. Targets without a tank position are left out.

    Parameters
    ----------
    targets : sequence of Target
        With ``position_tank_m`` set (pose known).
    gate_m : float
        Largest distance (m) between a target and a group's mean position.
    """
    groups: list[list[tg.Target]] = []
    means: list[NDArray[np.float64]] = []
    for t in sorted(targets, key=lambda t: t.ping):
        if t.position_tank_m is None or not np.all(np.isfinite(t.position_tank_m)):
            continue
        p = np.asarray(t.position_tank_m)
        best, best_d = -1, np.inf
        for k, (g, m) in enumerate(zip(groups, means)):
            dist = float(np.linalg.norm(p[:2] - m[:2]))
            if dist < best_d and dist <= gate_m and all(o.ping != t.ping for o in g):
                best, best_d = k, dist
        if best < 0:
            groups.append([t])
            means.append(p.copy())
        else:
            groups[best].append(t)
            means[best] = np.mean([np.asarray(o.position_tank_m) for o in groups[best]], axis=0)
    return groups


def observations_of(targets: Sequence[tg.Target]) -> list[PoseObservation]:
    """PoseObservations from targets that carry a pose."""
    return [PoseObservation(t.pose, t.path_lengths_m, t.path_length_std_m, t.ping)
            for t in targets if t.pose is not None]


