"""Read the localisation results JSON (``binsonar localize PING.h5 --json``) into markers to draw.

The reader is defensive: it accepts the layouts and field names below and ignores anything
else. Layouts: ``{"pings": [{"ping": 0, "pose": ..., "targets": [...]}, ...]}``,
``{"targets": [...]}`` or a bare list of targets. Per target, the position is the first of:

- ``position_tank_m`` (3 values, tank frame);
- ``position_m`` (tank frame, or head frame when the target or the file says ``"frame": "head"``);
- ``position_head_m`` (2 or 3 values, head frame; z = 0 when 2);
- ``range_m`` and ``bearing_deg`` (optional ``elevation_deg``), head frame:
  x = r cos(el) sin(theta), y = r cos(el) cos(theta), z = r sin(el).

The position uncertainty is the first of ``covariance_tank_m2`` (3x3, tank frame);
``covariance_m2`` or ``covariance`` (2x2 or 3x3, in the frame of the position); ``std_m`` or
``position_std_m`` (2 or 3 standard deviations, same frame); ``range_std_m`` with
``bearing_std_deg`` (propagated through the polar-to-Cartesian Jacobian). The class is ``cls``,
``class`` or ``kind``. Head-frame values go to the tank frame with the ping's ``pose``
(``[x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg]`` or an object with those keys), else the file's
``pose``, else the sonar given by the caller.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.sonar import SonarHead
from acoustisim.viz.actors import EstimateMarker

POSE_KEYS: tuple[str, ...] = ("x_m", "y_m", "z_m", "yaw_deg", "pitch_deg", "roll_deg")


def _numbers(where: str, field: str, value: Any, sizes: Sequence[int]) -> NDArray[np.float64]:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{where}: {field} must be numbers, got {value!r}") from None
    if arr.size not in sizes or not np.all(np.isfinite(arr)):
        raise InputError(f"{where}: {field} must be {' or '.join(map(str, sizes))} finite numbers, got {value!r}")
    return arr


def _pose_sonar(where: str, pose: Any, sonar: SonarHead) -> SonarHead:
    if pose is None:
        return sonar
    if isinstance(pose, Mapping):
        values = [pose.get(k, default) for k, default in zip(POSE_KEYS, (*sonar.position_m, sonar.yaw_deg,
                                                                          sonar.pitch_deg, sonar.roll_deg))]
    else:
        values = pose
    v = _numbers(where, "pose", values, (3, 4, 6)).ravel()
    yaw = v[3] if v.size > 3 else None
    pitch = v[4] if v.size > 4 else None
    roll = v[5] if v.size > 5 else None
    return sonar.with_pose(v[:3], yaw, pitch, roll)


def _embed(cov: NDArray[np.float64]) -> NDArray[np.float64]:
    out = np.zeros((3, 3))
    n = cov.shape[0]
    out[:n, :n] = cov
    return out


def _target(where: str, target: Any, sonar: SonarHead, file_frame: str) -> EstimateMarker:
    if not isinstance(target, Mapping):
        raise InputError(f"{where}: a target must be an object, got {type(target).__name__}")
    frame = str(target.get("frame", file_frame))
    head_frame: bool
    if "position_tank_m" in target:
        position = _numbers(where, "position_tank_m", target["position_tank_m"], (3,))
        head_frame = False
    elif "position_m" in target:
        position = _numbers(where, "position_m", target["position_m"], (2, 3) if frame == "head" else (3,))
        head_frame = frame == "head"
    elif "position_head_m" in target:
        position = _numbers(where, "position_head_m", target["position_head_m"], (2, 3))
        head_frame = True
    elif "range_m" in target and "bearing_deg" in target:
        r = float(_numbers(where, "range_m", target["range_m"], (1,))[()])
        theta = math.radians(float(_numbers(where, "bearing_deg", target["bearing_deg"], (1,))[()]))
        elevation = math.radians(float(_numbers(where, "elevation_deg", target.get("elevation_deg", 0.0), (1,))[()]))
        position = r * np.array([math.cos(elevation) * math.sin(theta), math.cos(elevation) * math.cos(theta),
                                 math.sin(elevation)])
        head_frame = True
    else:
        raise InputError(f"{where}: no position (expected position_tank_m, position_m, position_head_m or "
                         f"range_m with bearing_deg)")
    position = position.ravel() if position.size == 3 else np.r_[position.ravel(), 0.0]

    covariance: NDArray[np.float64] | None = None
    cov_head = head_frame
    if "covariance_tank_m2" in target:
        covariance = _numbers(where, "covariance_tank_m2", target["covariance_tank_m2"], (9,)).reshape(3, 3)
        cov_head = False
    else:
        for key in ("covariance_m2", "covariance"):
            if key in target and target[key] is not None:
                raw = _numbers(where, key, target[key], (4, 9))
                covariance = _embed(raw.reshape(int(round(math.sqrt(raw.size))), -1))
                break
        else:
            for key in ("std_m", "position_std_m"):
                if key in target and target[key] is not None:
                    covariance = _embed(np.diag(_numbers(where, key, target[key], (2, 3)) ** 2))
                    break
            else:
                if "range_std_m" in target and "bearing_std_deg" in target and "range_m" in target:
                    r = float(target["range_m"])
                    theta = math.radians(float(target["bearing_deg"]))
                    s_r = float(_numbers(where, "range_std_m", target["range_std_m"], (1,))[()])
                    s_t = math.radians(float(_numbers(where, "bearing_std_deg", target["bearing_std_deg"], (1,))[()]))
                    jac = np.array([[math.sin(theta), r * math.cos(theta)], [math.cos(theta), -r * math.sin(theta)]])
                    covariance = _embed(jac @ np.diag([s_r**2, s_t**2]) @ jac.T)
                    cov_head = True
    if head_frame:
        position = sonar.head_to_tank(position[None, :])[0]
    if covariance is not None:
        covariance = 0.5 * (covariance + covariance.T)
        if cov_head:
            rotation = sonar.rotation
            covariance = rotation @ covariance @ rotation.T
    cls = str(target.get("cls", target.get("class", target.get("kind", "unknown"))))
    return EstimateMarker(position, covariance, cls, str(target.get("name", target.get("label", ""))))


def parse_results(data: Any, sonar: SonarHead, source: str = "results") -> list[EstimateMarker]:
    """Estimated targets in the tank frame from a parsed results object.

    Parameters
    ----------
    data : dict or list
        The parsed JSON (layouts in the module docstring).
    sonar : SonarHead
        The head's pose when the file gives none (head-frame values are placed with it).
    source : str
        Name used in error messages.

    Raises
    ------
    InputError
        A target without a usable position, or malformed numbers; the message names the field.
    """
    file_frame = "tank"
    file_pose = None
    if isinstance(data, Mapping):
        file_frame = str(data.get("frame", "tank"))
        file_pose = data.get("pose")
        if "pings" in data:
            pings = data["pings"]
        elif "targets" in data:
            pings = [{"targets": data["targets"]}]
        else:
            raise InputError(f"{source}: expected a 'pings' or 'targets' field, found {sorted(data)!r}")
    elif isinstance(data, list):
        pings = [{"targets": data}]
    else:
        raise InputError(f"{source}: expected a JSON object or list, got {type(data).__name__}")
    if not isinstance(pings, list):
        raise InputError(f"{source}: 'pings' must be a list")
    base = _pose_sonar(f"{source}: pose", file_pose, sonar)
    markers = []
    for i, ping in enumerate(pings):
        if not isinstance(ping, Mapping):
            raise InputError(f"{source}: pings[{i}] must be an object")
        ping_sonar = _pose_sonar(f"{source}: pings[{i}].pose", ping.get("pose"), base)
        targets = ping.get("targets", [])
        if not isinstance(targets, list):
            raise InputError(f"{source}: pings[{i}].targets must be a list")
        frame = str(ping.get("frame", file_frame))
        markers.extend(_target(f"{source}: pings[{i}].targets[{j}]", t, ping_sonar, frame)
                       for j, t in enumerate(targets))
    return markers


def load_results(path: str | os.PathLike[str], sonar: SonarHead) -> list[EstimateMarker]:
    """Read a results JSON file (see :func:`parse_results`).

    Raises
    ------
    InputError
        Unreadable or malformed file; the message names the file and the field.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: results file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read results: {exc}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    return parse_results(data, sonar, str(path))
