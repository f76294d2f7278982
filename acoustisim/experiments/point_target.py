"""The edge-target measurement of the seed's section 4.2.3 (range and angle sweeps).

Scene: the 9 m x 3 m x 1 m concrete tank of fresh water with one steel prism whose sharp
60-degree vertical edge (the seed's "sharp edge of a triangle", a point target in the
horizontal plane) faces the sonar at ``EDGE_M``. The prism is ``PRISM_SIZE_M`` deep, so its two
rear edges (which diffract more strongly than the front one, being seen near grazing) lie
about 0.43 m behind the front edge, outside the range gate.

One position: the sonar placed so that the edge is at a given range and bearing, the head
turned so that the line to the edge stays on the prism's bisector (``pose_for_target`` with
yaw = bearing); ``n_pings`` pings averaged (the seed's 50); the record gated to the edge's
range +/- ``GATE_HALF_WIDTH_M`` (blanking the main bang and the cross-talk); each detector's
earliest echo on the left and right channels gives the path lengths L = c TOF and the seed's
exact point solution (eqs. 4.30 and the corrected 4.31, ``binsonar.localization.point``).

The bound (``noise_bound``): the Cramer-Rao bound at the measured SNR of the averaged ping,
1 / (2 pi beta sqrt(2E/N0)) with beta the template's RMS bandwidth and 2E/N0 the matched
filter's output SNR of the edge's noise-free echo in the ping's actual noise (the record minus
the noise-free record), on the left and right channels, propagated through the localiser's
linearised covariance (``seed_point_covariance``) to range and bearing. It bounds the noise's
part of the error only. Kept alongside: the detector's own bound (``Echo.tof_std_s``, whose
noise floor includes the frozen reverberation), the optimal bound of the received echo's
spectrum in the noise's spectrum (``echo_tof_crlb_s``), and the bound with the diffuse
reverberation counted as Gaussian interference at its level at the echo's delay
(``reverb_bound``). With ``fresh_reverberation`` every repeat draws a new realisation of the
diffuse field, so the RMS over repeats is an estimate over that ensemble, which is what this last
bound is an expectation over; by default the realisation is frozen, as in one tank.

The threshold detector is the seed's: a preset level and an offset calibrated once per sweep
(``calibrate_threshold``).

``BEAM_MATCHED`` ("beam-matched") is the matched filter's echoes refined by binsonar's
beam-aware TOF estimator (``binsonar.localization.beam_refine``) with the beams and the baseline
the recording's array description gives (``recording_array``: the simulated head's pistons, as
the simulator writes them into every recording) and the target class (``beam_config``: a vertical
edge, a rigid 60-degree wedge facing the sonar). Its CPU time includes the matched filter's pass.

The deterministic part: every repeat of a position has the same echo and only new noise, so
the error splits into a bias, the same in every repeat, and a scatter. The bias is measured
directly by running each detector on the noise-free averaged record (``Simulation.clean``),
picking per channel the detected echo nearest the true time of flight, and decomposed by
re-synthesising the noise-free record from subsets of the paths: the edge's diffraction
alone (the beam's effect on the extended edge's echo), plus the specular paths (walls, floor,
surface), plus the diffuse reverberation (everything).

The prism's faces: machined steel, the library's "steel-machined" (``prism_material``). Its
Lambert strength is not a sea-floor value: it follows from first-order small-perturbation
scattering for an rms roughness of ``PRISM_RMS_ROUGHNESS_M`` (``small_roughness_lambert_mu``; the
library's "steel", mu = 0.002, is a rusted or sand-blasted face). Being a library material, it is
what the recording's truth scene names: the paths and the truth come from the same scene.
"""

from __future__ import annotations

import math
import time
import warnings
from typing import Any

import numpy as np

from acoustisim.experiments.gating import gate_recording, range_window_s
from acoustisim.experiments.geometry import pose_for_target
from acoustisim.experiments.runner import Trial
from acoustisim.experiments.truth import object_truth
from acoustisim.scene import Scene, Tank

EDGE_M: tuple[float, float] = (6.0, 1.5)
"""Tank-frame (x, y) of the prism's sharp edge (m): 6 m from the near wall, mid-width."""
PRISM_SIZE_M = 0.5
"""Depth of the prism (m): its rear edges are 0.43 m behind the front edge."""
GATE_HALF_WIDTH_M = 0.1
"""Half depth of the range gate around the edge (m): +/-135 us, many envelope widths, and short of
the prism's rear edges (0.43 m behind). With the head on the tank's centre line at mid-depth, the
floor and surface (0.5 m away) and the side walls (1.5 m) still fall inside it at ranges within
0.1 m of theirs; a wider gate (0.2 m) let them in over twice those spans."""
DETECTORS: tuple[str, ...] = ("threshold", "matched")
"""The seed's two detectors."""
BEAM_MATCHED = "beam-matched"
"""The matched filter followed by binsonar's beam-aware TOF refinement
(``binsonar.localization.beam_refine``) with the simulated sonar's pistons and a vertical-edge
target: an experiment-level detector name (not a ``binsonar.detection`` method)."""


PRISM_ANGLE_DEG = 60.0
"""Interior angle of the prism at its sharp edge (deg)."""
PRISM_RMS_ROUGHNESS_M = 3e-6
"""RMS roughness of the prism's faces (m): machined or cold-rolled steel plate (Ra 0.8-3.2 um,
rms about 1.25 Ra)."""
BOUNDED_DETECTORS: tuple[str, ...] = ("matched", BEAM_MATCHED)
"""Detectors whose errors are compared with the CRLB-derived bound (range and bearing RMS / bound)."""
TOF_MATCH_S = 5e-6
"""A noise-free echo further than this from the true TOF (s, one pulse length) is not the edge's."""


