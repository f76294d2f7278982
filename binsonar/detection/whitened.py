"""Extended matched filter for coloured noise (seed section 4.1.4, eq. 4.27).

H(f) = S*(f) / S_n(f): pre-whitening by 1/sqrt(S_n) of both the record and the template,
then the matched filter with the whitened template. The noise PSD S_n is estimated per channel
by Welch's method on a noise-only segment (default: the whole record with median averaging,
which the few segments holding echoes do not move). Everything else (envelope, noise floor,
sub-sample peak, SNR) is the matched filter's, with the weights 2 S* / S_n.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.matched import (
    MatchedPlan,
    check_pfa,
    echo_values,
    envelope,
    filtered_spectrum,
    noise_mean_power,
    plan_matched,
    refine_peaks,
    white_noise_power,
)
from binsonar.detection.noise import window_indices
from binsonar.recording import RecordingError, Template

# The PSD is floored at this fraction of its maximum so that bins with (numerically) no noise
# cannot get unbounded weight.
PSD_FLOOR = 1e-8


class InterpolatedPsd:
    """A noise PSD tabulated by Welch, interpolated linearly in frequency, floored.

    Parameters
    ----------
    frequency_hz : ndarray, shape (k,)
    psd : ndarray, shape (k,)

    floor : float
        Least PSD (the ADC's quantisation noise, 2 sigma_q^2 / fs one-sided), > 0 unless the
        PSD itself has a positive maximum.
    """

    def __init__(self, frequency_hz: NDArray[np.float64], psd: NDArray[np.float64], floor: float = 0.0) -> None:
        self._f = np.asarray(frequency_hz, dtype=float)
        p = np.maximum(np.asarray(psd, dtype=float), float(floor))
        if not float(p.max()) > 0.0:
            raise ValueError("the noise PSD is zero at every frequency")
        self._p = np.maximum(p, PSD_FLOOR * float(p.max()))

    def __call__(self, frequency_hz: NDArray[np.float64]) -> NDArray[np.float64]:
        """PSD at these frequencies."""
        return np.interp(frequency_hz, self._f, self._p)


def estimate_psd(
    row: NDArray[np.float64],
    *,
    sample_rate_hz: float,
    t0_s: float,
    nperseg: int,
    noise_window_s: tuple[float, float] | None,
    where: str,
    noise_floor_v: float = 0.0,
) -> InterpolatedPsd:
    """Welch PSD (Hann window, 50 % overlap, median averaging) of one row's noise-only part.

    Floored at the one-sided density 2 noise_floor_v^2 / fs of white noise with the ADC's
    quantisation noise variance.

    Raises
    ------
    RecordingError
        A segment with no noise at all (a dead, all-zero channel) and no floor.
    """
    from scipy.signal import welch

    segment = row if noise_window_s is None else row[window_indices(noise_window_s, row.size, sample_rate_hz, t0_s, where)]
    if segment.size < nperseg:
        raise RecordingError(
            f"{where}: the noise segment ({segment.size} samples) is shorter than nperseg={nperseg}"
        )
    f, p = welch(segment, fs=sample_rate_hz, nperseg=nperseg, average="median", detrend=False)
    try:
        return InterpolatedPsd(f, p, 2.0 * float(noise_floor_v) ** 2 / sample_rate_hz)
    except ValueError:
        raise RecordingError(
            f"{where}: whitened-matched: a channel has no noise (its noise spectrum is zero: a dead, all-zero "
            "channel?); nothing to whiten with: pass adc_step_v, or use another method"
        ) from None


def detect_whitened_matched(
    rows: NDArray[np.float64],
    template: Template,
    *,
    sample_rate_hz: float,
    t0_s: float,
    pfa: float = 1e-3,
    nperseg: int = 1024,
    noise_window_s: tuple[float, float] | None = None,
    where: str = "record",
    noise_floor_v: float = 0.0,
) -> list[list[tuple[float, float, float, float, float]]]:
    """Strongest echo of each row after pre-whitening with its own noise PSD.

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
    template : Template
    sample_rate_hz, t0_s : float
    pfa : float
        Design false-alarm probability per record.
    nperseg : int
        Welch segment length (samples): frequency resolution fs / nperseg (19.5 kHz at 20 MHz
        with 1024, fine against the pulse's ~300 kHz band).
    noise_window_s : (start_s, stop_s), optional
        Noise-only window for the PSD.
    noise_floor_v : float
        Least noise standard deviation (V), the ADC's quantisation noise: floors the PSD and
        the filter output's noise mean.

    Returns
    -------
    list (n_rows) of list of (tof_s, amplitude, snr_db, score, tof_std_s)
    """
    pfa = check_pfa(pfa)
    if not (isinstance(nperseg, (int, np.integer)) and 16 <= nperseg):
        raise RecordingError(f"{where}: nperseg must be an integer >= 16, got {nperseg!r}")
    out: list[list[tuple[float, float, float, float, float]]] = []
    for r in range(rows.shape[0]):  # one filter per channel (its own noise spectrum)
        psd = estimate_psd(
            rows[r], sample_rate_hz=sample_rate_hz, t0_s=t0_s, nperseg=int(nperseg),
            noise_window_s=noise_window_s, where=where, noise_floor_v=noise_floor_v,
        )
        plan: MatchedPlan = plan_matched(template, rows.shape[1], sample_rate_hz, psd)
        row = rows[r:r + 1]
        spectrum = filtered_spectrum(plan, row)
        z = envelope(plan, spectrum)
        power = z.real ** 2 + z.imag ** 2
        noise = noise_mean_power(power, float(white_noise_power(plan, noise_floor_v)))
        coarse = np.argmax(power, axis=1)
        lag, peak = refine_peaks(plan, row, spectrum, np.zeros(1, dtype=np.intp), coarse * plan.decimation)
        values = echo_values(plan, lag, peak, noise, plan.threshold_factor(pfa), t0_s)
        echo = tuple(float(v[0]) for v in values)
        out.append([echo] if echo[3] >= 1.0 else [])  # type: ignore[list-item]
    return out
