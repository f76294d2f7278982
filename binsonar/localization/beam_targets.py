"""Beam-aware times of flight of the pipeline's targets, with the standard deviations their echoes support.

Physics
-------
Off axis, the transducers filter each echo per frequency (``beam_model``): the echo of channel c
is the template T(f) times H_c(f) (the pistons' directivities at the target's angles; for a
vertical edge, the beam-weighted line integral along it). ``beam_refine.refine_tofs`` times
each channel by the maximum of |z_c(tau)|, z_c(tau) = sum_k X_k conj(A_k) exp(j w_k tau) with
A = T H_c, which is unbiased for the modelled echo. Its error at high SNR follows from
linearising d|z|^2/dtau = 0 about the true delay (X = a A exp(-j w tau0) + N, N the noise's
bins, E|N_k|^2 = P_k, W_k = |A_k|^2):

    delta = -Im(sum_k (w_k - w_bar) N_k conj(A_k)) / (a S0 beta_w^2),
    var(delta) = sum_k (w_k - w_bar)^2 W_k P_k / (2 |z_s|^2 beta_w^4),

S0 = sum W_k, w_bar = sum w_k W_k / S0, beta_w^2 = sum (w_k - w_bar)^2 W_k / S0 and
|z_s| = a S0 the noise-free peak. In white noise (P_k = P) this is the Cramer-Rao bound
1 / (2 pi beta sqrt(2E/N0)) of the beam-filtered echo (``physics.md`` section 6), with
2E/N0 = 2 |z_s|^2 / (P S0) and beta its envelope RMS bandwidth: near a side receiver's first
null the echo is weaker and narrower in band than the on-axis template, and its TOF std grows
accordingly. The general form also holds in coloured noise, for the unwhitened filter used.

Which expected echo: a post, a cylinder or a wall reflects specularly, its echo is the point
model's, the directivities at the specular point's angles. On a cylinder of radius a at range
r the three channels' specular points lie within a d / (2 r) of each other, so their angles
differ from the hypothesised point's by about a d / (2 r^2) (0.05 deg for a 25 mm post at 1 m);
the echo and A then differ by a real, positive factor except in the thin band of frequencies
between the two angles' nulls, which leaves the envelope peak in place (noise-free, on the
simulator's 5 mm post at 0.3 m and 10 deg, the refined TOFs are within 0.03 ns of the specular
arrivals). A sharp vertical edge diffracts: its echo is the line integral's
(``BeamModelConfig(target="vertical-edge")``). The two differ by a spectral tilt
(f^-1/2) and the beam's weighting along the edge; timing an edge with the point model is
biased by up to 40 ns on a channel at 0.3 m (measured on the simulator's noise-free edge),
timing a post with the edge model likewise. ``refine_target`` refines with one model; the
pipeline compares the models' fits where the geometry cannot tell (``localize_ping``).

Comparing the models: each model m is fitted by its own delays and complex amplitudes (three
of each; the same degrees of freedom for both), and in noise of level P_c per bin the
generalised log-likelihood of m is, up to terms common to both,

    L_m = sum_c |z_mc|^2 / (P_c S0_mc),     S0_mc = sum_k |A_mck|^2,

the energy of the record the fitted echo explains (least squares). ``model_fit_snr`` is L_m less
the noise's share (1 per channel). The noise level P_c is one number per channel, common to
both models: the per-bin estimate averaged over the band with the template's weights |T_k|^2.
Weighting each model by the per-bin estimate instead (sum_k W_mk P_ck) gives each model its own
random normalisation: a relative error e in it moves L_m by e L_m, and with L ~ 1,500 at
2E/N0 = 30 dB on three channels, the two models' normalisations differing by 2 % swamp their
difference (tens). Under the point model, L_edge - L_point has the mean -mu (the part of the
echo the edge model cannot explain, in noise units) and, at high SNR, the sd sqrt(2 mu).

Method
------
1. A channel without an echo is searched where the other two predict it (``beam_cue``).
2. ``refine_tofs`` (locate, model, correlate, iterate) with the model's ``BeamModelConfig``, its
   first search narrowed so that it cannot reach another detected echo (``search_half_width_s``).
3. At the refined TOFs, the expected echo A of the final position and each channel's segment
   spectrum X give |z| (one short FFT per channel), and ``NoiseSpectrum`` the P_k of the
   channel: the median-averaged periodogram of the record within ``NOISE_HALF_WINDOW_S`` of the
   echo, away from the detected echoes (``PingNoise``), interpolated onto the correlation's
   frequencies. Near the echo, the diffuse reverberation counts as noise (Gaussian interference
   at its level there); a coherent echo that overlaps the target's (a multipath arriving
   within the pulse) does not, and biases it.
4. The echo's ``tof_std_s`` from the variance above, its ``snr_db`` 10 log10(2 |z_s|^2 /
   sum W P), and the model's fit ``model_fit_snr`` (above).

Accuracy
--------
Noise-free, the refined TOFs of the simulator's free-field post (5 mm) and 60-degree edge are
within 1.5 ns of their geometric TOFs at 0.3, 1.0 and 2.5 m, 0 and 10 deg (the edge with a
constant wedge factor; ``beam_model`` gives the wedge-angle weighting for closer ranges). The
variance is the high-SNR limit, validated at 2E/N0 = 30 dB (the experiment
``localization-accuracy``); at low SNR the envelope maximum leaves it (the threshold effect).
The noise spectrum's resolution is the sample rate over its segment length (``NOISE_SEGMENT``
down to 64 samples, so that ``NOISE_SEGMENTS_MIN`` segments stay clear of the echoes): smooth
noise spectra only.

The model comparison (``model_fit_snr``), measured in the experiment ``localization-accuracy``
(500 pings per position at 2E/N0 = 30 dB, 0.3 m / 10 deg, 0.5 m / 0 deg, 0.8 m / 8 deg,
1.5 m / -6 deg, 2.5 m / -10 deg): the 5 mm post is timed with the point model in every ping
(2,500 of 2,500), the 60-degree edge with the edge model in 2,496 of 2,500. On the post at
0.3 m / 10 deg, the difference of the fits (edge - point) has mean -50 and sd 10 (the
likelihood ratio's sqrt(2 mu) = 10). Its scatter also holds the noise level's relative error
e_c per channel (about sum_c g_c e_c, g_c the channel's share of the difference): with the
record's noise estimate from a few short segments it grows (sd 24 against 11 on a synthetic
point echo whose noise is measured within 0.12 ms of it rather than 0.5 ms).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.localization.beam_model import PistonTransducers, expected_response
from binsonar.localization.beam_refine import BeamRefinementConfig, CorrelationGrid, refine_tofs
from binsonar.recording import RecordingError, Template

ECHO_MODELS: tuple[str, ...] = ("point", "vertical-edge")
"""The expected echoes the pipeline chooses from: a specular reflection (points, posts,
cylinders, walls) and a sharp vertical edge's diffraction."""
NOISE_SEGMENT = 1024
"""Longest segment (samples) of the noise spectrum's periodograms."""
NOISE_SEGMENTS_MIN = 31
"""Shorter segments (powers of two, down to 64 samples) are used when a record holds fewer
than this many half-overlapping ones: the median of 31 exponential variables is within
about 20 % of the spectrum per bin, and the variance sums over tens of bins."""
NOISE_HALF_WINDOW_S = 0.5e-3
"""The noise is measured within this of the target's echo (s, 0.37 m of range): what the
record holds there besides the echoes, the receiver's noise and the reverberation of that range
(which decays over milliseconds and which averaging pings does not reduce), is what the echo's
timing competes with."""


