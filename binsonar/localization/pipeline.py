"""``localize``: from a recording (or detections) to classified targets per ping, and fused targets.

Steps per ping: path lengths L = c x TOF and their stds (the echo's ``tof_std_s``, else the
Cramer-Rao bound from its ``snr_db`` and the template's RMS envelope bandwidth), association of
echoes across channels, point/circle/plane fits and classification, then the tank frame from the
ping's pose. With several pings and known poses, targets are grouped across pings and fused.

Beam-aware by default: when the recording describes its transducers as pistons
(``ArrayDescription.transducers()``) and carries its template, each associated group of echoes
is re-timed with the echo the beam makes (``beam_targets.refine_target``: the directivities at
the target's angles, for an edge the line integral along it), its stds from that echo's SNR and
bandwidth, before the fits. Association then allows the plain matched filter's beam bias
(``LocalizationConfig.beam_association_floor_s``), and a centre echo with one side echo is a
target too when the cued search finds the other side (a weak edge next to a strong one). Which
expected echo: the point model for every target; where the fits say "point" (or cannot tell),
also the vertical edge's, and the one that explains more of the echoes' energy is kept
(``beam_targets.model_fit_snr``, both at one noise level per channel: a likelihood ratio;
``LocalizationConfig.echo_model`` fixes one instead). Then the joint search
(``joint_search``: the three channels summed along hypothesised positions, at a stated
false-alarm probability) finds the targets whose echo crossed the detector on one channel only,
or on none; its hits are timed and fitted like the groups (``joint_targets``).
``LocalizationConfig(beam=False)`` (the command line's ``--no-beam``) keeps the plain matched
filter's times, without the joint search.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.detection.echo import DetectionResult, Echo
from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.association import associate, trailing_echoes
from binsonar.localization.beam_refine import BeamRefinementConfig
from binsonar.localization.beam_targets import ECHO_MODELS, BeamSetup, PingNoise, RefinedTarget, refine_target
from binsonar.localization.classify import POINT, UNKNOWN
from binsonar.localization.estimate import EstimationConfig, target_from_path_lengths
from binsonar.localization.fusion import FusedTarget, fuse, group_across_pings, observations_of
from binsonar.localization.joint_search import JointSearchConfig, JointSetup, joint_search
from binsonar.localization.target import STATUS_AMBIGUOUS, Target
from binsonar.recording import Recording, RecordingError, as_poses

ECHO_MODEL_CHOICES: tuple[str, ...] = ("auto",) + ECHO_MODELS
JOINT_SEARCH_METHODS: tuple[str, ...] = ("ca-cfar", "os-cfar")
"""Detectors after which the joint search runs: those that report every echo above their
threshold, so that what they did not report is noise or an echo too weak for one channel (after
"matched", which reports one echo per channel, the other strong echoes would look new)."""
JOINT_SEARCH_MIN_TEMPLATES = 8
"""The joint search needs a record at least this many templates long (its noise windows)."""
"""``LocalizationConfig.echo_model``: "auto" chooses per target, the others fix the expected echo."""


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
        Systematic TOF uncertainty (s) added in quadrature to the std of every echo timed by the
        plain matched filter (no beam model). The detectors' ``tof_std_s`` (CRLB-like, ~1 ns at
        60 dB) omits template mismatch: the beam's per-frequency directivity off axis, and
        echoes from extended or curved reflectors whose spectra the scattering tilts, move the
        matched-filter peak; on the simulator's free-post, free-plane and free-cylinder scenes
        this bias is 20-70 ns (30-105 um of path), microseconds near a side receiver's null.
        The default, 50 ns, is one sample at 20 MS/s. Set 0 to trust the detector's std alone.
    min_range_m : float
        Echo pairs implying a reflector closer than this to the transmitter (m) are not
        targets: the transmitter's direct cross-talk to the side receivers (at |T - R| / c,
        44 us for d = 65 mm) and the ringing around it. The default, 5 cm, is a few transducer
        diameters.
    beam : bool
        Re-time the echoes with the beam's expected echo when the recording describes its
        transducers as pistons and carries its template (module docstring). False: the plain
        matched filter's times.
    beam_refinement : BeamRefinementConfig
        Iterations, search windows and the cued search of the refinement (its
        ``model.target`` is set per target; ``model.wedge_interior_angle_deg`` applies to
        edges).
    joint_search : JointSearchConfig
        The joint multi-channel search for targets whose echo crosses the detector on one
        channel or none (``joint_search``; beam-aware pipeline after a CFAR detector only,
        ``JOINT_SEARCH_METHODS``). ``enabled=False`` turns it off (the command line's
        ``--no-joint``).
    beam_tof_floor_s : float
        Systematic TOF uncertainty (s) added in quadrature to the std of beam-timed echoes. 0
        by default: the expected echo models the beam and the target class, and the std follows
        the beam-filtered echo's SNR and bandwidth (``beam_targets``).
    beam_association_floor_s : float
        TOF uncertainty (s) added in quadrature to the plain times when echoes are associated
        ahead of the refinement: the plain matched filter is biased by up to about 3.5 us on a
        side channel near its null (simulated posts and edges at 0.3 m, 10 deg), which 4
        standard deviations of 1 us cover.
    echo_model : {"auto", "point", "vertical-edge"}
        "auto": the point model's echo for every target, and where the fits say point (or
        cannot tell) also the vertical edge's, keeping the one with the better fit
        (``beam_targets.model_fit_snr``);
        otherwise that model for every target.
    ringing_span_s : float
        Echoes arriving up to this long (s) after an earlier echo on the same channel that is at
        most ``ringing_margin_db`` weaker are grouped after the others (``association``: a
        body's elastic and internal echoes must not claim its specular echo). The default,
        100 us (148 mm of path), covers the compressional echo through the diameter of the
        tank's 25 mm PVC and concrete posts (about 42 us behind the specular echo) and their
        creeping waves ((2 + pi) a of path, 87 us), and stays shorter than the 180 mm of path
        between the edge prism's apex and its corners. 0: one stage, in gate order only.
    ringing_margin_db : float
        How much weaker (dB) the earlier echo may be.
    """

    estimation: EstimationConfig = field(default_factory=EstimationConfig)
    gate_n_sigma: float = 4.0
    fuse: bool = True
    track_gate_m: float = 0.15
    min_pings_to_fuse: int = 3
    tof_floor_s: float = 50e-9
    min_range_m: float = 0.05
    beam: bool = True
    beam_refinement: BeamRefinementConfig = field(default_factory=BeamRefinementConfig)
    joint_search: JointSearchConfig = field(default_factory=JointSearchConfig)
    beam_tof_floor_s: float = 0.0
    beam_association_floor_s: float = 1e-6
    echo_model: str = "auto"
    ringing_span_s: float = 100e-6
    ringing_margin_db: float = 6.0

    def __post_init__(self) -> None:
        for name in ("tof_floor_s", "beam_tof_floor_s", "beam_association_floor_s", "ringing_span_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and 0 <= value <= 1e-3):
                raise LocalizationError(f"{name} must be within 0-1e-3 s, got {value!r}")
        if not (math.isfinite(self.min_range_m) and self.min_range_m >= 0):
            raise LocalizationError(f"min_range_m must be >= 0, got {self.min_range_m!r}")
        if not (isinstance(self.ringing_margin_db, (int, float)) and math.isfinite(self.ringing_margin_db)):
            raise LocalizationError(f"ringing_margin_db must be a finite number (dB), got {self.ringing_margin_db!r}")
        if not self.gate_n_sigma > 0:
            raise LocalizationError(f"gate_n_sigma must be > 0, got {self.gate_n_sigma!r}")
        if not isinstance(self.beam, bool):
            raise LocalizationError(f"beam must be True or False, got {self.beam!r}")
        if self.echo_model not in ECHO_MODEL_CHOICES:
            raise LocalizationError(f"echo_model must be one of {', '.join(ECHO_MODEL_CHOICES)}, got {self.echo_model!r}")


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
    beam : str
        How the echoes were timed: "pistons D_left/D_centre/D_right mm" when beam-aware, else
        why not ("off", "no array description", ...).
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
    beam: str = "off"

    @property
    def n_pings(self) -> int:
        """Number of pings."""
        return len(self.targets)

    @property
    def beam_aware(self) -> bool:
        """Whether the echoes were re-timed with the beam's expected echo."""
        return self.beam.startswith("pistons")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {
            "source": self.source,
            "method": self.method,
            "sound_speed_m_s": self.sound_speed_m_s,
            "sound_speed_source": self.sound_speed_source,
            "beam_aware": self.beam_aware,
            "beam": self.beam,
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


@dataclass(frozen=True, eq=False)
class PingBeam:
    """One ping's samples and noise for the beam-aware refinement.

    Attributes
    ----------
    setup : BeamSetup
    noise : PingNoise
        The ping's samples (V) and detected echoes.
    joint : JointSetup or None
        The joint search's plan (None: no joint search).
    """

    setup: BeamSetup
    noise: PingNoise = field(repr=False)
    joint: JointSetup | None = None

    @property
    def rows(self) -> NDArray[np.float64]:
        """The ping's channels (3, n) (V)."""
        return self.noise.rows

    @classmethod
    def of(cls, rows: ArrayLike, setup: BeamSetup, echoes: tuple[tuple[Echo, ...], ...] = ((), (), ()),
           joint: JointSetup | None = None) -> "PingBeam":
        """The ping ``rows`` (3, n) (V) and its detected ``echoes`` (left out of the noise estimates)."""
        busy = tuple(np.array([e.tof_s for e in channel], dtype=float) for channel in echoes)
        return cls(setup, PingNoise(np.asarray(rows, dtype=float), setup.sample_rate_hz, setup.t0_s, busy,
                                    setup.busy_half_width_s), joint)


def _refined_target(refined: RefinedTarget, geometry: ArrayGeometry, c: float, ping: int,
                    cfg: LocalizationConfig) -> Target:
    """The fitted, classified target of refined echoes."""
    tof = np.array([np.nan if e is None else e.tof_s for e in refined.echoes])
    std = np.array([np.nan if e is None else math.hypot(e.tof_std_s, cfg.beam_tof_floor_s) for e in refined.echoes])
    prefer = POINT if refined.model == "vertical-edge" else None  # a diffracting edge, not a wall
    target = target_from_path_lengths(c * tof, c * std, geometry, ping=ping, echoes=refined.echoes,
                                      config=cfg.estimation, prefer=prefer)
    return replace(target, echo_model=refined.model)


def beam_timed_target(echoes: tuple[Echo | None, ...], geometry: ArrayGeometry, c: float, ping: int,
                      beam: PingBeam, cfg: LocalizationConfig) -> Target | None:
    """One group of echoes re-timed with the expected echo and fitted (module docstring); None
    when the group cannot be located (a side channel still missing after the cued search)."""
    first_model = "vertical-edge" if cfg.echo_model == "vertical-edge" else "point"
    first = refine_target(echoes, beam.setup, beam.noise, first_model)
    if first is None:
        return None
    target = _refined_target(first, geometry, c, ping, cfg)
    could_be_edge = target.cls in (POINT, UNKNOWN) or target.status == STATUS_AMBIGUOUS
    if cfg.echo_model == "auto" and could_be_edge:
        edge = refine_target(first.echoes, beam.setup, beam.noise, "vertical-edge")
        if edge is not None and edge.output_snr > first.output_snr:
            target = _refined_target(edge, geometry, c, ping, cfg)
    return target


def localize_ping(echoes: tuple[tuple[Echo, ...], ...], geometry: ArrayGeometry, sound_speed_m_s: float, *,
                  ping: int = 0, rms_bandwidth_hz: float | None = None, pose: ArrayLike | None = None,
                  config: LocalizationConfig | None = None, beam: PingBeam | None = None) -> tuple[list[Target], int]:
    """Targets of one ping from its echoes per channel (left, centre, right).

    Parameters
    ----------
    echoes : tuple of 3 tuples of Echo
    geometry : ArrayGeometry
    sound_speed_m_s : float
    ping : int
    rms_bandwidth_hz : float, optional
        For the CRLB of echoes without ``tof_std_s``.
    pose : array_like (6,), optional
    config : LocalizationConfig, optional
    beam : PingBeam, optional
        The ping's samples and the transducers: the echoes are re-timed with the beam's
        expected echo (module docstring). None: the plain times.

    Returns
    -------
    targets : list of Target
    unassociated : int
        Echoes not used by any target.
    """
    cfg = config or LocalizationConfig()
    c = sound_speed_m_s
    if len(echoes) != 3:
        raise LocalizationError(f"ping {ping}: need echoes for 3 channels, got {len(echoes)}")
    lengths = [np.array([c * e.tof_s for e in ch], dtype=float) for ch in echoes]
    sigmas = [np.array([path_length_std_m(e, c, rms_bandwidth_hz, cfg.tof_floor_s) for e in ch], dtype=float)
              for ch in echoes]
    for ch, s in enumerate(sigmas):
        if s.size and not np.all(np.isfinite(s)):
            raise LocalizationError(
                f"ping {ping}, channel {ch}: echoes carry no tof_std_s and no RMS bandwidth is known "
                "(no template in the recording): pass rms_bandwidth_hz")
    if beam is not None:
        gate_sigmas = [np.hypot(s, c * cfg.beam_association_floor_s) for s in sigmas]
    else:
        gate_sigmas = sigmas
    trailing = [trailing_echoes(lengths[ch], [e.amplitude for e in echoes[ch]], c * cfg.ringing_span_s,
                                cfg.ringing_margin_db) for ch in range(3)]
    groups = associate(lengths, gate_sigmas, geometry, cfg.gate_n_sigma, cfg.min_range_m,
                       centre_side_pairs=beam is not None, trailing=trailing)
    # Groups with more detected echoes first: a group that the refinement (or the cued search)
    # brings onto another's echoes is the same reflector, and the first one is kept.
    groups = sorted(groups, key=lambda g: sum(i is None for i in (g.left, g.centre, g.right)))
    targets: list[Target] = []
    used = 0
    claimed = [np.zeros(len(ch), dtype=bool) for ch in echoes]  # echoes of a located reflector
    for grp in groups:
        idx = (grp.left, grp.centre, grp.right)
        ech = tuple(echoes[ch][i] if i is not None else None for ch, i in enumerate(idx))
        if beam is not None:
            timed = beam_timed_target(ech, geometry, c, ping, beam, cfg)
            if timed is None:
                continue
            used += sum(i is not None for i in idx)
            for ch, i in enumerate(idx):
                if i is not None:
                    claimed[ch][i] = True
            if any(same_reflector(timed, other, cfg.gate_n_sigma) for other in targets):
                continue
            t = timed
        else:
            L = np.array([lengths[ch][i] if i is not None else np.nan for ch, i in enumerate(idx)])
            S = np.array([sigmas[ch][i] if i is not None else np.nan for ch, i in enumerate(idx)])
            t = target_from_path_lengths(L, S, geometry, ping=ping, echoes=ech, config=cfg.estimation)
            used += sum(i is not None for i in idx)
        clipped = [ch for ch, e in enumerate(t.echoes) if e is not None and getattr(e, "clipped", False)]
        if clipped:
            t = replace(t, message=f"{t.message}; echoes on clipped channel(s) {clipped} (unreliable)")
        targets.append(t)
    if beam is not None and beam.joint is not None and beam.joint.config.enabled:
        joint, seeds = joint_targets(echoes, claimed, geometry, c, ping, beam, beam.joint, cfg, targets)
        targets.extend(joint)
        used += seeds
    if pose is not None:
        targets = [t.with_pose(pose) for t in targets]
    targets.sort(key=lambda t: (math.isnan(t.range_m), t.range_m))
    return targets, sum(len(ch) for ch in echoes) - used


def joint_targets(echoes: tuple[tuple[Echo, ...], ...], claimed: list[NDArray[np.bool_]], geometry: ArrayGeometry,
                  c: float, ping: int, beam: PingBeam, joint: JointSetup, cfg: LocalizationConfig,
                  targets: list[Target]) -> tuple[list[Target], int]:
    """The joint search's targets (``joint_search``) that are not one of ``targets``, beam-timed and
    fitted like the others, and how many detected echoes (seeds) they use.

    Each joint detection's three delays are re-timed with the expected echo
    (``beam_timed_target``: the point and the edge models); a detection that the refinement
    brings onto a target already found is that target and is dropped.
    """
    found = joint_search(beam.rows, joint, t0_s=beam.setup.t0_s, transmitter_m=geometry.transmitter_m,
                         receivers_m=geometry.receivers_m, echoes=echoes, used=claimed, min_range_m=cfg.min_range_m)
    out: list[Target] = []
    seeds = 0
    for detection in found:
        triple = []
        for ch in range(3):
            if detection.seed is not None and detection.seed[0] == ch:
                triple.append(echoes[ch][detection.seed[1]])
            else:
                triple.append(Echo(channel=ch, tof_s=float(detection.tof_s[ch]),
                                   amplitude=float(detection.amplitude_v[ch]), snr_db=float("nan"),
                                   score=detection.statistic / detection.threshold, ping=ping))
        timed = beam_timed_target(tuple(triple), geometry, c, ping, beam, cfg)
        if timed is None or any(same_reflector(timed, other, cfg.gate_n_sigma) for other in (*targets, *out)):
            continue
        timed = replace(timed, message=f"{timed.message}; joint search (summed {detection.statistic:.1f} over "
                                       f"threshold {detection.threshold:.1f})")
        seeds += detection.seed is not None
        out.append(timed)
    return out, seeds


def same_reflector(a: Target, b: Target, n_sigma: float) -> bool:
    """Whether two beam-timed targets are one reflector: on every channel they both have, their
    TOFs agree within ``n_sigma`` combined standard deviations."""
    common = [(x, y) for x, y in zip(a.echoes, b.echoes) if x is not None and y is not None]
    if len(common) < 2:
        return False
    return all(abs(x.tof_s - y.tof_s) <= n_sigma * math.hypot(x.tof_std_s, y.tof_std_s) for x, y in common)


def beam_setup(header: Any, sound_speed_m_s: float, config: LocalizationConfig,
               transducers: Any = None) -> tuple[BeamSetup | None, str]:
    """The refinement's setup for a recording (or its header), and how the echoes will be timed.

    Parameters
    ----------
    header : Recording or RecordingHeader
        Its ``array``, ``template``, ``sample_rate_hz``, ``t0_s`` and ``channel_positions_m``.
    sound_speed_m_s : float
    config : LocalizationConfig
    transducers : PistonTransducers, optional
        Overrides the array description's.

    Returns
    -------
    setup : BeamSetup or None
        None when the echoes keep their plain times.
    beam : str
        ``LocalizationResult.beam``.
    """
    from binsonar.localization.beam_model import PistonTransducers

    if not config.beam:
        return None, "off"
    if transducers is None:
        array = getattr(header, "array", None)
        transducers = None if array is None else array.transducers()
        if transducers is None:
            return None, "off: the array description does not describe the beams"
    if not isinstance(transducers, PistonTransducers):
        return None, "off: measured beam tables are not modelled by the refinement (pistons only)"
    template = header.template
    if template is None:
        return None, "off: the recording has no template"
    fs = float(header.sample_rate_hz)
    if not math.isclose(template.sample_rate_hz, fs, rel_tol=1e-9):
        return None, "off: the template is at another sample rate than the record"
    positions = np.asarray(header.channel_positions_m, dtype=float)
    setup = BeamSetup(transducers, template, fs, float(header.t0_s), positions, float(sound_speed_m_s),
                      config.beam_refinement)
    mm = "/".join(f"{1e3 * v:.4g}" for v in transducers.diameters_m)
    return setup, f"pistons {mm} mm"


def localize_detections(detections: DetectionResult, geometry: ArrayGeometry, sound_speed_m_s: float, *,
                        config: LocalizationConfig, rms_bandwidth_hz: float | None = None,
                        poses: NDArray[np.float64] | None = None, waveforms: NDArray[np.float64] | None = None,
                        setup: BeamSetup | None = None,
                        first_ping: int = 0) -> tuple[list[tuple[Target, ...]], list[int]]:
    """Targets of every ping of a detection result (``localize_ping``).

    Parameters
    ----------
    detections : DetectionResult
    geometry : ArrayGeometry
    sound_speed_m_s : float
    config : LocalizationConfig
    rms_bandwidth_hz : float, optional
    poses : ndarray (n_pings, 6), optional
        Head pose of each ping.
    waveforms : ndarray (n_pings, 3, n), optional
        The pings' samples (V) the detections came from; with ``setup``, the echoes are
        re-timed with the beam's expected echo.
    setup : BeamSetup, optional
    first_ping : int
        Index given to the first ping (the targets' ``ping``).

    Returns
    -------
    targets : list (n_pings) of tuple of Target
    unassociated : list (n_pings) of int
    """
    per_ping: list[tuple[Target, ...]] = []
    unassociated: list[int] = []
    joint = None
    if (setup is not None and waveforms is not None and config.joint_search.enabled and detections.n_pings
            and detections.method in JOINT_SEARCH_METHODS
            and np.shape(waveforms)[-1] >= JOINT_SEARCH_MIN_TEMPLATES * setup.template.samples.size):
        joint = JointSetup.create(setup.template, setup.transducers, np.shape(waveforms)[-1], setup.sample_rate_hz,
                                  setup.sound_speed_m_s, geometry.receivers_m, config.joint_search)
    for k in range(detections.n_pings):
        beam = None
        if setup is not None and waveforms is not None:
            beam = PingBeam.of(waveforms[k], setup, detections.echoes[k], joint)
        ts, left_out = localize_ping(detections.echoes[k], geometry, float(sound_speed_m_s), ping=first_ping + k,
                                     rms_bandwidth_hz=rms_bandwidth_hz, pose=None if poses is None else poses[k],
                                     config=config, beam=beam)
        per_ping.append(tuple(ts))
        unassociated.append(left_out)
    return per_ping, unassociated


def fuse_pings(per_ping: list[tuple[Target, ...]], geometry: ArrayGeometry, config: LocalizationConfig,
               have_poses: bool) -> tuple[FusedTarget, ...]:
    """Targets grouped across pings and fused (needs poses and ``config.min_pings_to_fuse`` pings)."""
    fused: list[FusedTarget] = []
    if config.fuse and have_poses and len(per_ping) >= config.min_pings_to_fuse:
        everything = [t for ts in per_ping for t in ts]
        for group in group_across_pings(everything, config.track_gate_m):
            if len(group) >= config.min_pings_to_fuse:
                fused.append(fuse(observations_of(group), geometry, config.estimation))
    return tuple(fused)


def check_sound_speed(c: float | None, where: str) -> float:
    """The sound speed (m/s) within 1000-2000 m/s, else a one-line LocalizationError."""
    if c is None:
        raise LocalizationError(f"{where}: no sound speed (the recording has no /environment sound_speed_m_s): "
                                "pass sound_speed_m_s")
    if not (math.isfinite(c) and 1000.0 < c < 2000.0):
        raise LocalizationError(f"{where}: sound_speed_m_s out of range: {c!r}")
    return float(c)


def localize(
    data: Recording | DetectionResult,
    *,
    method: str = "ca-cfar",
    sound_speed_m_s: float | None = None,
    channel_positions_m: ArrayLike | None = None,
    pose: ArrayLike | None = None,
    rms_bandwidth_hz: float | None = None,
    config: LocalizationConfig | None = None,
    transducers: Any = None,
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
        ``beam=True`` (default) re-times a recording's echoes with its beams when its array
        description gives them as pistons (a DetectionResult has no samples: plain times).
    transducers : PistonTransducers, optional
        The recording's pistons when its array description has none (or to override it).
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
    waveforms: NDArray[np.float64] | None = None
    setup: BeamSetup | None = None
    beam = "off: detections without samples"
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
    c = check_sound_speed(c, where)
    try:
        geometry = ArrayGeometry.from_channel_positions(positions)
    except ValueError as exc:
        raise LocalizationError(f"{where}: {exc}") from None
    n_pings = detections.n_pings
    if isinstance(data, Recording):
        setup, beam = beam_setup(data, c, cfg, transducers)
        if setup is not None:
            if channel_positions_m is not None:
                setup = replace(setup, channel_positions_m=np.asarray(channel_positions_m, dtype=float))
            waveforms = np.asarray(data.waveforms, dtype=float)
            if n_pings == 1 and waveforms.shape[0] > 1:
                waveforms = waveforms.mean(axis=0, keepdims=True)  # the averaging methods' one ping
    pose_arr = pose_array(poses, n_pings, where)
    per_ping, unassociated = localize_detections(detections, geometry, c, config=cfg, rms_bandwidth_hz=rms_bandwidth_hz,
                                                 poses=pose_arr, waveforms=waveforms, setup=setup)
    fused = fuse_pings(per_ping, geometry, cfg, pose_arr is not None)
    return LocalizationResult(tuple(per_ping), fused, detections.method, c, c_source, geometry,
                              tuple(unassociated), source, pose_arr, beam)


def pose_array(poses: Any, n_pings: int, where: str) -> NDArray[np.float64] | None:
    """The head poses (n_pings, 6), or None; averaged pings must share one pose."""
    if poses is None:
        return None
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
        return as_poses(given, n_pings, where)
    except RecordingError as exc:
        raise LocalizationError(str(exc)) from None