def small_roughness_lambert_mu(rms_roughness_m: float, frequency_hz: float, sound_speed_m_s: float,
                               incidence_deg: float) -> float:
    """Lambert strength equivalent to a slightly rough hard face's backscatter (upper bound over correlation lengths).

    First-order small-perturbation (Rayleigh-Rice) backscatter of a rigid (Neumann) surface, the
    limit for steel in water (impedance ratio about 31), per unit area and solid angle:
    sigma = k^4 (1 + sin^2 t)^2 W(2 k sin t), t the incidence angle from the normal and W the
    roughness's 2-D spectrum (Thorsos and Jackson 1989 give the Dirichlet form 4 k^4 cos^4 t W;
    the Neumann factor follows from the same boundary perturbation). For a Gaussian correlation
    of rms h and length L, W(K) = h^2 L^2 / (4 pi) exp(-K^2 L^2 / 4), largest at L = 2 / K:
    W <= h^2 / (pi e K^2). The Lambert law sigma = mu sin(g_i) sin(g_s) = mu cos^2 t in
    backscatter then gives mu. Valid for k h << 1.

    Parameters
    ----------
    rms_roughness_m : float
        RMS height h (m).
    frequency_hz, sound_speed_m_s : float
        The wavenumber k = 2 pi f / c.
    incidence_deg : float
        Incidence angle from the face's normal (deg), in (0, 90).

    Returns
    -------
    float
        The Lambert strength mu that gives the same backscatter at that angle.
    """
    k = 2.0 * math.pi * frequency_hz / sound_speed_m_s
    t = math.radians(incidence_deg)
    if not (0.0 < t < 0.5 * math.pi and rms_roughness_m >= 0.0):
        raise ValueError(f"need 0 < incidence < 90 deg and h >= 0, got {incidence_deg!r}, {rms_roughness_m!r}")
    big_k = 2.0 * k * math.sin(t)
    w_max = rms_roughness_m ** 2 / (math.pi * math.e * big_k ** 2)
    sigma = k ** 4 * (1.0 + math.sin(t) ** 2) ** 2 * w_max
    return sigma / math.cos(t) ** 2


PRISM_MATERIAL = "steel-machined"
"""The prism's library material: steel with the Lambert strength of ``PRISM_RMS_ROUGHNESS_M`` at
500 kHz and 60 deg incidence (``acoustisim.materials``' docstring gives the derivation)."""


def prism_material() -> Any:
    """The library's machined steel ("steel-machined"), the prism's material.

    Its ``diffuse_mu`` is ``small_roughness_lambert_mu(PRISM_RMS_ROUGHNESS_M, 500 kHz, 1482 m/s,
    60 deg)`` to 3 significant digits: the faces of a prism seen along its bisector are at
    90 - angle / 2 deg from the line of sight (incidence 60 deg for the 60-degree prism).
    """
    from acoustisim.materials import get_material

    return get_material(PRISM_MATERIAL)


def edge_tank_scene(prism: Any = None) -> Scene:
    """The thesis tank with only the 60-degree prism facing -x (toward the sonar).

    Parameters
    ----------
    prism : Material or str, optional
        The prism's material; default ``prism_material()`` (machined steel). With a library
        material, ``simulate`` writes the scene into a recording's truth (a scene file names
        library materials only).
    """
    from acoustisim.medium import Medium
    from scenes.builders import default_sonar, edge_prism

    tank = Tank(length_m=9.0, width_m=3.0, water_depth_m=1.0, wall_material="concrete", floor_material="concrete")
    edge = edge_prism("edge", EDGE_M, PRISM_ANGLE_DEG, 180.0, PRISM_SIZE_M, tank.water_depth_m,
                      prism_material() if prism is None else prism)
    medium = Medium(water="fresh", temperature_c=20.0, salinity_ppt=0.0, depth_m=0.5)
    return Scene(name="edge-tank", medium=medium, sonar=default_sonar(), tank=tank, objects=(edge,))


def estimate_point(echoes: tuple[Any, Any, Any], sound_speed_m_s: float, half_baseline_m: float) -> tuple[float, float]:
    """Range (m) and bearing (deg) from the left and right echoes; NaN when one is missing."""
    from binsonar.localization.point import point_from_path_lengths

    left, _, right = echoes
    if left is None or right is None:
        return float("nan"), float("nan")
    r, th = point_from_path_lengths(sound_speed_m_s * left.tof_s, sound_speed_m_s * right.tof_s, half_baseline_m)
    return float(r), float(np.degrees(th))


def bound_of(echoes: tuple[Any, Any, Any], range_m: float, bearing_deg: float, sound_speed_m_s: float,
             half_baseline_m: float) -> tuple[float, float]:
    """CRLB-derived std of range (m) and bearing (deg) from the echoes' ``tof_std_s``."""
    from binsonar.localization.point import seed_point_covariance

    left, _, right = echoes
    if left is None or right is None or not (math.isfinite(left.tof_std_s) and math.isfinite(right.tof_std_s)):
        return float("nan"), float("nan")
    cov = seed_point_covariance(range_m, math.radians(bearing_deg), half_baseline_m,
                                sound_speed_m_s * left.tof_std_s, sound_speed_m_s * right.tof_std_s)
    return float(math.sqrt(cov[0, 0])), float(math.degrees(math.sqrt(cov[1, 1])))


SWEEP_MAX_ORDER = 4
"""Most reflections per specular path in the sweeps: the engine's maximum
(``acoustisim.propagation.paths.MAX_INTERACTIONS``). In a tank of depth H = 1 m the head's
vertical multiples (floor and surface, 90 deg off every axis) return at ranges k H / 2 for a head
at mid-depth and at k H for any depth: the floor-surface pair (order 2) at 1.0 m, order 3 at
1.5 m, order 4 at 2.0 m. Order 5, which returns at 2.5 m, is not modelled."""


def solver_config(params: dict[str, Any]) -> Any:
    """Propagation settings of a trial: ``max_order`` (default ``SWEEP_MAX_ORDER``), no amplitude
    floor, the diffuse tracer's ``diffuse_seed`` (default 0) and, with ``reverberation`` False,
    no diffuse mechanism (no Lambert reverberation from the floor, surface, walls and the prism's
    faces)."""
    from acoustisim.propagation import SolverConfig
    from acoustisim.propagation.config import MECHANISMS

    mechanisms = MECHANISMS if params.get("reverberation", True) else tuple(m for m in MECHANISMS if m != "diffuse")
    # No amplitude floor: the floor is judged at 500 kHz, where the pistons' directivity has its
    # first null at 11 deg; the broadband edge echo there (carried by 300-400 kHz) is 90 dB below the
    # walls' specular echoes and would be dropped, leaving only other returns in the gate.
    return SolverConfig(max_order=int(params.get("max_order", SWEEP_MAX_ORDER)), mechanisms=mechanisms,
                        amplitude_floor_db=None, seed=int(params.get("diffuse_seed", 0)))


