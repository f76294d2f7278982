"""The recording file: what the hardware writes and the pipeline reads (HDF5, versioned).

Layout, ``format_version`` "1.0" (documented in the README; a public contract)::

    /                       attrs: format_version ("1.0"), sample_rate_hz, t0_s (time of the
                            first sample after the transmit trigger, s), channel_names
                            (["left", "centre", "right"]), created_by
    /waveforms              (n_pings, 3, n_samples): int16 ADC codes with attrs
                            volts_per_code and adc_bits, or float32/float64 volts (attr units="V")
    /channel_positions_m    (3, 3) float64, channel positions in the head frame (m)
    /clipped                optional (n_pings, 3) uint8, 1 where the ADC clipped
    /template               optional (n,) float64 pulse or calibration echo, attrs
                            sample_rate_hz, t0_s (time of template sample 0 relative to the
                            pulse's reference instant, s), kind
    /environment            optional group, attrs sound_speed_m_s, temperature_c
    /pose                   optional (n_pings, 6) float64: x_m, y_m, z_m, yaw_deg, pitch_deg,
                            roll_deg of the head in the tank frame
    /truth/...              optional, simulated pings only; never read by binsonar

Times of flight are measured from the transmit trigger: sample ``i`` of a channel is at
``t0_s + i / sample_rate_hz``, and the template's reference instant is what a time of flight
refers to.
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from numpy.typing import NDArray

from binsonar.errors import InputError

FORMAT_VERSION = "1.0"
CHANNEL_NAMES: tuple[str, str, str] = ("left", "centre", "right")
POSE_COLUMNS: tuple[str, ...] = ("x_m", "y_m", "z_m", "yaw_deg", "pitch_deg", "roll_deg")


class RecordingError(InputError):
    """A recording file or array that cannot be used; the message names file, field and value."""


@dataclass(frozen=True, eq=False)
class Template:
    """A matched-filter template.

    Attributes
    ----------
    samples : ndarray, shape (n,)
        The template (any unit; only its shape matters).
    sample_rate_hz : float
    t0_s : float
        Time of ``samples[0]`` relative to the reference instant a TOF refers to (s).
    kind : str
        "transmitted-pulse", "calibration-echo" or "user".
    """

    samples: NDArray[np.float64] = field(repr=False)
    sample_rate_hz: float
    t0_s: float = 0.0
    kind: str = "transmitted-pulse"

    def __post_init__(self) -> None:
        samples = np.array(self.samples, dtype=float, copy=True)
        if samples.ndim != 1 or samples.size < 2:
            raise RecordingError(f"template: samples must be 1-D with >= 2 values, got shape {samples.shape}")
        if not np.all(np.isfinite(samples)):
            raise RecordingError("template: samples contain NaN or infinite values")
        if not (math.isfinite(self.sample_rate_hz) and self.sample_rate_hz > 0):
            raise RecordingError(f"template: sample_rate_hz must be > 0, got {self.sample_rate_hz!r}")
        if not math.isfinite(self.t0_s):
            raise RecordingError(f"template: t0_s must be finite, got {self.t0_s!r}")
        samples.setflags(write=False)
        object.__setattr__(self, "samples", samples)


@dataclass(frozen=True, eq=False)
class Recording:
    """One recording of one or many pings.

    Attributes
    ----------
    waveforms : ndarray, shape (n_pings, 3, n_samples), float64
        Volts, channels left, centre, right.
    sample_rate_hz : float
    t0_s : float
        Time of the first sample after the transmit trigger (s).
    channel_positions_m : ndarray, shape (3, 3)
        Channel positions in the head frame (m).
    channel_names : tuple of str
    clipped : ndarray of bool, shape (n_pings, 3)
        Where the ADC clipped (all False when unknown).
    template : Template or None
    sound_speed_m_s, temperature_c : float or None
    pose : ndarray, shape (n_pings, 6), or None
        x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg per ping.
    volts_per_code : float or None
        Set when stored as int16 ADC codes.
    adc_bits : int or None
    created_by : str
    source : str
        Path the recording was read from ("" for arrays).
    codes : ndarray of int16, shape (n_pings, 3, n_samples), or None
        The ADC codes the volts were made from (``waveforms`` = ``codes * volts_per_code``),
        kept when asked for (``read_recording(..., keep_codes=True)``): detectors that work on
        codes read them instead of the volts (a quarter of the bytes). Needs
        ``volts_per_code``; with codes, ``waveforms`` may be None (made from the codes).
    """

    waveforms: NDArray[np.float64] | None = field(repr=False)
    sample_rate_hz: float
    t0_s: float = 0.0
    channel_positions_m: NDArray[np.float64] = field(
        default_factory=lambda: np.array([[-0.065, 0.0, 0.0], [0.0, 0.0, 0.0], [0.065, 0.0, 0.0]]), repr=False
    )
    channel_names: tuple[str, ...] = CHANNEL_NAMES
    clipped: NDArray[np.bool_] | None = field(default=None, repr=False)
    template: Template | None = None
    sound_speed_m_s: float | None = None
    temperature_c: float | None = None
    pose: NDArray[np.float64] | None = field(default=None, repr=False)
    volts_per_code: float | None = None
    adc_bits: int | None = None
    created_by: str = ""
    source: str = ""
    codes: NDArray[np.int16] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        where = self.source or "recording"
        codes = None if self.codes is None else _as_codes(self.codes, self.volts_per_code, where)
        if codes is not None and self.waveforms is None:
            w = codes * float(self.volts_per_code)  # type: ignore[arg-type]
        else:
            w = np.array(self.waveforms, dtype=float, copy=True)
        if w.ndim == 2:
            w = w[np.newaxis]
        if w.ndim != 3 or w.shape[1] != 3 or w.shape[2] < 1 or w.shape[0] < 1:
            raise RecordingError(f"{where}: waveforms must have shape (n_pings, 3, n_samples), got {w.shape}")
        if not np.all(np.isfinite(w)):
            bad = np.argwhere(~np.isfinite(w))[0]
            raise RecordingError(
                f"{where}: waveforms contain NaN or infinite samples (first at ping {bad[0]}, channel {bad[1]}, "
                f"sample {bad[2]})"
            )
        w.setflags(write=False)
        object.__setattr__(self, "waveforms", w)
        if codes is not None:
            if codes.shape != w.shape:
                raise RecordingError(f"{where}: codes shape {codes.shape} != waveforms shape {w.shape}")
            if self.waveforms is not None and not np.array_equal(w, codes * float(self.volts_per_code)):  # type: ignore[arg-type]
                raise RecordingError(f"{where}: waveforms are not codes * volts_per_code ({self.volts_per_code!r})")
            codes.setflags(write=False)
            object.__setattr__(self, "codes", codes)
        if not (isinstance(self.sample_rate_hz, (int, float)) and math.isfinite(self.sample_rate_hz)
                and self.sample_rate_hz > 0):
            raise RecordingError(f"{where}: sample_rate_hz must be a finite number > 0, got {self.sample_rate_hz!r}")
        if not math.isfinite(self.t0_s):
            raise RecordingError(f"{where}: t0_s must be finite, got {self.t0_s!r}")
        positions = np.array(self.channel_positions_m, dtype=float)
        if positions.shape != (3, 3) or not np.all(np.isfinite(positions)):
            raise RecordingError(f"{where}: channel_positions_m must be (3, 3) finite, got shape {positions.shape}")
        positions.setflags(write=False)
        object.__setattr__(self, "channel_positions_m", positions)
        clipped = (
            np.zeros(w.shape[:2], dtype=bool) if self.clipped is None else np.array(self.clipped, dtype=bool)
        )
        if clipped.shape != w.shape[:2]:
            raise RecordingError(f"{where}: clipped must have shape {w.shape[:2]}, got {clipped.shape}")
        clipped.setflags(write=False)
        object.__setattr__(self, "clipped", clipped)
        if self.pose is not None:
            pose = as_poses(self.pose, w.shape[0], where)
            pose.setflags(write=False)
            object.__setattr__(self, "pose", pose)
        if self.sound_speed_m_s is not None and not (
            math.isfinite(self.sound_speed_m_s) and 1000.0 < self.sound_speed_m_s < 2000.0
        ):
            raise RecordingError(f"{where}: sound_speed_m_s out of range: {self.sound_speed_m_s!r}")
        if self.temperature_c is not None and not (math.isfinite(self.temperature_c) and -5.0 < self.temperature_c < 100.0):
            raise RecordingError(f"{where}: temperature_c out of range: {self.temperature_c!r}")
        if len(self.channel_names) != 3:
            raise RecordingError(f"{where}: channel_names must name 3 channels, got {self.channel_names!r}")

    @property
    def n_pings(self) -> int:
        """Number of pings."""
        return int(self.waveforms.shape[0])

    @property
    def n_samples(self) -> int:
        """Samples per channel."""
        return int(self.waveforms.shape[2])

    @property
    def times_s(self) -> NDArray[np.float64]:
        """Time (s) of each sample after the trigger, shape (n_samples,)."""
        return self.t0_s + np.arange(self.n_samples) / self.sample_rate_hz


def _as_codes(codes: Any, volts_per_code: float | None, where: str) -> NDArray[np.int16]:
    """ADC codes as a new int16 array of shape (n_pings, 3, n) ((3, n) gets a ping axis).

    Raises
    ------
    RecordingError
        No valid ``volts_per_code``, a non-integer array, or codes outside the int16 range.
    """
    if volts_per_code is None or not (isinstance(volts_per_code, (int, float)) and math.isfinite(volts_per_code)
                                      and volts_per_code > 0):
        raise RecordingError(f"{where}: codes need volts_per_code > 0, got {volts_per_code!r}")
    array = np.asarray(codes)
    if not np.issubdtype(array.dtype, np.integer):
        raise RecordingError(f"{where}: codes must be integer ADC codes, got dtype {array.dtype}")
    if array.dtype != np.int16 and array.size and (array.min() < -32768 or array.max() > 32767):
        raise RecordingError(f"{where}: codes must fit int16, got values in [{array.min()}, {array.max()}]")
    out = np.array(array, dtype=np.int16, copy=True)
    return out[np.newaxis] if out.ndim == 2 else out


def as_poses(pose: Any, n_pings: int, where: str) -> NDArray[np.float64]:
    """Head poses as a new (n_pings, 6) float array: one pose (6,) is repeated for every ping.

    Parameters
    ----------
    pose : array_like, shape (6,) or (n_pings, 6)
        x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg (per ping).
    n_pings : int
    where : str
        Names the source in the error message.

    Raises
    ------
    RecordingError
        Another shape, or a non-finite value.
    """
    try:
        poses = np.array(pose, dtype=float)
    except (TypeError, ValueError):
        raise RecordingError(f"{where}: pose must be ({n_pings}, 6) finite numbers, got {pose!r}") from None
    if poses.ndim == 1:
        poses = np.broadcast_to(poses, (n_pings, poses.size)).copy()
    if poses.shape != (n_pings, 6) or not np.all(np.isfinite(poses)):
        raise RecordingError(f"{where}: pose must be ({n_pings}, 6) finite, got shape {poses.shape}")
    return poses


def _attr(attrs: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in attrs:
        raise RecordingError(f"{where}: missing attribute {key!r}")
    value = attrs[key]
    if isinstance(value, bytes):
        value = value.decode()
    if isinstance(value, np.generic):
        value = value.item()
    return value


def read_recording(path: str | os.PathLike[str], *, keep_codes: bool = False) -> Recording:
    """Read a recording file (format 1.x); never reads ``/truth``.

    Parameters
    ----------
    path : path-like
    keep_codes : bool
        For a file of int16 ADC codes, keep them too (``Recording.codes``): the detectors that
        work on codes then read them instead of the volts. Ignored for files of volts.

    Raises
    ------
    RecordingError
        Missing, unreadable, truncated or malformed file, naming the file, field and value.
    """
    import h5py

    path = Path(path)
    where = str(path)
    if not path.is_file():
        raise RecordingError(f"{where}: no such file")
    if path.stat().st_size == 0:
        raise RecordingError(f"{where}: the file is empty")
    try:
        handle = h5py.File(path, "r")
    except OSError as exc:
        raise RecordingError(f"{where}: not a readable HDF5 recording (truncated or corrupt?): {exc}") from None
    try:
        with handle as h5:
            version = str(_attr(h5.attrs, "format_version", where))
            if version.split(".")[0] != FORMAT_VERSION.split(".")[0]:
                raise RecordingError(f"{where}: format_version {version!r} is not supported (expected 1.x)")
            sample_rate = float(_attr(h5.attrs, "sample_rate_hz", where))
            t0 = float(_attr(h5.attrs, "t0_s", where))
            names_raw = _attr(h5.attrs, "channel_names", where)
            names = tuple(n.decode() if isinstance(n, bytes) else str(n) for n in np.atleast_1d(names_raw))
            if "waveforms" not in h5:
                raise RecordingError(f"{where}: missing dataset 'waveforms'")
            dset = h5["waveforms"]
            raw = dset[()]
            volts_per_code = None
            adc_bits = None
            if np.issubdtype(raw.dtype, np.integer):
                volts_per_code = float(_attr(dset.attrs, "volts_per_code", f"{where}:/waveforms"))
                if not (math.isfinite(volts_per_code) and volts_per_code > 0):
                    raise RecordingError(f"{where}: waveforms.volts_per_code must be > 0, got {volts_per_code!r}")
                adc_bits = int(dset.attrs.get("adc_bits", 12))
                waveforms = None if keep_codes else raw.astype(float) * volts_per_code
            elif np.issubdtype(raw.dtype, np.floating):
                waveforms = raw.astype(float)
            else:
                raise RecordingError(f"{where}: waveforms has unsupported dtype {raw.dtype}")
            if "channel_positions_m" not in h5:
                raise RecordingError(f"{where}: missing dataset 'channel_positions_m'")
            positions = h5["channel_positions_m"][()]
            clipped = h5["clipped"][()].astype(bool) if "clipped" in h5 else None
            template = None
            if "template" in h5:
                tds = h5["template"]
                template = Template(
                    tds[()],
                    float(_attr(tds.attrs, "sample_rate_hz", f"{where}:/template")),
                    float(tds.attrs.get("t0_s", 0.0)),
                    str(tds.attrs.get("kind", "transmitted-pulse")),
                )
            sound_speed = temperature = None
            if "environment" in h5:
                env = h5["environment"].attrs
                sound_speed = float(env["sound_speed_m_s"]) if "sound_speed_m_s" in env else None
                temperature = float(env["temperature_c"]) if "temperature_c" in env else None
            pose = h5["pose"][()] if "pose" in h5 else None
            created_by = str(_attr(h5.attrs, "created_by", where)) if "created_by" in h5.attrs else ""
    except RecordingError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise RecordingError(f"{where}: cannot read recording: {exc}") from None
    keep = keep_codes and volts_per_code is not None
    return Recording(
        waveforms=None if keep else waveforms,  # with codes: made from them (the same product)
        sample_rate_hz=sample_rate,
        t0_s=t0,
        channel_positions_m=positions,
        channel_names=names,
        clipped=clipped,
        template=template,
        sound_speed_m_s=sound_speed,
        temperature_c=temperature,
        pose=pose,
        volts_per_code=volts_per_code,
        adc_bits=adc_bits,
        created_by=created_by,
        source=where,
        codes=raw if keep else None,
    )


def write_recording(
    path: str | os.PathLike[str],
    recording: Recording,
    *,
    codes: NDArray[np.integer] | None = None,
    truth: Mapping[str, NDArray[Any] | str] | None = None,
) -> Path:
    """Write a recording atomically (a temporary file in the same folder, then a rename).

    Parameters
    ----------
    path : path-like
        Destination; an existing file is replaced only once the new one is complete.
    recording : Recording
    codes : int ndarray (n_pings, 3, n_samples), optional
        Store these int16 ADC codes (with ``recording.volts_per_code``) instead of float volts.
    truth : mapping of name -> array or str, optional
        Ground truth datasets written under ``/truth`` (simulated pings only).

    Returns
    -------
    Path
        The written file.
    """
    import h5py

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        # Fixed creation metadata so the same inputs give byte-identical files.
        with h5py.File(tmp_name, "w", track_order=True, libver="earliest") as h5:
            h5.attrs["format_version"] = FORMAT_VERSION
            h5.attrs["sample_rate_hz"] = float(recording.sample_rate_hz)
            h5.attrs["t0_s"] = float(recording.t0_s)
            h5.attrs["channel_names"] = np.array(recording.channel_names, dtype=h5py.string_dtype())
            h5.attrs["created_by"] = recording.created_by
            if codes is not None:
                codes = np.asarray(codes)
                if codes.shape != recording.waveforms.shape:
                    raise RecordingError(f"{path}: codes shape {codes.shape} != waveforms {recording.waveforms.shape}")
                if recording.volts_per_code is None:
                    raise RecordingError(f"{path}: volts_per_code is required with int16 codes")
                dset = h5.create_dataset("waveforms", data=codes.astype(np.int16))
                dset.attrs["volts_per_code"] = float(recording.volts_per_code)
                dset.attrs["adc_bits"] = int(recording.adc_bits or 12)
            else:
                dset = h5.create_dataset("waveforms", data=recording.waveforms)
                dset.attrs["units"] = "V"
            h5.create_dataset("channel_positions_m", data=recording.channel_positions_m)
            h5.create_dataset("clipped", data=np.asarray(recording.clipped, dtype=np.uint8))
            if recording.template is not None:
                tds = h5.create_dataset("template", data=recording.template.samples)
                tds.attrs["sample_rate_hz"] = float(recording.template.sample_rate_hz)
                tds.attrs["t0_s"] = float(recording.template.t0_s)
                tds.attrs["kind"] = recording.template.kind
            if recording.sound_speed_m_s is not None or recording.temperature_c is not None:
                env = h5.create_group("environment")
                if recording.sound_speed_m_s is not None:
                    env.attrs["sound_speed_m_s"] = float(recording.sound_speed_m_s)
                if recording.temperature_c is not None:
                    env.attrs["temperature_c"] = float(recording.temperature_c)
            if recording.pose is not None:
                pds = h5.create_dataset("pose", data=recording.pose)
                pds.attrs["columns"] = np.array(POSE_COLUMNS, dtype=h5py.string_dtype())
            if truth:
                group = h5.create_group("truth")
                for name, value in truth.items():
                    if isinstance(value, str):
                        group.attrs[name] = value
                    else:
                        group.create_dataset(name, data=value)
        os.replace(tmp_name, path)
    except BaseException:
        if os.path.exists(tmp_name):
            os.unlink(tmp_name)
        raise
    return path
