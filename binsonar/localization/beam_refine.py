"""Beam-aware time-of-flight refinement: matched filtering with the echo the transducers actually receive.

The plain matched filter correlates each channel with the transmitted pulse. Off axis the
pistons filter the echo per frequency (``beam_model``), so the correlation's envelope peaks
away from the geometric time of flight: by microseconds on the side channels when the target is
near or past the first null (close range), by nanoseconds for an extended edge whose outer
Fresnel zone the beam trims. A real sonar has this distortion; its user knows the transducers'
aperture (``PistonTransducers``), so the refinement takes it as an explicit input:

1. Start from the plain matched filter's times of flight (one per channel).
2. Locate the target: the left and right path lengths give its head-frame position
   (``point.initial_point``: the seed geometry's exact solution at the receivers' height).
3. Per channel, the expected echo spectrum A_c(f) = T(f) H_c(f): the template's spectrum T (its
   phase referred to its reference instant) times ``beam_model.expected_response`` (referred to
   the channel's geometric time of flight).
4. Re-estimate each channel's TOF as the maximum over tau of |z_c(tau)|,
   z_c(tau) = sum_{f > 0} X(f) conj(A_c(f)) exp(j 2 pi f tau), X the record segment's spectrum
   with absolute-time phases. For a noise-free echo x = a_c(t - tau_0),
   z_c(tau) = sum |A_c|^2 exp(j 2 pi f (tau - tau_0)), whose modulus is largest at tau_0 exactly
   (triangle inequality): the reference delay is the geometric TOF by construction, with no
   offset to calibrate and no interpolation bias. The maximum is found on a grid of half a sample
   and polished by Newton's method on the band-limited |z|^2 (its derivatives are exact sums).
5. Repeat 2-4 (``iterations``) with the refined TOFs.

The correlation runs on a segment of the record that holds the whole expected echo for every
searched delay (template, beam spread, edge tail), so it equals the full correlation. This needs
an echo of finite extent: a template with a mean (no high-pass in it), phase-rotated as an
edge's echo is (-45 deg), has Hilbert tails ~1/t beyond any segment; the transmitted pulse
through the receiver's band-pass, as a recording stores it, has none.

With vanishing pistons (D = 1) and a point target, A_c = T and the result is the plain matched
filter's continuous envelope maximum (its log-parabolic vertex differs by well under a
nanosecond, tested). Costs: one FFT of a short segment per channel and iteration, and for an
edge a (3, points, bins) line-integral table (vectorised, no loop over samples, frequencies or
points).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.localization.beam_cue import cue_missing_echo
from binsonar.localization.beam_correlation import CorrelationGrid, correlation_maximum, segment_spectra
from binsonar.localization.beam_model import BeamModelConfig, PistonTransducers, expected_response
from binsonar.recording import RecordingError, Template


@dataclass(frozen=True)
class BeamRefinementConfig:
    """Settings of the beam-aware refinement.

    Attributes
    ----------
    model : BeamModelConfig
        Target class (point or vertical edge) and line-integral settings.
    iterations : int
        Locate-and-refine passes (2-3 converge: the beam factor depends on the angles only, which
        a first pass already gets to a fraction of a degree).
    search_half_width_s : float
        First pass: the maximum is searched within this of the plain matched filter's TOF (s);
        it covers the plain filter's bias at the closest ranges (about 4 us at 0.1 m).
    track_half_width_s : float
        Later passes: within this of the previous pass's TOF (s).
    cue_missing_channel : bool
        ``refine_echoes``: when one channel has no echo and the other two have, search it with
        the beam-aware filter around the time the other two predict (``beam_cue``) before
        refining. False: such a target is returned as it is.
    cue_pfa : float
        False-alarm probability of that search over its window.
    """

    model: BeamModelConfig = field(default_factory=BeamModelConfig)
    iterations: int = 3
    search_half_width_s: float = 6e-6
    track_half_width_s: float = 0.5e-6
    cue_missing_channel: bool = True
    cue_pfa: float = 1e-3

    def __post_init__(self) -> None:
        if not (isinstance(self.iterations, int) and 1 <= self.iterations <= 20):
            raise RecordingError(f"beam refinement: iterations must be an integer in [1, 20], got {self.iterations!r}")
        if not isinstance(self.cue_missing_channel, bool):
            raise RecordingError(f"beam refinement: cue_missing_channel must be True or False, got "
                                 f"{self.cue_missing_channel!r}")
        if not (isinstance(self.cue_pfa, float) and 0.0 < self.cue_pfa < 1.0):
            raise RecordingError(f"beam refinement: cue_pfa must be a float in (0, 1), got {self.cue_pfa!r}")
        for name in ("search_half_width_s", "track_half_width_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise RecordingError(f"beam refinement: {name} must be > 0 (s), got {value!r}")


@dataclass(frozen=True, eq=False)
class BeamRefinement:
    """Result of ``refine_tofs``.

    Attributes
    ----------
    tof_s : ndarray, shape (3,)
        Refined times of flight (s), left, centre, right (NaN where there was no start).
    initial_tof_s : ndarray, shape (3,)
        The plain times of flight it started from (s).
    position_m : ndarray, shape (3,)
        The target's head-frame position from the refined left and right TOFs (m).
    peak : ndarray, shape (3,)
        |z_c| at the refined TOFs (the adapted filter's peak, arbitrary unit).
    iterations : int
        Passes run.
    last_change_s : float
        Largest |TOF change| of the last pass (s): the iteration's convergence.
    """

    tof_s: NDArray[np.float64] = field(repr=False)
    initial_tof_s: NDArray[np.float64] = field(repr=False)
    position_m: NDArray[np.float64] = field(repr=False)
    peak: NDArray[np.float64] = field(repr=False)
    iterations: int
    last_change_s: float



def refine_tofs(rows: ArrayLike, tof_s: ArrayLike, *, sample_rate_hz: float, t0_s: float, template: Template,
                channel_positions_m: ArrayLike, sound_speed_m_s: float, transducers: PistonTransducers,
                config: BeamRefinementConfig = BeamRefinementConfig()) -> BeamRefinement:
    """Beam-aware TOFs of one target on the three channels of one ping (module docstring).

    Parameters
    ----------
    rows : array_like, shape (3, n)
        The ping's channels (V), left, centre, right; sample i at ``t0_s + i / sample_rate_hz``.
    tof_s : array_like, shape (3,)
        The plain matched filter's TOFs (s) of the target; NaN where a channel has none (it is
        not refined). Left and right are needed to locate the target.
    sample_rate_hz : float
    t0_s : float
        Time of sample 0 after the trigger (s).
    template : Template
        The matched filter's template at ``sample_rate_hz`` (the transmitted pulse through the
        receiver's chain).
    channel_positions_m : array_like, shape (3, 3)
        Channel positions in the head frame (m); the transmitter is
        ``transducers.transmitter_channel``.
    sound_speed_m_s : float
    transducers : PistonTransducers
    config : BeamRefinementConfig

    Returns
    -------
    BeamRefinement

    Raises
    ------
    RecordingError
        Bad shapes, a template at another sample rate, or no left or right TOF.
    """
    from binsonar.localization.array_geometry import ArrayGeometry
    from binsonar.localization.point import initial_point

    x = np.asarray(rows, dtype=float)
    tof0 = np.asarray(tof_s, dtype=float).ravel()
    fs = float(sample_rate_hz)
    if x.ndim != 2 or x.shape[0] != 3 or x.shape[1] < 2:
        raise RecordingError(f"beam refinement: rows must have shape (3, n), got {x.shape}")
    if tof0.shape != (3,):
        raise RecordingError(f"beam refinement: tof_s must hold 3 values (left, centre, right), got {tof0.shape}")
    if not math.isclose(template.sample_rate_hz, fs, rel_tol=1e-9):
        raise RecordingError(f"beam refinement: template at {template.sample_rate_hz:g} Hz, record at {fs:g} Hz")
    if not (np.isfinite(tof0[0]) and np.isfinite(tof0[2])):
        raise RecordingError(f"beam refinement: needs the left and right TOFs, got {tof0.tolist()}")
    c = float(sound_speed_m_s)
    if not (math.isfinite(c) and c > 0):
        raise RecordingError(f"beam refinement: sound_speed_m_s must be > 0, got {sound_speed_m_s!r}")
    positions = np.asarray(channel_positions_m, dtype=float)
    geometry = ArrayGeometry.from_channel_positions(positions, transducers.transmitter_channel)
    # Each channel's DC offset (its median, robust to the echoes) out: a segment's rectangular cut
    # of a constant would leak into the band's low bins.
    x = x - np.median(x, axis=1, keepdims=True)
    grid = CorrelationGrid.create(template, transducers, config.model, c, config.search_half_width_s)
    model, n_fft, frequency, bins, t_spec, lead_s = (grid.model, grid.n_fft, grid.frequency_hz, grid.bins,
                                                     grid.template_spectrum, grid.lead_s)
    active = np.isfinite(tof0)
    tof = tof0.copy()
    peak = np.full(3, np.nan)
    change = float("nan")
    done = 0
    for it in range(config.iterations):
        half = config.search_half_width_s if it == 0 else config.track_half_width_s
        lengths = c * tof
        position = initial_point(lengths, geometry)
        response, _ = expected_response(frequency, position, geometry.transmitter_m, geometry.receivers_m, transducers,
                                        c, model)
        centre = np.where(active, tof, 0.0)
        starts = centre - half - lead_s - 4.0 / fs
        spectrum, _ = segment_spectra(x, t0_s, fs, starts, n_fft, bins)
        refined, values = correlation_maximum(spectrum, t_spec * response, frequency, centre, half, fs)
        new = np.where(active, refined, np.nan)
        change = float(np.nanmax(np.abs(new - tof)))
        tof, peak = new, np.where(active, values, np.nan)
        done = it + 1
        if change < 1e-12:  # converged: 1 ps moves the hypothesised target by 1.5 nm
            break
    final = initial_point(c * tof, geometry)
    return BeamRefinement(tof, tof0, final, peak, done, change)


def refine_echoes(rows: ArrayLike, echoes: Sequence[Any], *, sample_rate_hz: float, t0_s: float,
                  template: Template, channel_positions_m: ArrayLike, sound_speed_m_s: float,
                  transducers: PistonTransducers | None,
                  config: BeamRefinementConfig = BeamRefinementConfig()) -> tuple[Any, Any, Any]:
    """The (left, centre, right) echoes of one target with beam-aware TOFs (``refine_tofs``).

    Parameters
    ----------
    rows : array_like, shape (3, n)
    echoes : sequence of 3 ``binsonar.detection.Echo`` or None
        The plain matched filter's echoes of the target on each channel.
    transducers : PistonTransducers or None
        None: no beam model, the echoes are returned as they are (the plain matched filter).
    sample_rate_hz, t0_s, template, channel_positions_m, sound_speed_m_s, config
        As ``refine_tofs``.

    Returns
    -------
    tuple of 3 Echo or None
        The same echoes with ``tof_s`` replaced. With ``config.cue_missing_channel``, a channel
        without an echo while the other two have one is first searched around the time they
        predict (``beam_cue.cue_missing_echo``); the echo found there, if any, is refined with the
        others. Unchanged when the left or right one is still missing (the target cannot be
        located).
    """
    triple = tuple(echoes)
    if len(triple) != 3:
        raise RecordingError(f"beam refinement: needs 3 echoes (left, centre, right), got {len(triple)}")
    if transducers is not None and config.cue_missing_channel and sum(e is None for e in triple) == 1:
        triple = cue_missing_echo(rows, triple, sample_rate_hz=sample_rate_hz, t0_s=t0_s, template=template,
                                  channel_positions_m=channel_positions_m, sound_speed_m_s=sound_speed_m_s,
                                  transducers=transducers, config=config)
    if transducers is None or triple[0] is None or triple[2] is None:
        return triple  # type: ignore[return-value]
    tof = [float("nan") if e is None else float(e.tof_s) for e in triple]
    result = refine_tofs(rows, tof, sample_rate_hz=sample_rate_hz, t0_s=t0_s, template=template,
                         channel_positions_m=channel_positions_m, sound_speed_m_s=sound_speed_m_s,
                         transducers=transducers, config=config)
    return tuple(None if e is None else replace(e, tof_s=float(result.tof_s[ch]))  # type: ignore[return-value]
                 for ch, e in enumerate(triple))


def refine_detection(result: Any, recording: Any, transducers: PistonTransducers | None,
                     config: BeamRefinementConfig = BeamRefinementConfig(), *,
                     sound_speed_m_s: float | None = None) -> Any:
    """A matched-filter ``DetectionResult`` whose first echo per channel and ping has beam-aware TOFs.

    For ``binsonar detect`` / scripts: each ping's earliest echoes (``result.first(ping)``) are
    taken as one target's (the plain matched filter reports one echo per channel) and refined
    with ``refine_echoes``; other echoes, and pings without a left or right echo, are kept as
    they are. The result's ``method`` gains the suffix "+beam".

    Parameters
    ----------
    result : DetectionResult
        From ``binsonar.detection.detect(recording, "matched", ...)`` (or another method that
        times an echo by the template's envelope peak).
    recording : Recording
        The recording it ran on; with ``result.n_pings == 1`` and several pings in the recording,
        the pings' mean (the averaged detection).
    transducers : PistonTransducers or None
        None returns ``result`` unchanged.
    config : BeamRefinementConfig
    sound_speed_m_s : float, optional
        Default: the recording's.

    Raises
    ------
    RecordingError
        No template or no sound speed in the recording.
    """
    if transducers is None:
        return result
    where = getattr(recording, "source", "") or "recording"
    if recording.template is None:
        raise RecordingError(f"{where}: beam refinement needs the recording's template")
    c = sound_speed_m_s if sound_speed_m_s is not None else recording.sound_speed_m_s
    if c is None:
        raise RecordingError(f"{where}: beam refinement needs a sound speed (the recording has none)")
    waveforms = np.asarray(recording.waveforms, dtype=float)
    if result.n_pings == 1 and waveforms.shape[0] > 1:
        waveforms = waveforms.mean(axis=0, keepdims=True)
    if result.n_pings != waveforms.shape[0]:
        raise RecordingError(f"{where}: the detection has {result.n_pings} ping(s), the recording {waveforms.shape[0]}")
    template = recording.template
    if not math.isclose(template.sample_rate_hz, recording.sample_rate_hz, rel_tol=1e-9):
        from binsonar.detection.inputs import as_signals, resolve_template

        template = resolve_template(template, as_signals(recording), "matched")
    pings = []
    for ping, channels in enumerate(result.echoes):  # pings, not samples: one refinement each
        refined = refine_echoes(waveforms[ping], result.first(ping), sample_rate_hz=recording.sample_rate_hz,
                                t0_s=recording.t0_s, template=template,
                                channel_positions_m=recording.channel_positions_m, sound_speed_m_s=float(c),
                                transducers=transducers, config=config)
        pings.append(tuple((new,) + tuple(echoes[1:]) if echoes else echoes
                           for new, echoes in zip(refined, channels)))
    return replace(result, echoes=tuple(pings), method=f"{result.method}+beam")


__all__ = ("BeamRefinement", "BeamRefinementConfig", "refine_detection", "refine_echoes", "refine_tofs")
