"""The EchoResponse span promise, measured: how far above the rest an echo's energy reaches
outside ``span_s``."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

SAMPLE_RATE_HZ = 4e6
"""The measuring grid: 4 MHz, 2**13 samples (a 2 ms window: every response's echo fits)."""

N_SAMPLES = 1 << 13

BAND_TOP_HZ = 1.3e6
"""Above it the pulse is 100 dB down: H is evaluated below it only."""


def worst_outside_span_db(responses: Sequence[Any], pulse: Any, sound_speed_m_s: float,
                          margin_s: tuple[float, float]) -> float:
    """The largest level (dB re each echo's own peak) of the pulse's echo through a response's
    H outside its ``span_s`` widened by ``margin_s`` (earliest, latest: the pulse's own
    support, the first negative), over ``responses``."""
    from acoustisim.synthesis.transducer import pulse_spectrum

    f = np.fft.rfftfreq(N_SAMPLES, 1 / SAMPLE_RATE_HZ)
    band = f <= BAND_TOP_HZ
    spectrum = pulse_spectrum(pulse, f) * band
    t = np.fft.fftfreq(N_SAMPLES) * N_SAMPLES / SAMPLE_RATE_HZ  # times (s), the second half negative
    worst = -np.inf
    for response in responses:  # a few hundred responses, each one inverse FFT
        transfer = np.ones(f.size, dtype=complex)
        transfer[band] = response.transfer(f[band], sound_speed_m_s)
        echo = np.abs(np.fft.irfft(spectrum * transfer, N_SAMPLES))
        start, stop = response.span_s
        outside = (t < start + margin_s[0]) | (t > stop + margin_s[1])
        worst = max(worst, 20 * np.log10(echo[outside].max() / echo.max()))
    return float(worst)