NOISE_FREE_PARTS: tuple[str, ...] = ("edge", "specular", "all")
"""Noise-free records of a position: the edge's diffraction alone; plus the direct and specular
paths (walls, floor, surface); everything (plus the diffuse reverberation)."""


def path_subsets(paths: Any) -> dict[str, Any]:
    """The ``NOISE_FREE_PARTS`` as row masks of ``paths`` (cumulative: each adds mechanisms)."""
    from acoustisim.propagation.paths import PathKind

    kind = paths.rows["kind"]
    edge = kind == PathKind.EDGE
    return {"edge": edge, "specular": kind != PathKind.DIFFUSE, "all": np.ones(kind.shape, dtype=bool)}


def nearest_echoes(result: Any, truth_tof_s: Any) -> tuple[Any, Any, Any]:
    """Per channel, the detected echo nearest the true TOF (None when none lies within ``TOF_MATCH_S``)."""
    out = []
    for ch, echoes in enumerate(result.echoes[0]):
        best = min(echoes, key=lambda e: abs(e.tof_s - truth_tof_s[ch]), default=None)
        out.append(best if best is not None and abs(best.tof_s - truth_tof_s[ch]) <= TOF_MATCH_S else None)
    return out[0], out[1], out[2]


def recording_array(recording: Any) -> tuple[float, Any]:
    """What binsonar learns from the recording about its head: half the left-right baseline (m,
    from its channel positions) and the beams (``recording.array.transducers()``: the simulated
    head's pistons, as the simulator describes them in every recording; None without a
    description)."""
    from binsonar.localization.array_geometry import ArrayGeometry

    half_baseline = ArrayGeometry.from_channel_positions(recording.channel_positions_m).half_baseline_m
    array = getattr(recording, "array", None)
    return half_baseline, (array.transducers() if array is not None else None)


def beam_config() -> Any:
    """binsonar's beam-aware refinement for the sweeps' target: a vertical edge, a rigid 60-degree
    wedge facing the sonar (``PRISM_ANGLE_DEG``; the head is turned so that it looks along the
    prism's bisector), the refinement's other settings at their defaults."""
    from binsonar.localization.beam_model import BeamModelConfig
    from binsonar.localization.beam_refine import BeamRefinementConfig

    return BeamRefinementConfig(model=BeamModelConfig(target="vertical-edge", wedge_interior_angle_deg=PRISM_ANGLE_DEG))


def beam_matched_echoes(recording: Any, matched: Any, transducers: Any, sound_speed_m_s: float) -> tuple[Any, Any, Any]:
    """The matched filter's first echoes of ping 0 refined by the beam-aware filter (``beam_config``).

    Parameters
    ----------
    recording : Recording
        The (gated, averaged) record the matched filter ran on.
    matched : DetectionResult
        ``detect(recording, "matched")``.
    transducers : PistonTransducers
    sound_speed_m_s : float
    """
    from binsonar.localization.beam_refine import refine_echoes

    return refine_echoes(recording.waveforms[0], matched.first(0), sample_rate_hz=recording.sample_rate_hz,
                         t0_s=recording.t0_s, template=recording.template,
                         channel_positions_m=recording.channel_positions_m, sound_speed_m_s=sound_speed_m_s,
                         transducers=transducers, config=beam_config())


def noise_free_errors(recording: Any, clean: Any, detectors: tuple[str, ...], truth_tof_s: Any, truth: Any,
                      sound_speed_m_s: float, half_baseline_m: float, gate: tuple[float, float],
                      transducers: Any = None) -> dict[str, Any]:
    """Errors of each detector (except the threshold detector, whose threshold needs noise) on a noise-free record.

    ``BEAM_MATCHED`` refines the matched filter's echoes nearest the truth with ``transducers``
    (``recording_array``).

    Returns
    -------
    dict
        Per detector: ``tof_error_s`` (left, right; NaN when the edge's echo is not detected),
        ``range_error_m``, ``bearing_error_deg``.
    """
    from dataclasses import replace

    from binsonar.detection import detect

    record = gate_recording(replace(recording, waveforms=np.asarray(clean, dtype=float)[np.newaxis]), *gate)
    out: dict[str, Any] = {}
    for method in detectors:
        if method == "threshold":
            continue
        if method == BEAM_MATCHED:
            plain = nearest_echoes(detect(record, "matched"), truth_tof_s)
            echoes = plain
            if plain[0] is not None and plain[2] is not None:
                from binsonar.localization.beam_refine import refine_echoes

                echoes = refine_echoes(record.waveforms[0], plain, sample_rate_hz=record.sample_rate_hz,
                                       t0_s=record.t0_s, template=record.template,
                                       channel_positions_m=record.channel_positions_m,
                                       sound_speed_m_s=sound_speed_m_s, transducers=transducers,
                                       config=beam_config())
        else:
            echoes = nearest_echoes(detect(record, method), truth_tof_s)
        r, b = estimate_point(echoes, sound_speed_m_s, half_baseline_m)
        out[method] = {"tof_error_s": [float("nan") if e is None else e.tof_s - truth_tof_s[ch]
                                       for ch, e in ((0, echoes[0]), (2, echoes[2]))],
                       "range_error_m": r - truth.range_m, "bearing_error_deg": b - truth.bearing_deg}
    return out