@dataclass(frozen=True, eq=False)
class BeamSetup:
    """What refining a recording's targets takes besides each ping's samples.

    Attributes
    ----------
    transducers : PistonTransducers
        The head's pistons (``ArrayDescription.transducers()``).
    template : Template
        The matched filter's template at the record's sample rate.
    sample_rate_hz : float
    t0_s : float
        Time of sample 0 after the trigger (s).
    channel_positions_m : ndarray, shape (3, 3)
        Head-frame positions (m), left, centre, right.
    sound_speed_m_s : float
    config : BeamRefinementConfig
        Iterations, search windows and the cued search; its ``model.target`` is set per model.
    """

    transducers: PistonTransducers
    template: Template
    sample_rate_hz: float
    t0_s: float
    channel_positions_m: NDArray[np.float64] = field(repr=False)
    sound_speed_m_s: float
    config: BeamRefinementConfig = field(default_factory=BeamRefinementConfig)

    @property
    def busy_half_width_s(self) -> float:
        """Half-width (s) of the stretch around a detected echo that the noise spectrum leaves
        out: the template's length and an edge's tail (``BeamModelConfig.edge_tail_s``)."""
        return self.template.samples.size / self.sample_rate_hz + self.config.model.edge_tail_s

    def model_config(self, model: str) -> BeamRefinementConfig:
        """The refinement's settings with the expected echo of ``model`` ("point" or "vertical-edge")."""
        if model not in ECHO_MODELS:
            raise RecordingError(f"beam refinement: model must be one of {', '.join(ECHO_MODELS)}, got {model!r}")
        return replace(self.config, model=replace(self.config.model, target=model))


