"""A localised target: where it is, how well that is known, and what it is."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.detection.echo import Echo
from binsonar.localization.fit import ModelFit
from binsonar.localization.frames import covariance_to_tank, head_to_tank

# Target status values (the first problem found; details in ``Target.message``).
STATUS_OK = "ok"
STATUS_RADIUS_NOT_OBSERVABLE = "radius-not-observable"
STATUS_AMBIGUOUS = "ambiguous"
STATUS_NO_CENTRE_ECHO = "no-centre-echo"
STATUS_INVALID_PATH_LENGTHS = "invalid-path-lengths"
STATUS_FIT_FAILED = "fit-failed"
STATUS_NO_MODEL_FITS = "no-model-fits"


def _radius_json(radius_m: float) -> float | str | None:
    """A radius for JSON: None when not fitted, "inf" for a plane."""
    if math.isnan(radius_m):
        return None
    return float(radius_m) if math.isfinite(radius_m) else "inf"


def _frozen(a: ArrayLike) -> NDArray[np.float64]:
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class Target:
    """One reflector found in one ping.

    Attributes
    ----------
    ping : int
        Ping index.
    cls : str
        "point", "cylinder", "plane" or "unknown".
    status : str
        "ok" or the first problem (module constants), e.g. "radius-not-observable".
    message : str
        Details of the classification and of any problem.
    position_head_m : ndarray, shape (3,)
        Head frame (m): the point; the cylinder's axis (centre) at the array's height; the foot
        of the perpendicular from the transmitter to a wall. NaN when not localised.
    covariance : ndarray, shape (3, 3)
        Covariance of ``position_head_m`` (m^2); zero rows for a coordinate held fixed (the
        height in the horizontal-plane models).
    range_m : float
        Distance from the transmitter to the reflecting surface (m): the point itself, the
        cylinder's nearest surface |C - T| - rc, the wall's distance.
    bearing_deg : float
        atan2(x, y) of the point, of the cylinder's centre, of the wall's normal (deg), positive
        toward the right receiver.
    range_std_m, bearing_std_deg : float
        Their standard deviations.
    radius_m, radius_std_m : float
        Fitted cylinder radius and its std (m) where the circle was fitted (also reported for
        a target classified "point", whose radius is then usually not observable); NaN when
        not fitted; inf for a plane.
    path_lengths_m, path_length_std_m : ndarray, shape (3,)
        The bistatic path lengths used (left, centre, right; NaN if missing) and their stds (m).
    echoes : tuple of (Echo or None), length 3
        The echoes of the target on each channel.
    fits : tuple of ModelFit
        Every model fitted (point, circle, plane, ...).
    pose : ndarray, shape (6,), or None
        Head pose in the tank (x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg) when known.
    position_tank_m : ndarray, shape (3,), or None
        ``position_head_m`` in the tank frame when the pose is known.
    covariance_tank : ndarray, shape (3, 3), or None
        Its covariance (m^2).
    echo_model : str
        The expected echo the echoes were timed with: "point" or "vertical-edge" (beam-aware,
        ``beam_targets``), "" for the plain matched filter's times.
    """

    ping: int
    cls: str
    status: str
    message: str
    position_head_m: NDArray[np.float64] = field(repr=False)
    covariance: NDArray[np.float64] = field(repr=False)
    range_m: float
    bearing_deg: float
    range_std_m: float
    bearing_std_deg: float
    radius_m: float = float("nan")
    radius_std_m: float = float("nan")
    path_lengths_m: NDArray[np.float64] = field(default_factory=lambda: np.full(3, np.nan), repr=False)
    path_length_std_m: NDArray[np.float64] = field(default_factory=lambda: np.full(3, np.nan), repr=False)
    echoes: tuple[Echo | None, ...] = (None, None, None)
    fits: tuple[ModelFit, ...] = field(default=(), repr=False)
    pose: NDArray[np.float64] | None = field(default=None, repr=False)
    position_tank_m: NDArray[np.float64] | None = field(default=None, repr=False)
    covariance_tank: NDArray[np.float64] | None = field(default=None, repr=False)
    echo_model: str = ""

    def __post_init__(self) -> None:
        for name in ("position_head_m", "covariance", "path_lengths_m", "path_length_std_m"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        for name in ("pose", "position_tank_m", "covariance_tank"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _frozen(getattr(self, name)))

    @property
    def position_std_m(self) -> NDArray[np.float64]:
        """Standard deviations (3,) of ``position_head_m`` (m)."""
        return np.sqrt(np.abs(np.diag(self.covariance)))

    @property
    def position_tank_std_m(self) -> NDArray[np.float64] | None:
        """Standard deviations (3,) of ``position_tank_m`` (m), None without a pose."""
        return None if self.covariance_tank is None else np.sqrt(np.abs(np.diag(self.covariance_tank)))

    def fit(self, model: str) -> ModelFit | None:
        """The fit of one model ("point", "circle", "plane"), None if not attempted."""
        return next((f for f in self.fits if f.model == model), None)

    def with_pose(self, pose: ArrayLike) -> "Target":
        """This target with its tank-frame position and covariance for a head pose (6,)."""
        p = np.asarray(pose, dtype=float)
        if not np.all(np.isfinite(self.position_head_m)):
            return replace(self, pose=p, position_tank_m=np.full(3, np.nan), covariance_tank=np.full((3, 3), np.nan))
        return replace(self, pose=p, position_tank_m=head_to_tank(self.position_head_m, p),
                       covariance_tank=covariance_to_tank(self.covariance, p))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (non-finite numbers become None)."""

        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        def vec(a: NDArray[np.float64] | None) -> list[float | None] | None:
            return None if a is None else [num(float(x)) for x in np.ravel(a)]

        out: dict[str, Any] = {
            "ping": self.ping,
            "class": self.cls,
            "status": self.status,
            "message": self.message,
            "range_m": num(self.range_m),
            "range_std_m": num(self.range_std_m),
            "bearing_deg": num(self.bearing_deg),
            "bearing_std_deg": num(self.bearing_std_deg),
            "position_head_m": vec(self.position_head_m),
            "position_head_std_m": vec(self.position_std_m),
            "position_tank_m": vec(self.position_tank_m),
            "position_tank_std_m": vec(self.position_tank_std_m),
            "radius_m": _radius_json(self.radius_m),
            "radius_std_m": num(self.radius_std_m),
            "path_lengths_m": vec(self.path_lengths_m),
            "path_length_std_m": vec(self.path_length_std_m),
            "tof_s": [None if e is None else float(e.tof_s) for e in self.echoes],
            "tof_std_s": [None if e is None else num(float(e.tof_std_s)) for e in self.echoes],
            "echo_model": self.echo_model or None,
        }
        return out