def echo_tof_crlb_s(echo: Any, noise: Any, fs_hz: float, segment: int = 1024) -> tuple[Any, Any]:
    """Cramer-Rao bound on the TOF of a known echo shape with unknown carrier phase, in coloured Gaussian noise.

    Per channel, with X_k the echo's DFT over the record (n samples) and P(f) the noise's
    one-sided power spectral density (Welch, ``segment`` samples; integral of P = variance), the
    per-bin SNR weights are w_k = 4 |X_k|^2 / (n fs P(f_k)) (for white noise of variance s^2,
    sum w = sum x^2 / s^2 = 2E/N0, ``physics.md`` section 6); then
    sigma_tau = 1 / (2 pi beta sqrt(sum w)) with beta^2 the w-weighted variance of f about its
    w-weighted centroid (the unknown carrier phase removes the centroid: the envelope bound).
    For an echo that is the template in white noise this is ``binsonar.bounds.tof_crlb_s``; it
    also holds for the edge's actual echo (half-integrated, cut by the beam, low-passed off axis)
    and the receiver chain's coloured noise, which the template-based bound does not.

    Parameters
    ----------
    echo, noise : ndarray, shape (c, n)
        The noise-free echo alone and a noise record of the same length (V).
    fs_hz : float

    Returns
    -------
    tof_std_s, snr_db : ndarray, shape (c,)
    """
    from scipy.signal import welch

    x = np.asarray(echo, dtype=float)
    n = x.shape[-1]
    f_psd, psd = welch(np.asarray(noise, dtype=float), fs=fs_hz, nperseg=min(segment, n), axis=-1)
    f = np.fft.rfftfreq(n, 1.0 / fs_hz)
    power = np.abs(np.fft.rfft(x, axis=-1)) ** 2
    density = np.stack([np.interp(f, f_psd, row) for row in np.atleast_2d(psd)])
    w = 4.0 * power / (n * fs_hz * np.maximum(density, 1e-300))
    w[:, 0] = 0.0  # DC carries no timing information (and the record's offset sits there)
    total = w.sum(axis=-1)
    centroid = (w * f).sum(axis=-1) / total
    beta = np.sqrt((w * (f - centroid[:, np.newaxis]) ** 2).sum(axis=-1) / total)
    return 1.0 / (2.0 * np.pi * beta * np.sqrt(total)), 10.0 * np.log10(total)


def analytic_correlation(rows: Any, template: Any) -> Any:
    """z, shape (c, n - m + 1): each row (c, n) correlated with the analytic template (m,), full-overlap lags only.

    The matched filter's complex output (``binsonar.detection.matched``): |z| is its envelope.
    """
    from scipy.signal import fftconvolve, hilbert

    kernel = np.conj(hilbert(np.asarray(template, dtype=float)))[np.newaxis, ::-1]
    return fftconvolve(np.asarray(rows, dtype=float), kernel, mode="valid", axes=1)


def matched_snr(echo: Any, noise: Any, template: Any) -> Any:
    """2E/N0 (linear) at the matched filter's output: 2 max|z_s|^2 / mean|z_n|^2 per channel.

    z is the correlation with the analytic template (the matched filter's own SNR definition, see
    ``binsonar.detection.matched``), z_s of the echo alone and z_n of the noise alone.

    Parameters
    ----------
    echo, noise : ndarray, shape (c, n)
    template : ndarray, shape (m,)
    """
    z_s = analytic_correlation(echo, template)
    z_n = analytic_correlation(noise, template)
    return 2.0 * np.max(np.abs(z_s) ** 2, axis=1) / np.mean(np.abs(z_n) ** 2, axis=1)


def noise_bound(echo: Any, noise: Any, template: Any, fs_hz: float, range_m: float, bearing_deg: float,
                sound_speed_m_s: float, half_baseline_m: float) -> dict[str, Any]:
    """CRLB-derived std of range (m) and bearing (deg) of the averaged ping, from its true echo and noise.

    The simulation knows the averaged ping's noise exactly (the record minus the noise-free
    record) and the edge's echo alone. Two bounds, each on the left and right channels and
    propagated by ``seed_point_covariance``:

    - ``range_m``/``bearing_deg``: the CRLB at the measured SNR, sigma_tau =
      1 / (2 pi beta sqrt(2E/N0)) with beta the template's RMS bandwidth and 2E/N0 the matched
      filter's output SNR of the echo in this noise (``matched_snr``): the bound the detector
      itself reports (``Echo.tof_std_s``), but with the noise alone in its floor (the detector's
      median over the gate also counts the frozen reverberation).
    - ``optimal_range_m``/``optimal_bearing_deg``: ``echo_tof_crlb_s``, the bound of the echo's
      own shape in the noise's own spectrum (a whitened filter matched to the received echo
      would reach it; the transmitted-pulse template and the coloured noise keep the matched
      filter above it off axis).

    Parameters
    ----------
    echo, noise : ndarray, shape (3, n)
        The edge's noise-free echo and the averaged noise over the same gate (V).
    template : ndarray, shape (m,)
        The matched filter's template (the transmitted pulse).

    Returns
    -------
    dict
        ``range_m``, ``bearing_deg``, ``snr_db`` (3), ``optimal_range_m``, ``optimal_bearing_deg``,
        ``optimal_snr_db`` (3).
    """
    from binsonar.bounds import rms_bandwidth_hz, tof_crlb_s
    from binsonar.localization.point import seed_point_covariance

    snr = matched_snr(echo, noise, template)
    measured = tof_crlb_s(snr, rms_bandwidth_hz(np.asarray(template, dtype=float), fs_hz))
    optimal, optimal_snr_db = echo_tof_crlb_s(echo, noise, fs_hz)
    out: dict[str, Any] = {"snr_db": [float(v) for v in 10.0 * np.log10(snr)],
                           "optimal_snr_db": [float(v) for v in optimal_snr_db]}
    for prefix, std_s in (("", measured), ("optimal_", optimal)):
        cov = seed_point_covariance(range_m, math.radians(bearing_deg), half_baseline_m,
                                    sound_speed_m_s * std_s[0], sound_speed_m_s * std_s[2])
        out[f"{prefix}range_m"] = float(math.sqrt(cov[0, 0]))
        out[f"{prefix}bearing_deg"] = float(math.degrees(math.sqrt(cov[1, 1])))
    return out


