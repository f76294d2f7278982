"""Cued search for one channel's missing echo with the beam-aware filter.

At large bearings the far side receiver sees a target near its beam's null: the pistons'
directivity low-passes and weakens the echo there, and the plain matched filter (the
transmitted pulse, searched over the whole record) may miss it while it finds the target on the
two other channels. Those two echoes locate the target (``point.fit_point``), so they predict
when its echo reaches the third channel and what shape it has there
(``beam_model.expected_response``: the per-frequency directivity, and for an edge the
beam-weighted line integral). Correlating the channel with that shape over a short window around
the prediction gains twice over the plain search: the filter is matched to the off-axis echo,
and a window of microseconds needs a lower threshold than a whole record for the same
false-alarm probability.

Decision: the window's largest |z|^2, z the correlation with the expected echo
(``beam_correlation.correlation_maximum``), against the filter's noise level, the median of |z|^2 over
the channel divided by ln 2 (the mean of an exponential variable from its median; robust to the
few lags that echoes occupy, as the matched filter's own noise floor is), with the threshold of
``detection.matched.envelope_threshold_factor`` over the window (beta the RMS bandwidth of the
expected echo's spectrum) for ``BeamRefinementConfig.cue_pfa``.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Protocol, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from binsonar.localization.beam_correlation import CorrelationGrid, correlation_maximum, segment_spectra
from binsonar.localization.beam_model import BeamModelConfig, PistonTransducers, expected_response
from binsonar.recording import Template

PREDICTION_SIGMAS = 5.0
"""The window's half-width adds this many standard deviations of the predicted TOF to the
refinement's first-pass half-width (``search_half_width_s``, which covers the plain filter's
beam bias on the channels the prediction starts from)."""
NOISE_SEGMENTS = 64
"""At most this many segments, spread over the channel, estimate the filter's noise level (each
gives 2 x half-width x fs lags: thousands of lags, a median known to a few per cent)."""
FALLBACK_TOF_STD_S = 1e-7
"""TOF std (s) assumed for an echo without one when the two echoes are weighted in the fit."""


class CueSettings(Protocol):
    """What the cued search reads of its settings (``beam_refine.BeamRefinementConfig`` has them)."""

    @property
    def model(self) -> BeamModelConfig:
        """Target class and line-integral settings of the expected echo."""
        ...

    @property
    def search_half_width_s(self) -> float:
        """Half-width (s) of the window around the prediction, before the prediction's own spread."""
        ...

    @property
    def cue_pfa(self) -> float:
        """False-alarm probability of the search over its window."""
        ...


def cue_missing_echo(rows: ArrayLike, echoes: Sequence[Any], *, sample_rate_hz: float, t0_s: float,
                     template: Template, channel_positions_m: ArrayLike, sound_speed_m_s: float,
                     transducers: PistonTransducers, config: CueSettings) -> tuple[Any, Any, Any]:
    """The three echoes of one target, with the one missing channel searched where the others predict it.

    Parameters
    ----------
    rows : array_like, shape (3, n)
        The ping's channels (V), left, centre, right; sample i at ``t0_s + i / sample_rate_hz``.
    echoes : sequence of 3 ``binsonar.detection.Echo`` or None
        The target's echoes per channel; exactly one None is searched, otherwise they are
        returned as they are.
    sample_rate_hz, t0_s, template, channel_positions_m, sound_speed_m_s, transducers
        As ``beam_refine.refine_tofs``.
    config : CueSettings
        The window and false-alarm probability of the search (a ``BeamRefinementConfig``).

    Returns
    -------
    tuple of 3 Echo or None
        With the found echo in the missing channel's place (its ``tof_s`` the beam-aware
        correlation's maximum, ``snr_db`` 2E/N0 of that filter, ``score`` its |z|^2 over the
        threshold, ``tof_std_s`` the CRLB at that SNR and the expected echo's RMS bandwidth), or
        unchanged when nothing crosses the threshold or the two echoes cannot locate the target.
    """
    triple = tuple(echoes)
    missing = [ch for ch, e in enumerate(triple) if e is None]
    if len(triple) != 3 or len(missing) != 1:
        return triple  # type: ignore[return-value]
    found = search_channel(np.asarray(rows, dtype=float), triple, missing[0], sample_rate_hz=float(sample_rate_hz),
                           t0_s=float(t0_s), template=template, channel_positions_m=channel_positions_m,
                           sound_speed_m_s=float(sound_speed_m_s), transducers=transducers, config=config)
    if found is None:
        return triple  # type: ignore[return-value]
    return tuple(found if ch == missing[0] else e for ch, e in enumerate(triple))  # type: ignore[return-value]


def predicted_tof(echoes: Sequence[Any], channel: int, geometry: Any,
                  sound_speed_m_s: float) -> tuple[NDArray[np.float64], float, float] | None:
    """The target's head-frame position (3,) from the other two echoes, and ``channel``'s predicted TOF and its std (s).

    The position is the weighted least-squares point at the transmitter's height (the echoes'
    ``tof_std_s`` as weights); the std is the fit's covariance propagated through the channel's
    path length. None when the fit fails.
    """
    from binsonar.localization.point import fit_point, point_path_lengths

    c = sound_speed_m_s
    lengths = np.array([np.nan if e is None else c * float(e.tof_s) for e in echoes])
    stds = np.array([c * (float(e.tof_std_s) if e is not None and math.isfinite(e.tof_std_s) and e.tof_std_s > 0
                          else FALLBACK_TOF_STD_S) for e in echoes])
    fit = fit_point(lengths, stds, geometry)
    if not fit.ok or fit.parameters.size != 2:
        return None
    position = np.array([fit.parameters[0], fit.parameters[1], geometry.transmitter_m[2]])
    predicted, gradient = point_path_lengths(position, geometry)
    g = gradient[channel, :2]
    variance = float(g @ fit.covariance @ g)
    if not (math.isfinite(predicted[channel]) and math.isfinite(variance)):
        return None
    return position, float(predicted[channel]) / c, math.sqrt(max(variance, 0.0)) / c


