"""``localize``: from a recording (or detections) to classified targets per ping, and fused targets.

Steps per ping: path lengths L = c x TOF and their stds (the echo's ``tof_std_s``, else the
Cramer-Rao bound from its ``snr_db`` and the template's RMS envelope bandwidth), association of
echoes across channels, point/circle/plane fits and classification, then the tank frame from the
ping's pose. With several pings and known poses, targets are grouped across pings and fused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.detection.echo import DetectionResult, Echo
from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.association import associate
from binsonar.localization.estimate import EstimationConfig, target_from_path_lengths
from binsonar.localization.fusion import FusedTarget, fuse, group_across_pings, observations_of
from binsonar.localization.target import Target
from binsonar.recording import Recording, RecordingError, as_poses


class LocalizationError(RecordingError):
    """Input that cannot be localised (missing sound speed, geometry or noise model); one line."""


@dataclass(frozen=True)
class LocalizationConfig:
    """Settings of ``localize``.

    Attributes
    ----------
    estimation : EstimationConfig
        Model tests and radius observability.
    gate_n_sigma : float
        Association gate width (standard deviations).
    fuse : bool
        Fuse targets across pings when there are several pings with known poses.
    track_gate_m : float
        Largest distance (m) between a ping's target and a group's mean tank position.
    min_pings_to_fuse : int
        Groups with fewer pings are not fused.
    tof_floor_s : float
        Systematic TOF uncertainty (s) added in quadrature to every echo's statistical std. The
        detectors' ``tof_std_s`` (CRLB-like, ~1 ns at 60 dB) omits template mismatch: echoes
        from extended or curved reflectors have spectra tilted by the scattering, which moves
        the matched-filter peak; on the simulator's free-post, free-plane and free-cylinder
        scenes this bias is 20-70 ns (30-105 um of path). The default, 50 ns, is one sample at
        20 MS/s. Set 0 to trust the detector's std alone.
    min_range_m : float
        Echo pairs implying a reflector closer than this to the transmitter (m) are not
        targets: the transmitter's direct cross-talk to the side receivers (at |T - R| / c,
        44 us for d = 65 mm) and the ringing around it. The default, 5 cm, is a few transducer
        diameters.
    """

    estimation: EstimationConfig = field(default_factory=EstimationConfig)
    gate_n_sigma: float = 4.0
    fuse: bool = True
    track_gate_m: float = 0.15
    min_pings_to_fuse: int = 3
    tof_floor_s: float = 50e-9
    min_range_m: float = 0.05

    def __post_init__(self) -> None:
        if not (math.isfinite(self.tof_floor_s) and self.tof_floor_s >= 0):
            raise LocalizationError(f"tof_floor_s must be >= 0, got {self.tof_floor_s!r}")
        if not (math.isfinite(self.min_range_m) and self.min_range_m >= 0):
            raise LocalizationError(f"min_range_m must be >= 0, got {self.min_range_m!r}")
        if not self.gate_n_sigma > 0:
            raise LocalizationError(f"gate_n_sigma must be > 0, got {self.gate_n_sigma!r}")


@dataclass(frozen=True, eq=False)
class LocalizationResult:
    """Targets of every ping, and the fused targets.

    Attributes
    ----------
    targets : tuple (n_pings) of tuple of Target
    fused : tuple of FusedTarget
        One per group of targets seen in several pings (needs poses).
    method : str
        Detection method.
    sound_speed_m_s : float
    sound_speed_source : str
        "recording" or "argument".
    geometry : ArrayGeometry
    unassociated : tuple (n_pings) of int
        Echoes left out of every target.
    source : str
        The recording's path, if any.
    poses : ndarray, shape (n_pings, 6), or None
        Head pose of each ping in the tank, when known.
    """

    targets: tuple[tuple[Target, ...], ...]
    fused: tuple[FusedTarget, ...]
    method: str
    sound_speed_m_s: float
    sound_speed_source: str
    geometry: ArrayGeometry = field(repr=False)
    unassociated: tuple[int, ...] = ()
    source: str = ""
    poses: NDArray[np.float64] | None = field(default=None, repr=False)

    @property
    def n_pings(self) -> int:
        """Number of pings."""
        return len(self.targets)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {
            "source": self.source,
            "method": self.method,
            "sound_speed_m_s": self.sound_speed_m_s,
            "sound_speed_source": self.sound_speed_source,
            "pings": [
                {"ping": k, "pose": None if self.poses is None else [float(v) for v in self.poses[k]],
                 "unassociated_echoes": self.unassociated[k] if k < len(self.unassociated) else 0,
                 "targets": [t.to_dict() for t in ts]}
                for k, ts in enumerate(self.targets)
            ],
            "fused": [f.to_dict() for f in self.fused],
        }


def path_length_std_m(echo: Echo, sound_speed_m_s: float, rms_bandwidth_hz: float | None,
                      tof_floor_s: float = 0.0) -> float:
    """Std (m) of an echo's path length.

    c x sqrt(s^2 + floor^2) with s the echo's ``tof_std_s``, else the CRLB from its ``snr_db``
    and the RMS bandwidth; NaN when neither is known.
    """
    from binsonar.bounds import snr_db_to_linear, tof_crlb_s

    if math.isfinite(echo.tof_std_s) and echo.tof_std_s > 0:
        s = echo.tof_std_s
    elif rms_bandwidth_hz is not None and math.isfinite(echo.snr_db):
        s = float(tof_crlb_s(snr_db_to_linear(echo.snr_db), rms_bandwidth_hz))
    else:
        return float("nan")
    return sound_speed_m_s * math.hypot(s, tof_floor_s)


def localize_ping(echoes: tuple[tuple[Echo, ...], ...], geometry: ArrayGeometry, sound_speed_m_s: float, *,
                  ping: int = 0, rms_bandwidth_hz: float | None = None, pose: ArrayLike | None = None,
                  config: LocalizationConfig | None = None) -> tuple[list[Target], int]:
    """Targets of one ping from its echoes per channel (left, centre, right).

    Returns
    -------
    targets : list of Target
    unassociated : int
        Echoes not used by any target.
    """
    cfg = config or LocalizationConfig()
    if len(echoes) != 3:
        raise LocalizationError(f"ping {ping}: need echoes for 3 channels, got {len(echoes)}")
    lengths = [np.array([sound_speed_m_s * e.tof_s for e in ch], dtype=float) for ch in echoes]
    sigmas = [np.array([path_length_std_m(e, sound_speed_m_s, rms_bandwidth_hz, cfg.tof_floor_s) for e in ch],
                       dtype=float)
              for ch in echoes]
    for ch, s in enumerate(sigmas):
        if s.size and not np.all(np.isfinite(s)):
            raise LocalizationError(
                f"ping {ping}, channel {ch}: echoes carry no tof_std_s and no RMS bandwidth is known "
                "(no template in the recording): pass rms_bandwidth_hz")
    groups = associate(lengths, sigmas, geometry, cfg.gate_n_sigma, cfg.min_range_m)
    targets = []
    used = 0
    for grp in groups:
        idx = (grp.left, grp.centre, grp.right)
        L = np.array([lengths[c][i] if i is not None else np.nan for c, i in enumerate(idx)])
        S = np.array([sigmas[c][i] if i is not None else np.nan for c, i in enumerate(idx)])
        ech = tuple(echoes[c][i] if i is not None else None for c, i in enumerate(idx))
        used += sum(i is not None for i in idx)
        t = target_from_path_lengths(L, S, geometry, ping=ping, echoes=ech, config=cfg.estimation)
        clipped = [c for c, e in enumerate(ech) if e is not None and getattr(e, "clipped", False)]
        if clipped:
            t = replace(t, message=f"{t.message}; echoes on clipped channel(s) {clipped} (unreliable)")
        if pose is not None:
            t = t.with_pose(pose)
        targets.append(t)
    targets.sort(key=lambda t: (math.isnan(t.range_m), t.range_m))
    return targets, sum(len(ch) for ch in echoes) - used


def localize(
    data: Recording | DetectionResult,
    *,
    method: str = "ca-cfar",
    sound_speed_m_s: float | None = None,
    channel_positions_m: ArrayLike | None = None,
    pose: ArrayLike | None = None,
    rms_bandwidth_hz: float | None = None,
    config: LocalizationConfig | None = None,
    **detect_options: Any,
) -> LocalizationResult:
    """Localise and classify the reflectors of a recording (or of detections made already).

    Parameters
    ----------
    data : Recording or DetectionResult
        A recording is passed to ``binsonar.detection.detect(data, method, **detect_options)``.
    method : str
        Detection method (ignored for a DetectionResult, whose own method is reported). The
        default, "ca-cfar", reports every echo; "matched" reports only the strongest per channel.
    sound_speed_m_s : float, optional
        Used when the recording has none (a DetectionResult needs it).
    channel_positions_m : array_like (3, 3), optional
        Head-frame positions of left, centre, right (the centre transmits); default the
        recording's; required with a DetectionResult.
    pose : array_like (6,) or (n_pings, 6), optional
        Head pose(s) in the tank; default the recording's.
    rms_bandwidth_hz : float, optional
        Envelope RMS bandwidth (Hz) for the CRLB of echoes without ``tof_std_s``; default from
        the recording's template.
    config : LocalizationConfig, optional
    **detect_options
        Passed to the detector.

    Returns
    -------
    LocalizationResult

    Raises
    ------
    LocalizationError
        No sound speed, no geometry, or no noise model (a one-line message).
    """
    cfg = config or LocalizationConfig()
    source = ""
    c_source = "argument"
    if isinstance(data, Recording):
        from binsonar.detection import detect  # the detectors' module (issue 5)

        source = data.source
        detections = detect(data, method, **detect_options)
        positions = data.channel_positions_m if channel_positions_m is None else channel_positions_m
        poses = data.pose if pose is None else pose
        c = data.sound_speed_m_s
        if c is not None:
            c_source = "recording"
        else:
            c = sound_speed_m_s
        if rms_bandwidth_hz is None and data.template is not None:
            from binsonar.bounds import rms_bandwidth_hz as bandwidth

            rms_bandwidth_hz = bandwidth(data.template.samples, data.template.sample_rate_hz)
    elif isinstance(data, DetectionResult):
        detections = data
        positions, poses, c = channel_positions_m, pose, sound_speed_m_s
        if positions is None:
            raise LocalizationError("localize: channel_positions_m is required with a DetectionResult")
    else:
        raise LocalizationError(f"localize: expected a Recording or a DetectionResult, got {type(data).__name__}")
    where = source or "localize"
    if c is None:
        raise LocalizationError(f"{where}: no sound speed (the recording has no /environment sound_speed_m_s): "
                                "pass sound_speed_m_s")
    if not (math.isfinite(c) and 1000.0 < c < 2000.0):
        raise LocalizationError(f"{where}: sound_speed_m_s out of range: {c!r}")
    try:
        geometry = ArrayGeometry.from_channel_positions(positions)
    except ValueError as exc:
        raise LocalizationError(f"{where}: {exc}") from None
    n_pings = detections.n_pings
    pose_arr: NDArray[np.float64] | None = None
    if poses is not None:
        try:
            given = np.array(poses, dtype=float)
        except (TypeError, ValueError):
            given = poses  # as_poses names the problem
        if (n_pings == 1 and isinstance(given, np.ndarray) and given.ndim == 2 and given.shape[0] > 1
                and given.shape[1] == 6):
            # The pings were averaged into one: that is meaningful only for one pose.
            if not np.allclose(given, given[0], rtol=0.0, atol=1e-9):
                raise LocalizationError(f"{where}: the {given.shape[0]} averaged pings were recorded at "
                                        "different poses; average pings of one pose only")
            given = given[:1]
        try:
            pose_arr = as_poses(given, n_pings, where)
        except RecordingError as exc:
            raise LocalizationError(str(exc)) from None

    per_ping: list[tuple[Target, ...]] = []
    unassociated: list[int] = []
    for k in range(n_pings):
        ts, left_out = localize_ping(detections.echoes[k], geometry, float(c), ping=k,
                                     rms_bandwidth_hz=rms_bandwidth_hz,
                                     pose=None if pose_arr is None else pose_arr[k], config=cfg)
        per_ping.append(tuple(ts))
        unassociated.append(left_out)

    fused: list[FusedTarget] = []
    if cfg.fuse and pose_arr is not None and n_pings >= cfg.min_pings_to_fuse:
        everything = [t for ts in per_ping for t in ts]
        for group in group_across_pings(everything, cfg.track_gate_m):
            if len(group) >= cfg.min_pings_to_fuse:
                fused.append(fuse(observations_of(group), geometry, cfg.estimation))
    return LocalizationResult(tuple(per_ping), tuple(fused), detections.method, float(c), c_source, geometry,
                              tuple(unassociated), source, pose_arr)