def reverb_bound(echo: Any, noise: Any, reverbs: Any, template: Any, fs_hz: float, range_m: float,
                 bearing_deg: float, sound_speed_m_s: float, half_baseline_m: float) -> dict[str, float]:
    """The bound of ``noise_bound`` with the diffuse reverberation counted as Gaussian interference.

    The reverberation is a sum of many independent scatterers (Gaussian by the central limit
    theorem) whose power changes along the record, so it enters at its level at the echo's delay,
    as the sonar equation's reverberation level does: the mean of |z_r|^2 (z_r the correlation of
    the reverberation alone with the analytic template, as in ``matched_snr``) over one template
    length centred on the peak of the edge's own correlation, averaged over the realisations
    given. 2E/N0 = 2 max|z_s|^2 / (mean|z_n|^2 over the gate + that level), then the CRLB and the
    localiser's covariance as in ``noise_bound``.

    Parameters
    ----------
    echo, noise : ndarray, shape (3, n)
        The edge's noise-free echo and the averaged noise over the gate (V).
    reverbs : sequence of ndarray, shape (3, n)
        Realisations of the diffuse reverberation alone over the same gate (V).
    template : ndarray, shape (m,)

    Returns
    -------
    dict
        ``range_m``, ``bearing_deg``, ``snr_db`` (3), ``reverb_to_noise_db`` (3): the local
        reverberation level over the noise's, at the matched filter's output.
    """
    from binsonar.bounds import rms_bandwidth_hz, tof_crlb_s
    from binsonar.localization.point import seed_point_covariance

    def correlate(x: Any) -> Any:
        return analytic_correlation(x, template)

    z_s = correlate(echo)
    peak = np.argmax(np.abs(z_s), axis=1)
    half = len(template) // 2
    n_out = z_s.shape[1]
    window = np.stack([(np.arange(n_out) >= k - half) & (np.arange(n_out) <= k + half) for k in peak])
    levels = [np.sum(np.abs(correlate(r)) ** 2 * window, axis=1) / np.sum(window, axis=1) for r in reverbs]
    reverb_level = np.mean(levels, axis=0)
    noise_level = np.mean(np.abs(correlate(noise)) ** 2, axis=1)
    snr = 2.0 * np.max(np.abs(z_s) ** 2, axis=1) / (noise_level + reverb_level)
    std_s = tof_crlb_s(snr, rms_bandwidth_hz(np.asarray(template, dtype=float), fs_hz))
    cov = seed_point_covariance(range_m, math.radians(bearing_deg), half_baseline_m,
                                sound_speed_m_s * std_s[0], sound_speed_m_s * std_s[2])
    return {"range_m": float(math.sqrt(cov[0, 0])), "bearing_deg": float(math.degrees(math.sqrt(cov[1, 1]))),
            "snr_db": [float(v) for v in 10.0 * np.log10(snr)],
            "reverb_to_noise_db": [float(v) for v in 10.0 * np.log10(np.maximum(reverb_level, 1e-300) / noise_level)]}


TEMPLATE_S = 20e-6
"""The record runs this long (a template length) past the gate, so the last echo is whole (s)."""
THRESHOLD_LEVEL_SIGMA = 6.0
"""The seed's preset threshold, set once per sweep: this many noise standard deviations of the
averaged ping at the calibration position (a per-sample false-alarm probability of 2e-9)."""


def position_setup(range_m: float, bearing_deg: float) -> tuple[Any, Any, Any, list[float], tuple[float, float]]:
    """The scene, the posed sonar, the edge's truth, its true TOFs and the gate of a position.

    Returns
    -------
    scene : Scene
        ``edge_tank_scene()`` (machined-steel prism): for propagation and for ``simulate``.
    sonar : SonarHead
        Placed with the edge at ``range_m`` and ``bearing_deg``, seen along the prism's bisector.
    truth : ObjectTruth
    truth_tof_s : list of 3 float
        Least-time TOF (s) transmitter -> edge point at the head's height -> each receiver.
    gate : (start_s, stop_s)
        The kept part of the record (s after the trigger).
    """
    from dataclasses import replace

    scene = edge_tank_scene()
    c = float(scene.medium.sound_speed)
    start_s, stop_s = range_window_s(range_m, c, GATE_HALF_WIDTH_M)
    sonar = pose_for_target(scene.sonar, (*EDGE_M, scene.sonar.position_m[2]), range_m, bearing_deg,
                            yaw_deg=bearing_deg)
    sonar = replace(sonar, record_length_s=stop_s + TEMPLATE_S)
    truth = object_truth(scene, sonar, scene.objects[0])
    tx, rx = sonar.transmitter_position, sonar.receiver_positions
    truth_tof = [(float(np.linalg.norm(truth.position_tank_m - tx)) + float(np.linalg.norm(truth.position_tank_m - r)))
                 / c for r in rx]
    return scene, sonar, truth, truth_tof, (start_s, stop_s + TEMPLATE_S)


def calibrate_threshold(range_m: float, bearing_deg: float, n_pings: int, seed: int,
                        reverberation: bool = True) -> dict[str, float]:
    """The seed's threshold detector: a preset level and a TOF offset calibrated at one position.

    The seed (section 4.1.1) compares the echo with a pre-set level (0.04 V in its figure 4-1)
    and notes that the crossing comes after the echo's start by a rise time that depends on the
    echo's amplitude, so a constant calibration is right at one amplitude only. Here the level is
    ``THRESHOLD_LEVEL_SIGMA`` times the averaged ping's noise (left/right mean) at the
    calibration position, and the offset is the template's crossing delay at the edge's echo
    amplitude there (``binsonar`` threshold option ``calibrate_amplitude_v``); both then stay
    fixed for the whole sweep, so weaker echoes (longer range, larger angle) cross later.

    Returns
    -------
    dict
        ``level_v``, ``amplitude_v`` (peak of the edge's noise-free echo, left/right mean),
        ``range_m``, ``bearing_deg``.
    """
    from acoustisim.propagation import solve
    from acoustisim.propagation.paths import Paths
    from acoustisim.simulation import simulate
    from acoustisim.synthesis.pings import PingSynthesiser

    scene, sonar, _, _, gate = position_setup(range_m, bearing_deg)
    paths = solve(scene, sonar, solver_config({"reverberation": reverberation}))
    synthesiser = PingSynthesiser.create(sonar, scene.medium)
    edge = Paths(paths.rows[path_subsets(paths)["edge"]], paths.surface_names, paths.centre_frequency_hz,
                 paths.sound_speed_m_s)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # arrivals past the short record are left out on purpose
        sim = simulate(scene, sonar, paths=paths, seed=seed, n_pings=n_pings, average=n_pings > 1,
                       synthesiser=synthesiser)
        edge_clean = simulate(scene, sonar, paths=edge, n_pings=1, synthesiser=synthesiser).clean
    fs = sim.recording.sample_rate_hz
    t0 = sim.recording.t0_s
    span = slice(int(math.floor((gate[0] - t0) * fs)), int(math.ceil((gate[1] - t0) * fs)))
    noise = sim.recording.waveforms[0, :, span] - np.asarray(sim.clean)[:, span]
    sigma = float(np.mean(np.std(noise[[0, 2]], axis=1)))
    amplitude = float(np.mean(np.max(np.abs(np.asarray(edge_clean)[[0, 2], span]), axis=1)))
    return {"level_v": THRESHOLD_LEVEL_SIGMA * sigma, "amplitude_v": amplitude, "range_m": range_m,
            "bearing_deg": bearing_deg}


