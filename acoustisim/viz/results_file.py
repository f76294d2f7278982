"""Read the localisation results JSON (``binsonar localize PING.h5 --json``) into markers to draw.

The reader is defensive: it accepts the layouts and field names below and ignores anything
else. Layouts: ``{"pings": [{"ping": 0, "pose": ..., "targets": [...]}, ...]}``,
``{"targets": [...]}`` or a bare list of targets. Per target, the position is the first of:

- ``position_tank_m`` (3 values, tank frame);
- ``position_m`` (tank frame, or head frame when the target or the file says ``"frame": "head"``);
- ``position_head_m`` (2 or 3 values, head frame; z = 0 when 2);
- ``range_m`` and ``bearing_deg`` (optional ``elevation_deg``), head frame:
  x = r cos(el) sin(theta), y = r cos(el) cos(theta), z = r sin(el).

A null (or a list holding a null: the writer's non-finite numbers) counts as missing; a target
whose position fields are all null (a failed fit) is left out.

The position uncertainty is the first of ``covariance_tank_m2`` (3x3, tank frame);
``covariance_m2`` or ``covariance`` (2x2 or 3x3, in the frame of the position);
``position_tank_std_m`` (tank frame) or ``position_head_std_m`` (head frame) standard
deviations, as written by ``binsonar localize``; ``position_std_m`` or ``std_m`` (2 or 3
standard deviations, frame of the position); ``range_std_m`` with ``bearing_std_deg``
(propagated through the polar-to-Cartesian Jacobian). Standard deviations give an ellipsoid
aligned with that frame's axes (no correlation). The class is ``cls``,
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
POSITION_KEYS: tuple[str, ...] = ("position_tank_m", "position_m", "position_head_m", "range_m", "bearing_deg")


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


def _present(target: Mapping[str, Any], key: str) -> bool:
    """Whether ``key`` holds a value: absent keys, nulls and lists with a null (a non-finite
    number in the writer) count as missing."""
    value = target.get(key)
    if value is None:
        return False
    if isinstance(value, (list, tuple)):
        flat = np.asarray(value, dtype=object).ravel()
        return flat.size > 0 and not any(v is None for v in flat)
    return True


def _target(where: str, target: Any, sonar: SonarHead, file_frame: str) -> EstimateMarker | None:
    """One target as a marker; None when the target has position fields but all are null (a
    failed fit)."""
    if not isinstance(target, Mapping):
        raise InputError(f"{where}: a target must be an object, got {type(target).__name__}")
    frame = str(target.get("frame", file_frame))
    head_frame: bool
    if _present(target, "position_tank_m"):
        position = _numbers(where, "position_tank_m", target["position_tank_m"], (3,))
        head_frame = False
    elif _present(target, "position_m"):
        position = _numbers(where, "position_m", target["position_m"], (2, 3) if frame == "head" else (3,))
        head_frame = frame == "head"
    elif _present(target, "position_head_m"):
        position = _numbers(where, "position_head_m", target["position_head_m"], (2, 3))
        head_frame = True
    elif _present(target, "range_m") and _present(target, "bearing_deg"):
        r = float(_numbers(where, "range_m", target["range_m"], (1,))[()])
        theta = math.radians(float(_numbers(where, "bearing_deg", target["bearing_deg"], (1,))[()]))
        elevation = math.radians(float(_numbers(where, "elevation_deg", target.get("elevation_deg") or 0.0, (1,))[()]))
        position = r * np.array([math.cos(elevation) * math.sin(theta), math.cos(elevation) * math.cos(theta),
                                 math.sin(elevation)])
        head_frame = True
    elif any(key in target for key in POSITION_KEYS):
        return None
    else:
        raise InputError(f"{where}: no position (expected position_tank_m, position_m, position_head_m or "
                         f"range_m with bearing_deg)")
    position = position.ravel() if position.size == 3 else np.r_[position.ravel(), 0.0]

    # The uncertainty: (key, frame is head?, kind) in order of preference; the frame of
    # "covariance"/"std_m" is that of the position used.
    covariance: NDArray[np.float64] | None = None
    cov_head = head_frame
    candidates = (
        ("covariance_tank_m2", False, "cov"),
        ("covariance_m2", head_frame, "cov"),
        ("covariance", head_frame, "cov"),
        ("position_tank_std_m", False, "std"),
        ("position_head_std_m", True, "std"),
        ("position_std_m", head_frame, "std"),
        ("std_m", head_frame, "std"),
    )
    for key, in_head, kind in candidates:
        if not _present(target, key):
            continue
        if kind == "cov":
            raw = _numbers(where, key, target[key], (4, 9))
            covariance = _embed(raw.reshape(int(round(math.sqrt(raw.size))), -1))
        else:
            covariance = _embed(np.diag(_numbers(where, key, target[key], (2, 3)).ravel() ** 2))
        cov_head = in_head
        break
    else:
        if all(_present(target, k) for k in ("range_std_m", "bearing_std_deg", "range_m", "bearing_deg")):
            r = float(target["range_m"])
            theta = math.radians(float(target["bearing_deg"]))
            s_r = float(_numbers(where, "range_std_m", target["range_std_m"], (1,))[()])
            s_t = math.radians(float(_numbers(where, "bearing_std_deg", target["bearing_std_deg"], (1,))[()]))
            # d(x, y)/d(r, theta) of x = r sin(theta), y = r cos(theta).
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
        for j, t in enumerate(targets):
            marker = _target(f"{source}: pings[{i}].targets[{j}]", t, ping_sonar, frame)
            if marker is not None:
                markers.append(marker)
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