@dataclass(frozen=True, eq=False)
class NoiseSpectrum:
    """The noise's power per rfft bin of a ping's channels: E|N_k|^2 of an n-sample segment is
    ``n * density(f_k) * fs / 2``.

    Attributes
    ----------
    frequency_hz : ndarray, shape (m,)
        Frequencies of ``density`` (Hz).
    density : ndarray, shape (3, m)
        One-sided power spectral density per channel (V^2/Hz).
    sample_rate_hz : float
    """

    frequency_hz: NDArray[np.float64] = field(repr=False)
    density: NDArray[np.float64] = field(repr=False)
    sample_rate_hz: float

    @classmethod
    def estimate(cls, rows: ArrayLike, sample_rate_hz: float, t0_s: float = 0.0,
                 busy_s: Sequence[ArrayLike] = ((), (), ()), busy_half_width_s: float = 0.0) -> "NoiseSpectrum":
        """Median-averaged periodogram (Welch: Hann, half overlap) of each channel (rows (3, n), V).

        Segments within ``busy_half_width_s`` of a time in ``busy_s[channel]`` (s after the
        trigger: the detected echoes) are left out; the segments are the longest power of two
        up to ``NOISE_SEGMENT`` (down to 64 samples) that leaves ``NOISE_SEGMENTS_MIN`` of them.
        The median is robust to what else the record holds (the main bang, echoes not
        detected) in fewer than half the segments. The median of n exponential
        variables is divided by its expectation over their mean, 1 - 1/2 + 1/3 - ... + 1/n for
        odd n, n - 1 terms for even n (as ``scipy.signal.welch``).
        """
        x = np.asarray(rows, dtype=float)
        fs = float(sample_rate_hz)
        n = x.shape[-1]
        busy = [np.asarray(busy_s[ch] if ch < len(busy_s) else (), dtype=float).ravel() for ch in range(x.shape[0])]
        segment = NOISE_SEGMENT
        while True:
            segment_now = max(8, min(segment, n - n % 2))
            keep = _quiet_segments(n, segment_now, fs, t0_s, busy, busy_half_width_s)
            if segment <= 64 or min(k.sum() for k in keep) >= NOISE_SEGMENTS_MIN:
                break
            segment //= 2
        segment = segment_now
        hop = segment // 2
        window = np.hanning(segment + 2)[1:-1]  # the symmetric Hann without its zero ends
        frames = np.lib.stride_tricks.sliding_window_view(x, segment, axis=-1)[:, ::hop, :]  # (3, m, segment)
        spectra = np.fft.rfft((frames - frames.mean(axis=-1, keepdims=True)) * window, axis=-1)
        periodograms = np.abs(spectra) ** 2 / (fs * float(np.sum(window ** 2)))
        periodograms[..., 1:(segment + 1) // 2] *= 2.0  # one-sided
        density = np.empty((x.shape[0], periodograms.shape[-1]))
        for ch in range(x.shape[0]):  # three channels, each with its own echoes
            chosen = periodograms[ch, keep[ch]] if keep[ch].sum() >= 3 else periodograms[ch]
            count = chosen.shape[0]
            terms = np.arange(1, count + 1 - (1 - count % 2))  # odd: count; even: count - 1 (as scipy)
            bias = float(np.sum((-1.0) ** (terms + 1) / terms))
            density[ch] = np.median(chosen, axis=0) / bias
        return cls(np.fft.rfftfreq(segment, 1.0 / fs), density, fs)

    def bin_power(self, frequency_hz: NDArray[np.float64], n_fft: int) -> NDArray[np.float64]:
        """E|N_k|^2 (3, k) at ``frequency_hz`` (k,) for rfft segments of ``n_fft`` samples."""
        density = np.stack([np.interp(frequency_hz, self.frequency_hz, row) for row in self.density])
        return 0.5 * n_fft * self.sample_rate_hz * density


def _quiet_segments(n: int, segment: int, fs: float, t0_s: float, busy: Sequence[NDArray[np.float64]],
                    half_width_s: float) -> list[NDArray[np.bool_]]:
    """Per channel, which half-overlapping ``segment``-sample segments of an n-sample record lie
    further than ``half_width_s`` from every time in ``busy[channel]`` (s)."""
    hop = segment // 2
    count = (n - segment) // hop + 1
    centres = t0_s + (np.arange(count) * hop + 0.5 * segment) / fs
    reach = half_width_s + 0.5 * segment / fs
    out = []
    for times in busy:
        if times.size:
            out.append(np.min(np.abs(centres[:, np.newaxis] - times[np.newaxis, :]), axis=1) > reach)
        else:
            out.append(np.ones(count, dtype=bool))
    return out


@dataclass(frozen=True, eq=False)
class PingNoise:
    """One ping's samples and detected echoes, from which the noise near any echo is measured.

    Attributes
    ----------
    rows : ndarray, shape (3, n)
        The ping's channels (V).
    sample_rate_hz : float
    t0_s : float
        Time of sample 0 after the trigger (s).
    busy_s : tuple of 3 ndarray
        The detected echoes' TOFs per channel (s).
    busy_half_width_s : float
        Stretch around each that the estimate leaves out (s; ``BeamSetup.busy_half_width_s``).
    half_window_s : float
        The estimate uses the record within this of the echo (s).
    """

    rows: NDArray[np.float64] = field(repr=False)
    sample_rate_hz: float
    t0_s: float
    busy_s: tuple[NDArray[np.float64], ...] = field(repr=False)
    busy_half_width_s: float
    half_window_s: float = NOISE_HALF_WINDOW_S

    def window(self, start_s: float, stop_s: float) -> tuple[NDArray[np.float64], float]:
        """The samples (3, m) between ``start_s`` and ``stop_s`` (s after the trigger, clipped to
        the record), DC offset (each row's median) removed, and the time of their first (s)."""
        fs = self.sample_rate_hz
        n = self.rows.shape[-1]
        first = int(np.clip(math.floor((start_s - self.t0_s) * fs), 0, max(n - 2, 0)))
        last = int(np.clip(math.ceil((stop_s - self.t0_s) * fs), first + 2, n))
        x = self.rows[:, first:last]
        return x - np.median(x, axis=1, keepdims=True), self.t0_s + first / fs

    def spectrum(self, rows: NDArray[np.float64], t0_s: float) -> NoiseSpectrum:
        """The noise spectrum of ``rows`` (a ``window``, first sample at ``t0_s``), away from the echoes."""
        return NoiseSpectrum.estimate(rows, self.sample_rate_hz, t0_s, self.busy_s, self.busy_half_width_s)


@dataclass(frozen=True, eq=False)
class RefinedTarget:
    """One target's echoes timed with an expected echo (``refine_target``).

    Attributes
    ----------
    echoes : tuple of 3 Echo
        Left, centre, right, with ``tof_s`` refined, ``tof_std_s`` the variance's square root
        (module docstring), ``snr_db`` the beam-filtered echo's 2E/N0.
    model : str
        "point" or "vertical-edge".
    position_m : ndarray, shape (3,)
        Head-frame position from the refined left and right TOFs (m).
    output_snr : float
        The model's fit (``model_fit_snr``): the energy of the echoes it explains over the noise
        level, summed over the channels; the larger, the better the model explains the echoes.
    """

    echoes: tuple[Any, Any, Any]
    model: str
    position_m: NDArray[np.float64] = field(repr=False)
    output_snr: float


def tof_variance_s2(expected: NDArray[np.complex128], noise_power: NDArray[np.float64],
                    frequency_hz: NDArray[np.float64], signal_power: NDArray[np.float64]) -> NDArray[np.float64]:
    """Variance (s^2) of the envelope-maximum TOF, per row (module docstring).

    Parameters
    ----------
    expected : ndarray, shape (c, k)
        A, the expected echo's spectrum.
    noise_power : ndarray, shape (c, k)
        E|N_k|^2 of the segments' spectra.
    frequency_hz : ndarray, shape (k,)
    signal_power : ndarray, shape (c,)
        |z_s|^2, the noise-free peak's squared modulus (on the scale of sum X conj(A)).

    Returns
    -------
    ndarray, shape (c,)
        inf where the signal power is not positive.
    """
    w = np.abs(expected) ** 2
    omega = 2.0 * np.pi * np.asarray(frequency_hz, dtype=float)
    s0 = w.sum(axis=1)
    centroid = (w * omega).sum(axis=1) / s0
    spread = (omega - centroid[:, np.newaxis]) ** 2
    beta2 = (w * spread).sum(axis=1) / s0
    numerator = (spread * w * noise_power).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        variance = numerator / (2.0 * signal_power * beta2 ** 2)
    return np.where(signal_power > 0.0, variance, np.inf)


def segment_spectra(rows: NDArray[np.float64], t0_s: float, fs: float, starts_s: NDArray[np.float64], n_fft: int,
                    bins: NDArray[np.intp]) -> NDArray[np.complex128]:
    """Spectra (c, k) of the n_fft-sample segments of each row starting at ``starts_s`` (zeros
    outside the record) on ``bins``, with absolute-time phases X(f) = sum_n x[n] exp(-j 2 pi f t_n)."""
    import scipy.fft as sfft

    n = rows.shape[1]
    first = np.floor((starts_s - t0_s) * fs).astype(np.intp)
    index = first[:, np.newaxis] + np.arange(n_fft)
    inside = (index >= 0) & (index < n)
    segment = np.where(inside, rows[np.arange(rows.shape[0])[:, np.newaxis], np.clip(index, 0, n - 1)], 0.0)
    start = t0_s + first / fs
    return sfft.rfft(segment, axis=-1)[:, bins] * np.exp(-2j * np.pi * np.outer(start, bins * fs / n_fft))


def search_half_width_s(tof_s: NDArray[np.float64], busy_s: Sequence[NDArray[np.float64]],
                        config: BeamRefinementConfig) -> float:
    """The first pass's half-window (s): ``config.search_half_width_s``, narrowed to half the gap
    between a channel's TOF and the nearest other echo detected on that channel (never below
    ``config.track_half_width_s``), so that the search stays on its own echo and does not move
    onto a neighbour's: two reflectors at one range are separated on the side channels by
    2 d (sin theta_1 - sin theta_2) / c, 6 us for 4 deg."""
    half = float(config.search_half_width_s)
    for ch, t in enumerate(np.asarray(tof_s, dtype=float)):
        others = np.asarray(busy_s[ch] if ch < len(busy_s) else (), dtype=float)
        gaps = np.abs(others - t) if math.isfinite(t) else np.empty(0)
        gaps = gaps[gaps > 1e-9]  # the echo itself
        if gaps.size:
            half = min(half, max(0.5 * float(gaps.min()), float(config.track_half_width_s)))
    return half


def refine_target(echoes: Sequence[Any], setup: BeamSetup, noise: PingNoise,
                  model: str = "point") -> RefinedTarget | None:
    """One target's three echoes timed with ``model``'s expected echo, with their stds (module docstring).

    Parameters
    ----------
    echoes : sequence of 3 Echo or None
        The target's echoes (plain TOFs); one missing channel is searched first (``beam_cue``).
    setup : BeamSetup
    noise : PingNoise
        The ping's samples and echoes: the record within ``half_window_s`` of the echoes is
        searched, correlated and measured for noise.
    model : {"point", "vertical-edge"}

    Returns
    -------
    RefinedTarget or None
        None when, after the cued search, the left or right echo is still missing (the target
        cannot be located) or the echoes do not locate a target in front of the head.
    """
    from binsonar.localization.array_geometry import ArrayGeometry
    from binsonar.localization.beam_cue import cue_missing_echo

    config = setup.model_config(model)
    c = setup.sound_speed_m_s
    fs = setup.sample_rate_hz
    triple = tuple(echoes)
    times = [float(e.tof_s) for e in triple if e is not None]
    if not times:
        return None
    # The record around the target: what the searches, the correlation and the noise use.
    x, t0 = noise.window(min(times) - noise.half_window_s, max(times) + noise.half_window_s)
    common = dict(sample_rate_hz=fs, t0_s=t0, template=setup.template,
                  channel_positions_m=setup.channel_positions_m, sound_speed_m_s=c, transducers=setup.transducers)
    if config.cue_missing_channel and sum(e is None for e in triple) == 1:
        triple = cue_missing_echo(x, triple, config=config, **common)
    if triple[0] is None or triple[2] is None:
        return None
    tof = np.array([np.nan if e is None else float(e.tof_s) for e in triple])
    config = replace(config, search_half_width_s=search_half_width_s(tof, noise.busy_s, config))
    refined = refine_tofs(x, tof, config=config, **common)
    if not (np.all(np.isfinite(refined.position_m)) and np.all(np.isfinite(refined.tof_s[np.isfinite(tof)]))):
        return None
    geometry = ArrayGeometry.from_channel_positions(setup.channel_positions_m, setup.transducers.transmitter_channel)
    grid = CorrelationGrid.create(setup.template, setup.transducers, config.model, c, config.search_half_width_s)
    response, _ = expected_response(grid.frequency_hz, refined.position_m, geometry.transmitter_m,
                                    geometry.receivers_m, setup.transducers, c, grid.model)
    expected = grid.template_spectrum * response  # (3, k)
    active = np.isfinite(refined.tof_s)
    at = np.where(active, refined.tof_s, 0.0)
    spectrum = segment_spectra(x, t0, fs, at - config.search_half_width_s - grid.lead_s - 4.0 / fs, grid.n_fft,
                               grid.bins)
    z = np.sum(spectrum * np.conj(expected) * np.exp(2j * np.pi * np.outer(at, grid.frequency_hz)), axis=1)
    power = noise.spectrum(x, t0).bin_power(grid.frequency_hz, grid.n_fft)  # (3, k)
    noise_out = np.sum(np.abs(expected) ** 2 * power, axis=1)  # E|n|^2 of each filter's output
    signal = np.maximum(np.abs(z) ** 2 - noise_out, 1e-3 * noise_out)  # |z_s|^2, the noise's share removed
    std = np.sqrt(tof_variance_s2(expected, power, grid.frequency_hz, signal))
    snr_db = 10.0 * np.log10(2.0 * signal / noise_out)
    out = tuple(None if e is None else replace(e, tof_s=float(refined.tof_s[ch]), tof_std_s=float(std[ch]),
                                               snr_db=float(snr_db[ch]))
                for ch, e in enumerate(triple))
    return RefinedTarget(out, model, refined.position_m, model_fit_snr(z, expected, power, grid.template_spectrum, active))


def model_fit_snr(z: NDArray[np.complex128], expected: NDArray[np.complex128], noise_power: NDArray[np.float64],
                  template_spectrum: NDArray[np.complex128], active: NDArray[np.bool_]) -> float:
    """The statistic ``refine_target``'s models are compared by: sum over the active channels of
    |z_c|^2 / (P_c sum_k |A_ck|^2) - 1 (module docstring, "Comparing the models").

    Parameters
    ----------
    z : ndarray, shape (c,)
        The correlation sum_k X_k conj(A_k) at the model's refined TOF.
    expected : ndarray, shape (c, k)
        A, the model's expected echo.
    noise_power : ndarray, shape (c, k)
        E|N_k|^2 as estimated per bin (``NoiseSpectrum.bin_power``).
    template_spectrum : ndarray, shape (k,)
        T: the per-bin estimate is averaged over the band with the weights |T_k|^2, which do not
        depend on the model, into one level P_c per channel.
    active : ndarray of bool, shape (c,)

    Returns
    -------
    float
        The fitted echoes' energy over the noise level, less the noise's own share (1 per channel).
    """
    weight = np.abs(template_spectrum) ** 2
    level = np.sum(noise_power * weight, axis=1) / np.sum(weight)  # (c,)
    fit = np.abs(z) ** 2 / (level * np.sum(np.abs(expected) ** 2, axis=1)) - 1.0
    return float(np.sum(fit[active]))


__all__ = ("BeamSetup", "ECHO_MODELS", "NoiseSpectrum", "PingNoise", "RefinedTarget", "model_fit_snr", "refine_target",
           "search_half_width_s", "segment_spectra",
           "tof_variance_s2")
