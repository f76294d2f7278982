"""Cramer-Rao bounds on the time of flight of a known echo, in white, coloured or reverberant noise.

Physics
-------
For a real echo x(t - tau) of known shape and unknown carrier phase in Gaussian noise of one-sided
power spectral density P(f), the Fisher information about tau gives (Van Trees, *Detection,
Estimation and Modulation Theory* I, sec. 2.4 and 6.2; ``physics.md`` section 6)

    sigma_tau >= 1 / (2 pi beta sqrt(S)),    S = sum_k w_k,    w_k = 4 |X_k|^2 / (n fs P(f_k)),

with beta^2 the w-weighted variance of f about its w-weighted centroid: the carrier phase being
unknown removes the centroid, leaving the envelope's bound. For white noise of variance s^2 per
sample, S = sum x^2 / s^2 = 2E/N0 and beta is the RMS bandwidth of the echo about its centroid:
``binsonar.bounds.tof_crlb_s``. The bound holds above the estimator's threshold SNR.

The matched filter's own output SNR is 2E/N0 = 2 max|z_s|^2 / mean|z_n|^2 with z the
correlation of the record with the analytic template (its complex envelope): z_s of the echo
alone, z_n of the noise alone (for white noise mean|z_n|^2 = 2 s^2 sum s_t^2 and the ratio is
sum x^2 / s^2 when the echo is the template). Interference that is Gaussian but not stationary
(reverberation: many independent scatterers whose level changes along the record) enters at its
level at the echo's delay, as the sonar equation's reverberation level does.

Method
------
``echo_tof_crlb_s``: the echo's DFT over the record and the noise's Welch PSD interpolated onto
its bins; ``analytic_correlation``: the correlation with the template's analytic signal
(``scipy.signal.hilbert``) at every full-overlap lag, by FFT convolution; ``matched_snr`` and
``interference_snr`` from it.

Accuracy
--------
The Welch PSD (segments of 1,024 samples, 19.5 kHz resolution at 20 MHz) is known to a few per
cent for records of thousands of samples; the DC bin is left out (the record's offset sits
there and carries no timing information). ``analytic_correlation`` is not
``binsonar.detection.matched``'s filter on purpose: a bound needs z at every integer lag of the
record, where the detector decimates its envelope (by ``MatchedPlan.decimation``, up to ~0.3 dB
below the peak) and refines only around its maxima.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray


class EchoBound(NamedTuple):
    """``echo_tof_crlb_s``'s result, one value per channel.

    Attributes
    ----------
    tof_std_s : ndarray, shape (c,)
        The bound on the TOF's standard deviation (s).
    snr_db : ndarray, shape (c,)
        S = sum of the per-bin SNR weights (the optimal filter's 2E/N0), in dB.
    """

    tof_std_s: NDArray[np.float64]
    snr_db: NDArray[np.float64]


def echo_tof_crlb_s(echo: ArrayLike, noise: ArrayLike, fs_hz: float, segment: int = 1024) -> EchoBound:
    """Cramer-Rao bound on the TOF of a known echo shape with unknown carrier phase, in coloured Gaussian noise.

    The bound of the module notes with the echo's own spectrum (half-integrated, cut by the
    beam, low-passed off axis: whatever it is) and the noise's own spectrum: what a whitened
    filter matched to the received echo reaches. For an echo that is the template in white
    noise it is ``binsonar.bounds.tof_crlb_s``.

    Parameters
    ----------
    echo, noise : array_like, shape (c, n)
        The noise-free echo alone and a noise record of the same length (V).
    fs_hz : float
        Sample rate (Hz).
    segment : int
        Welch segment length (samples) of the noise PSD (the integral of P is the variance).

    Returns
    -------
    EchoBound
        ``tof_std_s`` and ``snr_db``, shape (c,).
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
    return EchoBound(1.0 / (2.0 * np.pi * beta * np.sqrt(total)), 10.0 * np.log10(total))


