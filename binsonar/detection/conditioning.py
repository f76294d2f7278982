"""The waveforms a method sees: the pings averaged and band-passed, with or without their DC offsets.

``PreparedDetector`` (``api``) chooses, from the method's attributes (``methods``): a method
that folds DC offsets into its arithmetic and runs without a band-pass gets the waveforms as
recorded (``average_keeping_offsets`` when it averages); every other gets them offset-free,
then averaged and band-passed (``average_and_bandpass``).
"""

from __future__ import annotations

from dataclasses import replace

from binsonar.detection.inputs import Signals


def average_and_bandpass(
    signals: Signals,
    average: bool,
    bandpass_hz: tuple[float, float] | None,
    bandpass_order: int,
) -> Signals:
    """Average the pings and/or band-pass them (``binsonar.preprocess``).

    The quantisation noise floor (``Signals.noise_floor_v``) is kept as it is: exact for
    noise below one code step, whose rounding errors are the same in every ping (averaging
    does not reduce them); conservative (an over-estimate, by up to sqrt(n_pings) and by the
    band-pass's share of the band) when the noise dithers the ADC.

    Parameters
    ----------
    signals : Signals
        Offset-free volts (``Signals.without_dc``).
    average : bool
        Average the pings (eq. 4.33): one ping, clipped where any ping clipped.
    bandpass_hz : (low_hz, high_hz) or None
        Zero-phase Butterworth band-pass of ``bandpass_order``.
    """
    from binsonar.preprocess import average_pings, bandpass

    waveforms = signals.waveforms
    clipped = signals.clipped
    if average:
        waveforms = average_pings(waveforms)
        clipped = clipped.any(axis=0, keepdims=True)
    if bandpass_hz is not None:
        waveforms = bandpass(waveforms, signals.sample_rate_hz, bandpass_hz[0], bandpass_hz[1], bandpass_order)
    if waveforms is signals.waveforms:
        return signals
    return signals.with_waveforms(waveforms, clipped)


def average_keeping_offsets(signals: Signals) -> Signals:
    """The pings' average (eq. 4.33) with its DC offset carried, not removed, for a method that
    folds offsets: mean_p(x_p - dc_p) = mean_p(x_p) - mean_p(dc_p) exactly, so the average of
    the waveforms as recorded plus the mean offset is the average of the offset-free pings,
    without a copy of each. One ping is its own average (no copy at all).
    """
    from binsonar.preprocess import average_pings

    if signals.n_pings == 1:
        return signals
    dc = None if signals.dc_v is None else signals.dc_v.mean(axis=0, keepdims=True)
    averaged = signals.with_waveforms(average_pings(signals.waveforms), signals.clipped.any(axis=0, keepdims=True))
    return replace(averaged, dc_v=dc)
