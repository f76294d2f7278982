"""Camera presets: top (a plan view like the seed's figure 3-8), side, from the sonar, perspective.

A preset is computed from the region to show and the window's aspect ratio, so that the same
numbers drive the VTK plotter and the WebGL page.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.sonar import SonarHead

CAMERA_NAMES: tuple[str, ...] = ("top", "side", "sonar", "perspective", "targets")


@dataclass(frozen=True)
class CameraPreset:
    """A camera pose in the tank frame.

    Attributes
    ----------
    name : str
    position_m, focal_point_m : tuple of 3 float
        Eye and look-at point (m).
    view_up : tuple of 3 float
        Unit vector pointing up on the screen.
    parallel : bool
        Orthographic projection (top and side views) instead of perspective.
    parallel_scale_m : float
        Half the visible height (m) for a parallel projection.
    view_angle_deg : float
        Vertical field of view for a perspective projection (degrees).
    """

    name: str
    position_m: tuple[float, float, float]
    focal_point_m: tuple[float, float, float]
    view_up: tuple[float, float, float]
    parallel: bool = False
    parallel_scale_m: float = 1.0
    view_angle_deg: float = 30.0


def _t(v: NDArray[np.float64]) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def camera_preset(name: str, bounds: NDArray[np.float64], *, aspect: float = 1.5, sonar: SonarHead | None = None,
                  margin: float = 1.08) -> CameraPreset:
    """The preset ``name`` framing ``bounds``.

    Parameters
    ----------
    name : {"top", "side", "sonar", "perspective", "targets"}
        "top": looking down -z, x to the right, y up the screen (the tank's plan).
        "side": looking along +y, x to the right, z up.
        "sonar": just behind and above the head, looking along its boresight.
        "perspective": from above the x = 0, y = 0 corner's side, looking at the centre.
        "targets": the top view of ``bounds`` as given (the caller passes the region around the
        sonar, the estimates and the true targets).
    bounds : ndarray, shape (2, 3)
        Region to frame (m).
    aspect : float
        Window width / height.
    sonar : SonarHead, optional
        Required by "sonar".
    margin : float
        Extra room around the region (1 = tight).

    Raises
    ------
    InputError
        For an unknown name, or "sonar" without a sonar.
    """
    bounds = np.asarray(bounds, dtype=float)
    centre = bounds.mean(axis=0)
    extent = bounds[1] - bounds[0]
    if name in ("top", "side", "targets"):
        # Plan (x right, y up) or elevation (x right, z up), centred on the region.
        vertical = 2 if name == "side" else 1
        scale = 0.5 * margin * max(extent[vertical], extent[0] / aspect)
        offset = np.zeros(3)
        if name == "side":
            offset[1] = -4.0 * np.linalg.norm(extent)
        else:
            offset[2] = 4.0 * np.linalg.norm(extent)
        up = (0.0, 0.0, 1.0) if name == "side" else (0.0, 1.0, 0.0)
        return CameraPreset(name, _t(centre + offset), _t(centre), up, True, scale)
    if name == "sonar":
        if sonar is None:
            raise InputError("camera 'sonar' needs a sonar")
        forward = sonar.boresight
        up = sonar.rotation[:, 2]
        # Over the head's shoulder: its body stays below the 50 degree field of view.
        eye = sonar.transmitter_position - 0.3 * forward + 0.25 * up
        return CameraPreset(name, _t(eye), _t(sonar.transmitter_position + 2.5 * forward), _t(up), False, 1.0, 50.0)
    if name == "perspective":
        view_angle = 30.0
        direction = np.array([-0.45, -1.0, 0.85])
        direction /= np.linalg.norm(direction)
        radius = 0.5 * float(np.linalg.norm(extent))
        # Distance at which the bounding sphere fits the vertical field of view, then a little
        # closer (the sphere over-estimates a flat tank's projected size).
        distance = 0.68 * margin * radius / math.sin(math.radians(0.5 * view_angle))
        right = np.cross(-direction, np.array([0.0, 0.0, 1.0]))
        up = np.cross(right, -direction)
        up /= np.linalg.norm(up)
        look = centre
        eye = look + distance * direction
        return CameraPreset(name, _t(eye), _t(look), _t(up), False, 1.0, view_angle)
    raise InputError(f"camera: unknown preset {name!r}; choose one of {', '.join(CAMERA_NAMES)}")


def apply_camera(plotter: object, preset: CameraPreset) -> None:
    """Set a pyvista plotter's camera to ``preset``."""
    camera = plotter.camera  # type: ignore[attr-defined]
    camera.position = preset.position_m
    camera.focal_point = preset.focal_point_m
    camera.up = preset.view_up
    if preset.parallel:
        camera.enable_parallel_projection()
        camera.parallel_scale = preset.parallel_scale_m
    else:
        camera.disable_parallel_projection()
        camera.view_angle = preset.view_angle_deg
    plotter.renderer.reset_camera_clipping_range()  # type: ignore[attr-defined]