def measure_position(trial: Trial) -> dict[str, Any]:
    """Simulate and measure one position, ``repeats`` times (a module-level function for the runner).

    Trial parameters: ``range_m``, ``bearing_deg``, ``n_pings``, ``repeats``; optional
    ``detectors`` (tuple of method names), ``max_order`` and ``reverberation`` (propagation, see
    ``solver_config``) and ``fresh_reverberation``: False (default) keeps one realisation of the
    diffuse reverberation for every repeat, as one tank does (diffuse seed 0); True draws a new
    one per repeat (diffuse seeds from ``trial.seed``), the ensemble over rough surfaces that a
    bound counting the reverberation as Gaussian interference is an expectation over.

    Returns
    -------
    dict
        ``range_m``, ``bearing_deg``, truth, ``solve_s``, ``simulate_s_per_ping``, per detector
        lists over the repeats of ``range_est_m``, ``bearing_est_deg``, ``range_error_m``,
        ``bearing_error_deg``, ``detected``, ``elapsed_s``, ``snr_db`` (left/right mean),
        ``bound_range_m``, ``bound_bearing_deg``, and ``noise_free``: per part of
        ``NOISE_FREE_PARTS`` the ``noise_free_errors`` of the first repeat (the bias of every
        repeat when the reverberation is frozen); with fresh reverberation also
        ``noise_free_all_by_repeat``, the ``all`` part of every repeat.
    """
    from acoustisim.propagation import solve
    from acoustisim.propagation.paths import Paths
    from acoustisim.simulation import simulate
    from acoustisim.synthesis.pings import PingSynthesiser
    from binsonar.detection import detect

    p = dict(trial.params)
    range_m, bearing_deg = float(p["range_m"]), float(p["bearing_deg"])
    n_pings, repeats = int(p["n_pings"]), int(p["repeats"])
    detectors = tuple(p.get("detectors", DETECTORS))
    scene, sonar, truth, truth_tof, gate = position_setup(range_m, bearing_deg)
    c = float(scene.medium.sound_speed)
    start_s, stop_s = gate[0], gate[1] - TEMPLATE_S
    fresh = bool(p.get("fresh_reverberation", False)) and bool(p.get("reverberation", True))
    diffuse_seeds = ([int(v) for v in np.random.SeedSequence([trial.seed, 1]).generate_state(repeats, dtype=np.uint32)]
                     if fresh else [int(p.get("diffuse_seed", 0))])
    t, cpu = time.perf_counter(), time.process_time()
    paths = solve(scene, sonar, solver_config({**p, "diffuse_seed": diffuse_seeds[0]}))
    synthesiser = PingSynthesiser.create(sonar, scene.medium)
    solve_s, solve_cpu_s = time.perf_counter() - t, time.process_time() - cpu
    out: dict[str, Any] = {
        "range_m": range_m, "bearing_deg": bearing_deg,
        "truth_range_m": truth.range_m, "truth_bearing_deg": truth.bearing_deg, "truth_tof_s": truth_tof,
        "sonar_position_m": list(sonar.position_m), "sonar_yaw_deg": sonar.yaw_deg,
        "gate_s": [start_s, stop_s], "n_pings": n_pings, "fresh_reverberation": fresh,
        "diffuse_seeds": diffuse_seeds,
        "detectors": {m: {k: [] for k in ("range_est_m", "bearing_est_deg", "range_error_m", "bearing_error_deg",
                                          "detected", "elapsed_s", "cpu_s", "snr_db", "bound_range_m",
                                          "bound_bearing_deg")}
                      for m in detectors},
    }
    sim_s = sim_cpu_s = 0.0
    seeds = np.random.SeedSequence(trial.seed).generate_state(repeats, dtype=np.uint32)
    reverbs: list[Any] = []  # the diffuse reverberation alone over the gate, per realisation
    for k in range(repeats):
        if fresh and k > 0:
            t, cpu = time.perf_counter(), time.process_time()
            paths = solve(scene, sonar, solver_config({**p, "diffuse_seed": diffuse_seeds[k]}))
            solve_s += time.perf_counter() - t
            solve_cpu_s += time.process_time() - cpu
        t, cpu = time.perf_counter(), time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # arrivals past the short record are left out on purpose
            sim = simulate(scene, sonar, paths=paths, seed=int(seeds[k]), n_pings=n_pings, average=n_pings > 1,
                           synthesiser=synthesiser)
        sim_s += time.perf_counter() - t
        sim_cpu_s += time.process_time() - cpu
        recording = gate_recording(sim.recording, *gate)
        if k == 0:
            half_baseline, transducers = recording_array(sim.recording)
            noise_free: dict[str, Any] = {}
            masks = path_subsets(paths)
            for part in NOISE_FREE_PARTS:
                if part == "all":
                    clean = sim.clean
                else:
                    subset = Paths(paths.rows[masks[part]], paths.surface_names, paths.centre_frequency_hz,
                                   paths.sound_speed_m_s)
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        clean = simulate(scene, sonar, paths=subset, seed=0, n_pings=1,
                                         synthesiser=synthesiser).clean
                noise_free[part] = noise_free_errors(sim.recording, clean, detectors, truth_tof, truth, c,
                                                     half_baseline, gate, transducers)
                if part == "edge":
                    edge_clean = clean
                elif part == "specular":
                    specular_clean = clean
            out["noise_free"] = noise_free
            fs = sim.recording.sample_rate_hz
            i0 = int(round((recording.t0_s - sim.recording.t0_s) * fs))
            span = slice(i0, i0 + recording.waveforms.shape[-1])
            noise = sim.recording.waveforms[0, :, span] - np.asarray(sim.clean)[:, span]
            template = sim.recording.template.samples
            bounds = noise_bound(np.asarray(edge_clean)[:, span], noise, template, fs, truth.range_m,
                                 truth.bearing_deg, c, half_baseline)
            out["noise_bound_range_m"], out["noise_bound_bearing_deg"] = bounds["range_m"], bounds["bearing_deg"]
            out["noise_snr_db"] = bounds["snr_db"]
            out["optimal_bound_range_m"] = bounds["optimal_range_m"]
            out["optimal_bound_bearing_deg"] = bounds["optimal_bearing_deg"]
        elif fresh:
            out.setdefault("noise_free_all_by_repeat", [out["noise_free"]["all"]]).append(
                noise_free_errors(sim.recording, sim.clean, detectors, truth_tof, truth, c, half_baseline, gate,
                                  transducers))
        if k == 0 or fresh:
            reverbs.append(np.asarray(sim.clean)[:, span] - np.asarray(specular_clean)[:, span])
        matched_run: tuple[Any, float] | None = None  # the matched filter's result and CPU time (s), shared
        for method in detectors:
            options = {}
            if method == "threshold" and "threshold_level_v" in p:
                options = {"level_v": float(p["threshold_level_v"]),
                           "calibrate_amplitude_v": float(p["threshold_amplitude_v"])}
            cpu = time.process_time()
            if method == BEAM_MATCHED:  # the matched filter (run once for both rows), then the refinement
                if matched_run is None:
                    matched_run = (detect(recording, "matched"), time.process_time() - cpu)
                    cpu = time.process_time()
                result = matched_run[0]
                wall = time.perf_counter()
                echoes = beam_matched_echoes(recording, result, transducers, c)
                elapsed = result.elapsed_s + time.perf_counter() - wall
                cpu = time.process_time() - cpu + matched_run[1]
            else:
                result = detect(recording, method, **options)
                cpu = time.process_time() - cpu
                elapsed = result.elapsed_s
                if method == "matched":
                    matched_run = (result, cpu)
                echoes = result.first(0)
            r_est, b_est = estimate_point(echoes, c, half_baseline)
            r_sd, b_sd = bound_of(echoes, r_est, b_est, c, half_baseline) if method != "threshold" else (np.nan, np.nan)
            snrs = [e.snr_db for e in (echoes[0], echoes[2]) if e is not None]
            rec = out["detectors"][method]
            rec["range_est_m"].append(r_est)
            rec["bearing_est_deg"].append(b_est)
            rec["range_error_m"].append(r_est - truth.range_m)
            rec["bearing_error_deg"].append(b_est - truth.bearing_deg)
            rec["detected"].append(bool(math.isfinite(r_est)))
            rec["elapsed_s"].append(elapsed)
            rec["cpu_s"].append(cpu)
            rec["snr_db"].append(float(np.mean(snrs)) if snrs else float("nan"))
            rec["bound_range_m"].append(r_sd)
            rec["bound_bearing_deg"].append(b_sd)
    # The bound with the diffuse reverberation counted as Gaussian interference at its level at the
    # echo's delay (``reverb_bound``), averaged over the realisations measured (one when frozen).
    with_reverb = reverb_bound(np.asarray(edge_clean)[:, span], noise, reverbs, template, fs, truth.range_m,
                               truth.bearing_deg, c, half_baseline)
    out["reverb_bound_range_m"], out["reverb_bound_bearing_deg"] = with_reverb["range_m"], with_reverb["bearing_deg"]
    out["reverb_to_noise_db"] = with_reverb["reverb_to_noise_db"]
    out["reverb_realisations"] = len(reverbs)
    out["solve_s"], out["solve_cpu_s"] = solve_s, solve_cpu_s
    out["simulate_s_per_ping"] = sim_s / (repeats * n_pings)
    out["simulate_cpu_s_per_ping"] = sim_cpu_s / (repeats * n_pings)
    return out


