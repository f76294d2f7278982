"""An independent matched filter for the synthesis tests: delay and amplitude of a template in a
record, from the band-limited interpolant of the correlation."""

import math

import numpy as np


def matched_filter(x, template, fs, t0):
    """Delay (s) and amplitude ratio of the template in x, band-limited sub-sample peak (Newton)."""
    n = 1 << int(math.ceil(math.log2(x.size + template.size)))
    cross = np.fft.rfft(x, n) * np.conj(np.fft.rfft(template, n))
    k = np.arange(cross.size)
    weight = np.full(cross.size, 2.0)
    weight[0] = 1.0
    weight[-1] = 1.0
    lag = float(np.argmax(np.fft.irfft(cross, n)))
    for _ in range(8):  # Newton on the band-limited interpolant of the correlation
        phasor = cross * weight * np.exp(2j * np.pi * k * lag / n)
        w = 2.0 * np.pi * k / n
        d1 = np.sum((1j * w * phasor).real)
        d2 = np.sum((-(w**2) * phasor).real)
        lag -= d1 / d2
    peak = np.sum((cross * weight * np.exp(2j * np.pi * k * lag / n)).real) / n
    return lag / fs - t0, peak / np.sum(template**2)