def analytic_correlation(rows: ArrayLike, template: ArrayLike) -> NDArray[np.complex128]:
    """z, shape (c, n - m + 1): each row (c, n) correlated with the analytic template (m,), full-overlap lags only.

    z[k] = sum_t x[k + t] conj(a[t]), a = s + j H{s} the template's analytic signal: |z| is the
    matched filter's envelope at every integer lag (module notes).
    """
    from scipy.signal import fftconvolve, hilbert

    kernel = np.conj(hilbert(np.asarray(template, dtype=float)))[np.newaxis, ::-1]
    return fftconvolve(np.asarray(rows, dtype=float), kernel, mode="valid", axes=1)


def matched_snr(echo: ArrayLike, noise: ArrayLike, template: ArrayLike) -> NDArray[np.float64]:
    """2E/N0 (linear) at the matched filter's output: 2 max|z_s|^2 / mean|z_n|^2 per channel.

    Parameters
    ----------
    echo, noise : array_like, shape (c, n)
        The noise-free echo alone and the noise alone over the same record (V).
    template : array_like, shape (m,)
        The matched filter's template.

    Returns
    -------
    ndarray, shape (c,)
    """
    z_s = analytic_correlation(echo, template)
    z_n = analytic_correlation(noise, template)
    return 2.0 * np.max(np.abs(z_s) ** 2, axis=1) / np.mean(np.abs(z_n) ** 2, axis=1)


class InterferenceSnr(NamedTuple):
    """``interference_snr``'s result, one value per channel.

    Attributes
    ----------
    snr : ndarray, shape (c,)
        2E/N0 (linear) with the interference's local level added to the noise's.
    interference_level : ndarray, shape (c,)
        Mean |z|^2 of the interference around the echo's peak (V^2 times the template's energy).
    noise_level : ndarray, shape (c,)
        Mean |z|^2 of the noise over the record (same unit).
    """

    snr: NDArray[np.float64]
    interference_level: NDArray[np.float64]
    noise_level: NDArray[np.float64]

    @property
    def interference_to_noise_db(self) -> NDArray[np.float64]:
        """The interference's level at the echo over the noise's (dB; -3000 dB for none)."""
        return 10.0 * np.log10(np.maximum(self.interference_level, 1e-300) / self.noise_level)


def interference_snr(echo: ArrayLike, noise: ArrayLike, interference: list[ArrayLike],
                     template: ArrayLike) -> InterferenceSnr:
    """2E/N0 at the matched filter's output with non-stationary Gaussian interference at its local level.

    The interference (e.g. diffuse reverberation: a sum of many independent scatterers, Gaussian
    by the central limit theorem, whose power changes along the record) enters at its level at
    the echo's delay: the mean of |z_r|^2 (z_r the analytic correlation of the interference alone)
    over one template length centred on the peak of the echo's own |z_s|, averaged over the
    realisations given. 2E/N0 = 2 max|z_s|^2 / (mean|z_n|^2 over the record + that level).

    Parameters
    ----------
    echo, noise : array_like, shape (c, n)
        The noise-free echo alone and the noise alone (V).
    interference : list of array_like, shape (c, n)
        Realisations of the interference alone over the same record (V).
    template : array_like, shape (m,)

    Returns
    -------
    InterferenceSnr
    """
    z_s = analytic_correlation(echo, template)
    peak = np.argmax(np.abs(z_s), axis=1)
    half = len(template) // 2
    n_out = z_s.shape[1]
    window = np.stack([(np.arange(n_out) >= k - half) & (np.arange(n_out) <= k + half) for k in peak])
    levels = [np.sum(np.abs(analytic_correlation(r, template)) ** 2 * window, axis=1) / np.sum(window, axis=1)
              for r in interference]
    level = np.mean(levels, axis=0)
    noise_level = np.mean(np.abs(analytic_correlation(noise, template)) ** 2, axis=1)
    snr = 2.0 * np.max(np.abs(z_s) ** 2, axis=1) / (noise_level + level)
    return InterferenceSnr(snr, level, noise_level)