def finite_mean(values: Any) -> float:
    """Mean of the finite values (NaN, without a warning, when none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else float("nan")


def finite_max(values: Any) -> float:
    """Largest finite value (NaN, without a warning, when none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.max()) if v.size else float("nan")


def rms(values: list[float]) -> float:
    """RMS of the finite values (NaN when none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(v * v))) if v.size else float("nan")


def summarise(positions: list[dict[str, Any]], detectors: tuple[str, ...]) -> dict[str, Any]:
    """Per-position RMS errors, bounds and times, and the overall summary of a sweep."""
    rows = []
    for pos in positions:
        row: dict[str, Any] = {"range_m": pos["range_m"], "bearing_deg": pos["bearing_deg"],
                               "simulate_s_per_ping": pos["simulate_s_per_ping"],
                               "simulate_cpu_s_per_ping": pos.get("simulate_cpu_s_per_ping", float("nan")),
                               "solve_s": pos["solve_s"], "solve_cpu_s": pos.get("solve_cpu_s", float("nan"))}
        bound = pos["detectors"].get("matched", {})
        b_r = finite_mean(bound.get("bound_range_m", [])) if bound else float("nan")
        b_b = finite_mean(bound.get("bound_bearing_deg", [])) if bound else float("nan")
        # The bound: the CRLB at the averaged ping's true SNR (``noise_bound``); the detector's
        # own estimate (noise floor including the frozen reverberation) is kept for comparison.
        row["detector_bound_range_m"], row["detector_bound_bearing_deg"] = b_r, b_b
        b_r = float(pos.get("noise_bound_range_m", b_r))
        b_b = float(pos.get("noise_bound_bearing_deg", b_b))
        row["bound_range_m"], row["bound_bearing_deg"] = b_r, b_b
        row["optimal_bound_range_m"] = float(pos.get("optimal_bound_range_m", float("nan")))
        row["optimal_bound_bearing_deg"] = float(pos.get("optimal_bound_bearing_deg", float("nan")))
        row["reverb_bound_range_m"] = float(pos.get("reverb_bound_range_m", float("nan")))
        row["reverb_bound_bearing_deg"] = float(pos.get("reverb_bound_bearing_deg", float("nan")))
        row["reverb_to_noise_db"] = pos.get("reverb_to_noise_db")
        row["fresh_reverberation"] = bool(pos.get("fresh_reverberation", False))
        for m in detectors:
            d = pos["detectors"][m]
            row[m] = {
                "range_rms_m": rms(d["range_error_m"]),
                "bearing_rms_deg": rms(d["bearing_error_deg"]),
                "range_mean_error_m": finite_mean(d["range_error_m"]),
                "bearing_mean_error_deg": finite_mean(d["bearing_error_deg"]),
                "detection_rate": float(np.mean(d["detected"])),
                "elapsed_s": float(np.mean(d["elapsed_s"])),
                "cpu_s": float(np.mean(d["cpu_s"])) if d.get("cpu_s") else float("nan"),
                "snr_db": finite_mean(d["snr_db"]),
            }
        for m in detectors:
            parts = {part: pos.get("noise_free", {}).get(part, {}).get(m) for part in NOISE_FREE_PARTS}
            if parts["all"] is None:
                continue
            d = pos["detectors"][m]
            row[m]["bias_range_parts_m"] = {part: v["range_error_m"] for part, v in parts.items() if v is not None}
            row[m]["bias_tof_parts_s"] = {part: v["tof_error_s"] for part, v in parts.items() if v is not None}
            by_repeat = pos.get("noise_free_all_by_repeat")
            if by_repeat:
                # Fresh reverberation: every repeat has its own bias; the scatter is about each
                # repeat's own, and the bias shown (and its ``all`` part) is their RMS.
                bias_r = np.array([b[m]["range_error_m"] for b in by_repeat], dtype=float)
                bias_b = np.array([b[m]["bearing_error_deg"] for b in by_repeat], dtype=float)
                row[m]["bias_range_m"], row[m]["bias_bearing_deg"] = rms(bias_r), rms(bias_b)
                row[m]["bias_range_parts_m"]["all"] = rms(bias_r)
                row[m]["bias_range_per_repeat_m"] = [float(v) for v in bias_r]
            else:
                bias_r, bias_b = parts["all"]["range_error_m"], parts["all"]["bearing_error_deg"]
                row[m]["bias_range_m"], row[m]["bias_bearing_deg"] = bias_r, bias_b
            row[m]["scatter_range_rms_m"] = rms(np.asarray(d["range_error_m"], dtype=float) - bias_r)
            row[m]["scatter_bearing_rms_deg"] = rms(np.asarray(d["bearing_error_deg"], dtype=float) - bias_b)
        for m in BOUNDED_DETECTORS:
            if m not in detectors:
                continue
            mf = row[m]
            mf["range_rms_over_bound"] = mf["range_rms_m"] / b_r if b_r > 0 else float("nan")
            mf["bearing_rms_over_bound"] = mf["bearing_rms_deg"] / b_b if b_b > 0 else float("nan")
            rb = row["reverb_bound_range_m"]
            mf["range_rms_over_reverb_bound"] = mf["range_rms_m"] / rb if rb > 0 else float("nan")
            mf["scatter_range_rms_over_bound"] = (mf.get("scatter_range_rms_m", float("nan")) / b_r
                                                  if b_r > 0 else float("nan"))
            mf["scatter_bearing_rms_over_bound"] = (mf.get("scatter_bearing_rms_deg", float("nan")) / b_b
                                                    if b_b > 0 else float("nan"))
        rows.append(row)
    summary: dict[str, Any] = {
        "simulate_s_per_ping": float(np.mean([r["simulate_s_per_ping"] for r in rows])),
        "simulate_cpu_s_per_ping": float(np.mean([r["simulate_cpu_s_per_ping"] for r in rows])),
        "solve_s_per_position": float(np.mean([r["solve_s"] for r in rows])),
        "solve_cpu_s_per_position": float(np.mean([r["solve_cpu_s"] for r in rows])),
    }
    for m in detectors:
        summary[m] = {
            "elapsed_s_per_position": float(np.mean([r[m]["elapsed_s"] for r in rows])),
            "cpu_s_per_position": float(np.mean([r[m]["cpu_s"] for r in rows])),
            "max_range_rms_m": finite_max([r[m]["range_rms_m"] for r in rows]),
            "max_bearing_rms_deg": finite_max([r[m]["bearing_rms_deg"] for r in rows]),
            "detection_rate": float(np.mean([r[m]["detection_rate"] for r in rows])),
        }
    for m in BOUNDED_DETECTORS:
        if m not in detectors:
            continue
        ratios = np.array([r[m]["range_rms_over_bound"] for r in rows], dtype=float)
        summary[m]["max_range_rms_over_bound"] = finite_max(ratios)
        summary[m]["positions_within_1_5_bound"] = int(np.sum(ratios <= 1.5))
        bearing = np.array([r[m]["bearing_rms_over_bound"] for r in rows], dtype=float)
        summary[m]["positions_bearing_within_1_5_bound"] = int(np.sum(bearing <= 1.5))
        scatter = np.array([r[m]["scatter_range_rms_over_bound"] for r in rows], dtype=float)
        summary[m]["max_scatter_range_rms_over_bound"] = finite_max(scatter)
        summary[m]["positions_scatter_within_1_5_bound"] = int(np.sum(scatter <= 1.5))
        reverb = np.array([r[m]["range_rms_over_reverb_bound"] for r in rows], dtype=float)
        summary[m]["positions_within_1_5_reverb_bound"] = int(np.sum(reverb <= 1.5))
        summary[m]["max_range_rms_over_reverb_bound"] = finite_max(reverb)
        summary[m]["pooled_range_rms_over_reverb_bound"] = rms(reverb)
        # Pooled over positions: sqrt(mean((scatter / bound)^2)) is 1 for an efficient estimator.
        summary[m]["pooled_scatter_range_rms_over_bound"] = rms(scatter)
    return {"positions": rows, "summary": summary}
