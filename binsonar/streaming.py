"""Detection and localisation of a recording of any length, in memory that does not grow with it.

``detect_source(source, method, ...)`` runs ``binsonar.detection`` on a ``PingSource``
(``binsonar.recording.open_recording``, ``binsonar.importers.open_source``) range of pings by
range of pings (``PingSource.chunks``: about 32 MB of samples each), with one ``Detector`` that
plans the method once, and joins the echoes, renumbering the pings. It gives what
``detect(read_recording(path, keep_codes=True), method, ...)`` gives, holding one range at a time.

Methods that average the pings (``average=True``, the seed's averaging combinations) get the
average made range by range (``average_source``): the mean of the pings' volts (from their
codes) and each ping's clipping, judged as the detectors judge it (the stored flags, the ADC's
rails +/-(2^(bits - 1) - 1) codes, ``full_scale_v``); the detectors then see one averaged ping,
whose DC offset they measure on the average (the in-memory path averages the pings' offsets
instead: both estimate the same offset, and differ by a small fraction of the noise).

``localize_source`` detects so, then localises the joined detections with the source's
geometry, poses, sound speed and template (``binsonar.localization.localize``).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Callable

import numpy as np
from numpy.typing import NDArray

from binsonar.recording.model import Recording, RecordingError
from binsonar.recording.source import CHUNK_BYTES, PingSource

if TYPE_CHECKING:
    from binsonar.detection.echo import DetectionResult
    from binsonar.localization.pipeline import LocalizationConfig, LocalizationResult

Refinement = Callable[["DetectionResult", Recording], "DetectionResult"]
"""A step applied to each range's detections with its recording (the beam-aware refinement)."""


def averages_pings(method: str, average: bool | None) -> bool:
    """Whether ``detect(..., method, average=average)`` averages the pings first."""
    if average is not None:
        return bool(average)
    from binsonar.detection.seed import SEED_COMBINATIONS

    return any(c.name == method and c.average for c in SEED_COMBINATIONS)


def average_source(source: PingSource, full_scale_v: float | None = None,
                   max_bytes: int = CHUNK_BYTES) -> Recording:
    """The mean of every ping (volts) as a one-ping recording, its channels clipped where any
    ping's were (see the module notes); read range by range.

    Raises
    ------
    RecordingError
        As the source's reading.
    """
    header = source.header
    total = np.zeros((3, header.n_samples))
    clipped = np.zeros(3, dtype=bool)
    rail = None
    if header.stores_codes and header.adc_bits is not None:
        rail = 2 ** (int(header.adc_bits) - 1) - 1
    for _, chunk in source.chunks(max_bytes, keep_codes=True):
        clipped |= chunk.clipped.any(axis=0)
        if chunk.codes is not None:
            codes = chunk.codes
            if rail is not None:
                clipped |= ((codes.max(axis=-1) >= rail) | (codes.min(axis=-1) <= -rail)).any(axis=0)
            if full_scale_v is not None:
                limit = full_scale_v * (1.0 - 1e-9)
                step = float(header.volts_per_code)  # type: ignore[arg-type]
                clipped |= ((codes.max(axis=-1) * step >= limit) | (codes.min(axis=-1) * step <= -limit)).any(axis=0)
            total += codes.sum(axis=0, dtype=np.float64) * float(header.volts_per_code)  # type: ignore[arg-type]
        else:
            volts = chunk.waveforms
            if full_scale_v is not None:
                limit = full_scale_v * (1.0 - 1e-9)
                clipped |= ((volts.max(axis=-1) >= limit) | (volts.min(axis=-1) <= -limit)).any(axis=0)
            total += volts.sum(axis=0)
    mean = total / source.n_pings
    mean.setflags(write=False)
    fields = header.recording_fields()
    fields["volts_per_code"] = None  # the average is not on the code grid
    return Recording(mean[np.newaxis], clipped=clipped[np.newaxis], **fields)


def _renumbered(result: "DetectionResult", first_ping: int) -> tuple[tuple[tuple[Any, ...], ...], ...]:
    """``result.echoes`` with each echo's ping moved by ``first_ping``."""
    if first_ping == 0:
        return result.echoes
    return tuple(
        tuple(tuple(replace(echo, ping=echo.ping + first_ping) for echo in channel) for channel in ping)
        for ping in result.echoes
    )


