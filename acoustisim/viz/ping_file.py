"""What the viewer takes from a simulated ping file: the head's pose, the true paths and the
true targets (``/truth``, written by ``acoustisim simulate``; ``binsonar`` never reads it).

Used: ``/pose`` (through :func:`binsonar.recording.read_recording`), ``/environment``
``sound_speed_m_s``, ``/truth/arrivals`` (a structured array whose fields are a subset of
``PATH_DTYPE``), ``/truth/surface_names`` (dataset or attribute), and ``/truth`` attribute (or
dataset) ``objects``, a JSON list of {name, kind, material, position, size, class}. A real
recording has no ``/truth``: the view then shows the pose only.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from acoustisim.errors import InputError
from acoustisim.propagation.paths import PATH_DTYPE, Paths, empty_paths_array
from acoustisim.sonar import SonarHead
from acoustisim.viz.actors import TruthMarker


@dataclass(frozen=True, eq=False)
class PingView:
    """The drawable content of one ping.

    Attributes
    ----------
    sonar : SonarHead
        The caller's sonar moved to the ping's pose (unchanged when the file has no pose).
    paths : Paths or None
        The true arrivals (None for a real recording).
    truths : tuple of TruthMarker
        True target positions (tank frame, m).
    """

    sonar: SonarHead
    paths: Paths | None = None
    truths: tuple[TruthMarker, ...] = field(default=())


def _text(value: Any) -> str:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.ndarray) and value.shape == ():
        return _text(value[()])
    return str(value)


def load_ping(path: str | os.PathLike[str], sonar: SonarHead, ping: int = 0) -> PingView:
    """Read the pose and truth of ping ``ping`` of a recording file.

    Raises
    ------
    InputError
        Missing file, ping index out of range, or a malformed ``/truth`` entry (named).
    """
    import h5py

    from binsonar.recording import RecordingError, read_recording

    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: ping file not found")
    try:
        recording = read_recording(path)
    except RecordingError as exc:
        raise InputError(str(exc)) from None
    if not 0 <= ping < recording.n_pings:
        raise InputError(f"{path}: ping {ping} out of range (the file has {recording.n_pings})")
    if recording.pose is not None:
        x, y, z, yaw, pitch, roll = (float(v) for v in recording.pose[ping])
        sonar = sonar.with_pose((x, y, z), yaw, pitch, roll)
    paths = None
    truths: list[TruthMarker] = []
    with h5py.File(path, "r") as h5:
        truth = h5.get("truth")
        if truth is None:
            return PingView(sonar)
        if "surface_names" in truth:
            names = tuple(_text(v) for v in np.asarray(truth["surface_names"][()]).ravel())
        elif "surface_names" in truth.attrs:
            names = tuple(_text(v) for v in np.atleast_1d(truth.attrs["surface_names"]))
        else:
            names = ()
        if "arrivals" in truth:
            stored = truth["arrivals"][()]
            if stored.dtype.names is None:
                raise InputError(f"{path}: /truth/arrivals is not a table (no named fields)")
            rows = empty_paths_array(stored.size)
            for name in stored.dtype.names:
                if name in PATH_DTYPE.names:
                    rows[name] = stored[name]
            if "channel" not in stored.dtype.names or "delay_s" not in stored.dtype.names:
                raise InputError(f"{path}: /truth/arrivals lacks the 'channel' or 'delay_s' column")
            sound_speed = recording.sound_speed_m_s
            if sound_speed is None:
                with np.errstate(divide="ignore", invalid="ignore"):
                    ratio = rows["path_length_m"] / rows["delay_s"]
                finite = ratio[np.isfinite(ratio) & (ratio > 0)]
                sound_speed = float(np.median(finite)) if finite.size else 1482.38
            paths = Paths(rows, names, sonar.centre_frequency_hz, float(sound_speed))
        raw_objects = truth.attrs.get("objects") if "objects" in truth.attrs else (
            truth["objects"][()] if "objects" in truth else None)
        if raw_objects is not None:
            try:
                objects = json.loads(_text(raw_objects))
            except json.JSONDecodeError as exc:
                raise InputError(f"{path}: /truth objects is not valid JSON ({exc.msg})") from None
            for i, obj in enumerate(objects if isinstance(objects, list) else []):
                position = obj.get("position", obj.get("position_m")) if isinstance(obj, dict) else None
                if position is None:
                    continue
                p = np.asarray(position, dtype=float).ravel()
                if p.size == 2:
                    p = np.r_[p, sonar.transmitter_position[2]]
                if p.size != 3 or not np.all(np.isfinite(p)):
                    raise InputError(f"{path}: /truth objects[{i}].position must be 2 or 3 numbers, got {position!r}")
                truths.append(TruthMarker(p, str(obj.get("name", ""))))
    return PingView(sonar, paths, tuple(truths))