def search_channel(rows: NDArray[np.float64], echoes: Sequence[Any], channel: int, *, sample_rate_hz: float,
                   t0_s: float, template: Template, channel_positions_m: ArrayLike, sound_speed_m_s: float,
                   transducers: PistonTransducers, config: CueSettings) -> Any:
    """The echo of ``channel`` found by the cued search (module docstring), or None."""
    from binsonar.bounds import tof_crlb_s
    from binsonar.detection.matched import envelope_threshold_factor
    from binsonar.localization.array_geometry import ArrayGeometry

    fs, c = sample_rate_hz, sound_speed_m_s
    if rows.ndim != 2 or rows.shape[0] != 3 or not math.isclose(template.sample_rate_hz, fs, rel_tol=1e-9):
        return None
    geometry = ArrayGeometry.from_channel_positions(np.asarray(channel_positions_m, dtype=float),
                                                    transducers.transmitter_channel)
    prediction = predicted_tof(echoes, channel, geometry, c)
    if prediction is None:
        return None
    position, _, std_s = prediction
    half = config.search_half_width_s + PREDICTION_SIGMAS * std_s
    grid = CorrelationGrid.create(template, transducers, config.model, c, half)
    response, delay = expected_response(grid.frequency_hz, position, geometry.transmitter_m, geometry.receivers_m,
                                        transducers, c, grid.model)
    expected = grid.template_spectrum * response[channel]  # (k,): the channel's echo, referred to its TOF
    energy = float(np.sum(np.abs(expected) ** 2))
    if not energy > 0.0:
        return None
    row = rows[channel] - np.median(rows[channel])
    centre = float(delay[channel])
    start = centre - half - grid.lead_s - 4.0 / fs
    spectrum, _ = segment_spectra(row[np.newaxis], t0_s, fs, np.array([start]), grid.n_fft, grid.bins)
    tof, peak = correlation_maximum(spectrum, expected[np.newaxis], grid.frequency_hz, np.array([centre]), half, fs)
    noise = filter_noise_level(row, expected, grid, half, fs)
    power = float(peak[0]) ** 2
    weights = np.abs(expected) ** 2
    f = grid.frequency_hz
    centroid = float(np.sum(weights * f) / energy)
    beta = math.sqrt(float(np.sum(weights * (f - centroid) ** 2) / energy))
    threshold = envelope_threshold_factor(config.cue_pfa, beta, 2.0 * half)
    if not (noise > 0.0 and power >= threshold * noise):
        return None
    snr = max(2.0 * power / noise - 2.0, 1e-3)
    full = np.zeros(grid.n_fft // 2 + 1, dtype=complex)
    full[grid.bins] = expected
    peak_voltage = float(np.max(np.abs(np.fft.irfft(full, grid.n_fft)))) * float(peak[0]) / energy
    template_echo = next(e for e in echoes if e is not None)
    return replace(template_echo, channel=channel, tof_s=float(tof[0]), amplitude=peak_voltage,
                   snr_db=10.0 * math.log10(snr), score=power / (threshold * noise),
                   tof_std_s=float(tof_crlb_s(snr, beta)), clipped=False)


def filter_noise_level(row: NDArray[np.float64], expected: NDArray[np.complex128], grid: CorrelationGrid,
                       half_width_s: float, fs: float) -> float:
    """Mean |z|^2 of the expected-echo filter's output on noise: median of |z|^2 over the channel / ln 2.

    Overlap-save with the search's own segments: segment j (``grid.n_fft`` samples) gives the
    lags of a whole window (2 ``half_width_s``), at most ``NOISE_SEGMENTS`` segments spread over
    the channel. |z| is on the same scale as ``correlation_maximum``'s peak.
    """
    n = row.size
    n_fft = grid.n_fft
    first = int(math.ceil(grid.lead_s * fs)) + 4  # lags where the whole echo lies in the segment
    valid = max(1, int(math.floor(2.0 * half_width_s * fs)))
    last_start = max(0, n - n_fft)
    count = min(NOISE_SEGMENTS, last_start // valid + 1)
    starts = np.unique(np.linspace(0, last_start, count).astype(np.intp))
    index = starts[:, np.newaxis] + np.arange(n_fft)
    segments = np.where(index < n, row[np.clip(index, 0, n - 1)], 0.0)
    product = np.zeros((starts.size, n_fft), dtype=complex)
    product[:, grid.bins] = np.fft.rfft(segments, axis=1)[:, grid.bins] * np.conj(expected)
    z = np.fft.ifft(product, axis=1) * n_fft  # the analytic correlation at integer lags
    power = np.abs(z[:, first:first + valid]) ** 2
    return float(np.median(power) / math.log(2.0))


__all__ = ("CueSettings", "cue_missing_echo", "filter_noise_level", "predicted_tof", "search_channel")