RangeStep = Callable[["DetectionResult", Recording, int], None]
"""Called with each range's detections, its recording and its first ping's index (the averaged
ping: the one averaged recording and 0), while the range's samples are in memory."""


def detect_chunks(source: PingSource, method: str, *, average: bool | None = None, on_clipped: str = "flag",
                  refine: Refinement | None = None, max_bytes: int = CHUNK_BYTES, each: RangeStep | None = None,
                  **arguments: Any) -> tuple["DetectionResult", NDArray[np.float64] | None]:
    """``detect_source``'s detections, and every ping's pose ((n_pings, 6), or None when the
    source has none); ``each`` is called on every range (``RangeStep``)."""
    from binsonar.detection import Detector, detect
    from binsonar.detection.echo import DetectionResult

    if averages_pings(method, average):
        poses = _poses(source, max_bytes)
        averaged = average_source(source, arguments.get("full_scale_v"), max_bytes)
        if source.header.stores_codes:
            arguments.setdefault("adc_step_v", source.header.volts_per_code)
        result = detect(averaged, method, average=average, on_clipped=on_clipped, **arguments)
        if refine is not None:
            result = refine(result, averaged)
        if each is not None:
            each(result, averaged, 0)
        return result, poses
    detector = Detector()
    echoes: list[Any] = []
    clipped: list[Any] = []
    poses_parts: list[NDArray[np.float64]] = []
    elapsed = 0.0
    options: tuple[tuple[str, object], ...] = ()
    name = method
    for start, chunk in source.chunks(max_bytes, keep_codes=True):
        result = detector.detect(chunk, method, average=average,
                                 on_clipped="flag" if on_clipped == "error" else on_clipped, **arguments)
        if on_clipped == "error" and any(any(row) for row in result.clipped):
            flags = np.array(result.clipped, dtype=bool)
            ping, channel = (int(v) for v in np.argwhere(flags)[0])
            raise RecordingError(f"{source.source}: ping {start + ping}, channel {channel} clipped "
                                 f"({int(flags.sum())} clipped channel(s) in pings {start}-{start + chunk.n_pings - 1})")
        if refine is not None:
            result = refine(result, chunk)
        if each is not None:
            each(result, chunk, start)
        echoes.extend(_renumbered(result, start))
        clipped.extend(result.clipped)
        elapsed += result.elapsed_s
        options, name = result.options, result.method
        if chunk.pose is not None:
            poses_parts.append(chunk.pose)
    poses = np.concatenate(poses_parts) if poses_parts else None
    return DetectionResult(method=name, echoes=tuple(echoes), elapsed_s=elapsed, clipped=tuple(clipped),
                           options=options), poses


def detect_source(source: PingSource, method: str, *, average: bool | None = None, on_clipped: str = "flag",
                  refine: Refinement | None = None, max_bytes: int = CHUNK_BYTES,
                  **arguments: Any) -> "DetectionResult":
    """Detect echoes in every ping of ``source``, range by range (see the module notes).

    Parameters
    ----------
    source : PingSource
    method : str
        Any of ``binsonar.detection.METHODS``.
    average : bool, optional
        As ``detect``'s (default: the method's own).
    on_clipped : {"flag", "drop", "error"}
        As ``detect``'s; "error" names the first clipped ping of the file.
    refine : callable, optional
        Applied to each range's detections with its recording (the beam-aware refinement).
    max_bytes : int
        Samples read at once (bytes).
    **arguments
        Passed to ``detect`` (template, bandpass_hz, full_scale_v, method options...).

    Returns
    -------
    DetectionResult
        All pings (one after averaging); ``elapsed_s`` is the detectors' own time, summed.

    Raises
    ------
    RecordingError
        Bad data, options or a clipped channel with ``on_clipped="error"`` (one line).
    """
    return detect_chunks(source, method, average=average, on_clipped=on_clipped, refine=refine,
                         max_bytes=max_bytes, **arguments)[0]


def _poses(source: PingSource, max_bytes: int) -> NDArray[np.float64] | None:
    """Every ping's pose, read range by range (only the small pose datasets are kept)."""
    parts = [chunk.pose for _, chunk in source.chunks(max_bytes, keep_codes=True) if chunk.pose is not None]
    return np.concatenate(parts) if parts else None


def localize_source(source: PingSource, *, method: str = "ca-cfar", sound_speed_m_s: float | None = None,
                    config: "LocalizationConfig | None" = None, refine: Refinement | None = None,
                    max_bytes: int = CHUNK_BYTES, transducers: Any = None,
                    **detect_options: Any) -> "LocalizationResult":
    """``binsonar.localization.localize`` of every ping of ``source``, range of pings by range of pings.

    The geometry is the source's channel positions, the poses its ``/pose``, the sound speed its
    own (else ``sound_speed_m_s``), the CRLB's bandwidth its template's. Each range's pings are
    localised while their samples are in memory (``detect_chunks``' ``each``), so the beam-aware
    refinement (``config.beam``, with the source's array description or ``transducers``) runs
    on them; the targets are fused across all pings at the end. Methods that average the pings
    localise the one averaged ping (whose pings must share one pose).

    Raises
    ------
    RecordingError
        No sound speed, bad data, or a localisation error (one line naming the file).
    """
    from binsonar.bounds import rms_bandwidth_hz
    from binsonar.localization.array_geometry import ArrayGeometry
    from binsonar.localization.pipeline import (
        LocalizationConfig, LocalizationError, LocalizationResult, beam_setup, fuse_pings, localize_detections,
        pose_array)

    header = source.header
    where = source.source
    cfg = config or LocalizationConfig()
    c = header.sound_speed_m_s
    c_source = "recording"
    if c is None:
        c, c_source = sound_speed_m_s, "argument"
    if c is None:
        raise RecordingError(f"{where}: no sound speed (the recording has no /environment sound_speed_m_s): "
                             "pass sound_speed_m_s (--sound-speed)")
    if not (math.isfinite(c) and 1000.0 < c < 2000.0):
        raise RecordingError(f"{where}: sound_speed_m_s out of range (1000-2000 m/s): {c!r}")
    c = float(c)
    try:
        geometry = ArrayGeometry.from_channel_positions(header.channel_positions_m)
    except ValueError as exc:
        raise LocalizationError(f"{where}: {exc}") from None
    bandwidth = None
    if header.template is not None:
        bandwidth = rms_bandwidth_hz(header.template.samples, header.template.sample_rate_hz)
    setup, beam = beam_setup(header, c, cfg, transducers)
    per_ping: list[Any] = []
    unassociated: list[int] = []
    averaged = averages_pings(method, detect_options.get("average"))

    def localize_range(result: "DetectionResult", chunk: Recording, first_ping: int) -> None:
        poses = None if averaged else pose_array(chunk.pose, result.n_pings, where)
        waveforms = None if setup is None else np.asarray(chunk.waveforms, dtype=float)
        try:
            targets, left_out = localize_detections(result, geometry, c, config=cfg, rms_bandwidth_hz=bandwidth,
                                                    poses=poses, waveforms=waveforms, setup=setup,
                                                    first_ping=first_ping)
        except RecordingError as exc:
            message = str(exc)
            raise RecordingError(message.replace("localize:", f"{where}:", 1)
                                 if message.startswith("localize:") else message) from None
        per_ping.extend(targets)
        unassociated.extend(left_out)

    detections, poses = detect_chunks(source, method, refine=refine, max_bytes=max_bytes, each=localize_range,
                                      **detect_options)
    pose_arr = pose_array(poses, detections.n_pings, where)
    if averaged and pose_arr is not None:  # the one averaged ping's targets in the tank frame
        per_ping = [tuple(t.with_pose(pose_arr[0]) for t in per_ping[0])]
    fused = fuse_pings(per_ping, geometry, cfg, pose_arr is not None)
    return LocalizationResult(tuple(per_ping), fused, detections.method, c, c_source, geometry, tuple(unassociated),
                              header.source, pose_arr, beam)
