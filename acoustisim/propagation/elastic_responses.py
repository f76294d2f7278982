"""The transfer functions of elastic echoes, evaluated lazily for all rows of one body at once.

:mod:`acoustisim.propagation.elastic_echoes` gives every echo row off an elastic post, sphere or
pipe an :class:`ElasticEchoResponse`; the rows of one body (same shape, radius, body and
material) share one :class:`ElasticRows`, which computes their transfer functions together when
synthesis first asks (:func:`acoustisim.propagation.responses.evaluate_transfers`).

Physics
-------
The transfer function of a row is the exact echo over today's geometric-optics row
(:mod:`acoustisim.scattering.echo`, engineering convention). A post row whose (image) source
and receiver are offset along the axis (elevation e: rows via the floor or the surface) is,
in phase 1's model, the normal-incidence series at the frequency f cos(e) with
kappa = k cos(e); since k/L = kappa/L_h and k sin(e) dz - k L = -kappa L_h, it is exactly

    H_row(f) = conj(C) T(f cos e),   C = cos(e) g_flat / g_row,

T the transfer function of the "flat" row (the same distances from the axis and bistatic angle,
no axial offset, path length L_h) and g_flat, g_row today's rows R(cos theta_i) G of the two
geometries. So one coefficient table per body serves every elevation.

Method
------
1. Band: [0, F], F the frequency where the sonar's pulse falls 100 dB below its peak (the
   synthesiser's band), computed to F_int = F (1 + TAPER_FRACTION) and rolled off above F by an
   erfc taper (the samples of step 2 are then band-limited, and the taper leaves every
   frequency up to F untouched to 1e-8).
2. Window: the flat transfer functions are computed on the grid k / W, W the window (s). W
   starts at :data:`FIRST_WINDOW_S` and doubles (the coefficients of the coarser grid are every
   other point of the finer one and are kept) until the pulse-filtered monostatic echo of the
   body (at the rows' median distance) falls below :data:`SPAN_LEVEL_DB` of its peak at least
   :data:`GUARD_S` before the window's end and after its start (nothing wraps around); at most
   :data:`MAX_WINDOW_S`. ``span_s`` is where that echo lies above the level, less the pulse.
3. Time responses: the flat rows' T on the grid (one modal sum per row,
   :func:`acoustisim.scattering.echo_series.series_transfer`), tapered, inverse FFT, and
   faded in and out over the first and last GUARD_S / 2 of the window (a raised cosine): the
   ring-down a row holds there (rows other than the reference ring a little longer) would
   otherwise end in a step, whose band-limited edge step 4 spreads as a precursor.
4. Spectra: each row's time response at f cos(e) for the requested frequencies f (chirp-z,
   :func:`acoustisim.scattering.spectral_resampling.response_spectrum`), times conj(C).
Everything is kept per sound speed and requested grid: the rows of one Paths are computed once
however many pings and records are synthesised from them.

Accuracy
--------
Rows without elevation at frequencies of the grid: the exact series (1e-11). Elsewhere the
band-limited interpolation of step 4 is exact for a response held by the window: what rings
longer than the window (below ``SPAN_LEVEL_DB`` of the echo's peak in the pulse's band) wraps
around, and the taper's smoothing reaches into the window by its Gaussian tail (the taper's
width, 0.15 F, makes it 1e-9 within GUARD_S). Measured against direct evaluation at f cos(e),
weighted by the pulse spectrum: ``tests/physics/test_elastic_echo_responses.py``. The span
is measured on the reference row: over the thesis tank's default pose, rows at other distances
and bistatic angles ring up to 2.2 dB above the span level just after it (-57.8 dB). A product
of several factors (an echo off two bodies, or in a shadow) has the sum of their spans; its
echo was measured up to -42.5 dB re its peak just past that sum (post-3 off itself in post-1's
shadow), which the product's span does not yet bound. The oblique
model itself (normal-incidence coefficients at f cos(e)) neglects the elastic coupling of
oblique incidence, an error of order e^2 (phase 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

from acoustisim.scattering.arrivals import InternalArrival, internal_arrivals, shell_arrivals
from acoustisim.scattering.bodies import Elastic, Fluid, Shell
from acoustisim.scattering.echo import EchoGeometry, EchoTarget
from acoustisim.scattering.echo_series import series_transfer
from acoustisim.scattering.modal import modal_coefficients
from acoustisim.scattering.series import ModalCoefficients
from acoustisim.scattering.spectral_resampling import response_spectrum

__all__ = ("BAND_LEVEL_DB", "EXACT_FREQUENCIES", "ElasticEchoResponse", "ElasticRows", "FIRST_WINDOW_S", "GUARD_S", "MAX_WINDOW_S",
           "ResponseWindow", "SPAN_LEVEL_DB", "TAPER_FRACTION", "edge_fade")

BAND_LEVEL_DB = -100.0
"""The band computed: up to where the pulse spectrum is this far below its peak (the
synthesiser's ``SYNTHESIS_BAND_DB``)."""

TAPER_FRACTION = 0.15
"""Width of the roll-off above the band, as a fraction of its top F."""

SPAN_LEVEL_DB = -60.0
"""The pulse-filtered echo outside ``span_s`` is below this level relative to its peak: below a
12-bit digitiser's 72 dB range for any echo that does not fill it, and 20 dB or more under the
noise of the tank's pings (the demo's averaged record, the clutter experiment's 40 dB SNR)."""

GUARD_S = 30e-6
"""Room kept at both ends of the window (s) for what the taper and the span level leave out: the
taper's Gaussian smoothing (sigma_f = 0.15 F / (8 sqrt 2) = 17 kHz at the thesis pulse's
F = 1.3 MHz, i.e. 9 us in time) and the ring-down just under the span level."""

FIRST_WINDOW_S = 192e-6
"""The first window tried (s)."""

MAX_WINDOW_S = 4.096e-3
"""The longest window (s); an echo that rings longer at the span level wraps around."""

PRECURSOR_S = 10e-6
"""How early (s) before its specular delay an echo may rise above the span level (the pulse's
own half-length and the 1/(ka) precursor of the exact series; phase 1)."""

EXACT_FREQUENCIES = 256
"""Requests needing at most this many distinct f cos(e) are evaluated exactly (a coefficient table
of that size costs less than the time responses)."""

SPAN_MARGIN = 0.05
"""Relative margin on the measured span (other distances and bistatic angles than the
monostatic reference shift the internal arrivals by a few per cent at most)."""


def edge_fade(n_samples: int, n_fade: int) -> NDArray[np.float64]:
    """A window of ``n_samples`` that rises over its first ``n_fade`` samples and falls over its
    last ``n_fade`` as half a raised cosine, 1 between: (n_samples,)."""
    fade = np.ones(n_samples)
    ramp = 0.5 - 0.5 * np.cos(np.pi * (np.arange(n_fade) + 0.5) / n_fade)
    fade[:n_fade] = ramp
    fade[n_samples - n_fade:] = ramp[::-1]
    return fade


class ResponseWindow(NamedTuple):
    """The grid and window of one body's responses at one sound speed.

    Attributes
    ----------
    band_top_hz : float
        F: the band the responses must hold.
    window_s : float
        W: the grid's spacing is 1 / W (Hz).
    frequency_hz : ndarray, shape (I,)
        The grid k / W, k = 0..I-1, up to F (1 + TAPER_FRACTION).
    taper : ndarray, shape (I,)
        1 up to F, erfc roll-off to 0 at the grid's top.
    coefficients : ModalCoefficients
        The body's A_n at ``frequency_hz[1:]``.
    span_s : tuple of 2 float
        (earliest, latest) time of the transfer function's impulse response relative to the
        row's delay (s), for :class:`~acoustisim.propagation.responses.EchoResponse`.
    envelope_db : ndarray, shape (M,)
        The pulse-filtered monostatic echo's envelope (dB re its peak) at ``times_s``.
    times_s : ndarray, shape (M,)
        From -``pre_s`` to W - ``pre_s`` (s), relative to the specular delay.
    pre_s : float
        The window's start before the specular delay (s).
    wraps : bool
        True when even :data:`MAX_WINDOW_S` did not hold the echo at the span level.
    """

    band_top_hz: float
    window_s: float
    frequency_hz: NDArray[np.float64]
    taper: NDArray[np.float64]
    coefficients: ModalCoefficients
    span_s: tuple[float, float]
    envelope_db: NDArray[np.float64]
    times_s: NDArray[np.float64]
    pre_s: float
    wraps: bool


def roll_off(frequency_hz: NDArray[np.float64], band_top_hz: float) -> NDArray[np.float64]:
    """The taper: 1 to F, 0.5 erfc over (F, F (1 + TAPER_FRACTION)) from 1 - 8e-9 to 8e-9."""
    width = TAPER_FRACTION * band_top_hz
    x = 8.0 * (frequency_hz - band_top_hz) / width - 4.0
    return np.where(frequency_hz <= band_top_hz, 1.0, 0.5 * special.erfc(x))


@dataclass(frozen=True, eq=False)
class ElasticRows:
    """The echo rows of one elastic body (a :class:`~acoustisim.propagation.responses.ResponseBatch`).

    Attributes
    ----------
    target : EchoTarget
        Shape, radius, body, and the material today's rows used.
    flat : EchoGeometry
        The rows' flat geometry (posts: no axial offset; spheres: as they are), R rows.
    compression : ndarray, shape (R,)
        cos(e) of each row (1 for spheres and rows in the plane normal to the axis).
    factor : ndarray of complex, shape (R,)
        conj(C) (module docstring).
    object_ids : ndarray of int, shape (R,)
        The surface (index into ``Paths.surface_names``) of each row's echo.
    water_density_kg_m3, sound_speed_m_s : float
        The water of the solve.
    pulse : GaussianPulse or SampledPulse
        The sonar's pulse (it sets the band and weighs the span).

    Everything computed is kept (``memo``), keyed by sound speed and requested frequencies.
    """

    target: EchoTarget
    flat: EchoGeometry
    compression: NDArray[np.float64]
    factor: NDArray[np.complex128]
    object_ids: NDArray[np.int64]
    water_density_kg_m3: float
    sound_speed_m_s: float
    pulse: Any = field(repr=False)
    memo: dict[Any, Any] = field(default_factory=dict, compare=False, repr=False)

    @property
    def n_rows(self) -> int:
        """R."""
        return int(self.compression.size)

    def water(self, sound_speed_m_s: float | None = None) -> Fluid:
        """The host water at ``sound_speed_m_s`` (default the solve's)."""
        c = self.sound_speed_m_s if sound_speed_m_s is None else float(sound_speed_m_s)
        return Fluid(self.water_density_kg_m3, c)

    # ------------------------------------------------------------------ window and span
    def window(self, sound_speed_m_s: float | None = None, band_top_hz: float | None = None) -> ResponseWindow:
        """The grid, window and span at ``sound_speed_m_s`` (module docstring, steps 1-2)."""
        c = self.sound_speed_m_s if sound_speed_m_s is None else float(sound_speed_m_s)
        top = max(self._pulse_band_top_hz(), 0.0 if band_top_hz is None else float(band_top_hz))
        key = ("window", c, top)
        if key not in self.memo:
            self.memo[key] = self._find_window(c, top)
        return self.memo[key]

    @property
    def span_s(self) -> tuple[float, float]:
        """(earliest, latest) time (s) of every row's impulse response relative to its delay."""
        return self.window().span_s

    def _pulse_band_top_hz(self) -> float:
        if "band" not in self.memo:
            from acoustisim.synthesis.transducer import pulse_band_top_hz

            self.memo["band"] = pulse_band_top_hz(self.pulse, BAND_LEVEL_DB)
        return float(self.memo["band"])

    def _coefficients(self, frequency_hz: NDArray[np.float64], water: Fluid) -> ModalCoefficients:
        shape = "sphere" if self.target.shape == "sphere" else "cylinder"
        return modal_coefficients(shape, self.target.body, self.target.radius_m, frequency_hz, water)

    def _find_window(self, c: float, top: float) -> ResponseWindow:
        from acoustisim.synthesis.transducer import pulse_spectrum, pulse_support_s

        water = self.water(c)
        distance = float(np.median(np.sqrt(self.flat.source_distance_m * self.flat.receiver_distance_m)))
        reference = EchoGeometry(np.array([distance]), np.array([distance]), np.zeros(1), np.zeros(1))
        pulse_start, pulse_stop = pulse_support_s(self.pulse)
        window = FIRST_WINDOW_S
        previous: ModalCoefficients | None = None
        while True:
            step = 1.0 / window
            frequency = step * np.arange(int(math.ceil(top * (1.0 + TAPER_FRACTION) / step)) + 1)
            coefficients = self._refined(previous, frequency[1:], water)
            taper = roll_off(frequency, top)
            monostatic = np.zeros(frequency.size, dtype=complex)
            monostatic[1:] = series_transfer(self.target, reference, water, coefficients)[0]
            # analytic signal of the pulse-filtered echo: one-sided spectrum, doubled
            n_time = 2 * (frequency.size - 1)
            spectrum = np.zeros(n_time, dtype=complex)
            spectrum[:frequency.size] = 2.0 * pulse_spectrum(self.pulse, frequency) * monostatic * taper
            envelope = np.abs(np.fft.ifft(spectrum))
            dt = window / n_time
            pre = GUARD_S + PRECURSOR_S
            shift = int(math.ceil(pre / dt))
            envelope = np.roll(envelope, shift)
            times = (np.arange(n_time) - shift) * dt
            level = 20.0 * np.log10(np.maximum(envelope / envelope.max(), 1e-300))
            above = times[level > SPAN_LEVEL_DB]
            first, last = float(above.min()), float(above.max())
            fits = first >= -PRECURSOR_S and last <= times[-1] - GUARD_S
            if fits or window >= MAX_WINDOW_S:
                span = (min(0.0, first - pulse_start),
                        max(0.0, last - pulse_stop) * (1.0 + SPAN_MARGIN) + 2e-6)
                return ResponseWindow(top, window, frequency, taper, coefficients, span, level, times,
                                      shift * dt, not fits)
            previous = coefficients
            window *= 2.0

    def _refined(self, coarse: ModalCoefficients | None, frequency_hz: NDArray[np.float64],
                 water: Fluid) -> ModalCoefficients:
        """A_n at ``frequency_hz`` (k / W, k >= 1), reusing ``coarse`` (at 2 k / W) for even k."""
        if coarse is None:
            return self._coefficients(frequency_hz, water)
        n = frequency_hz.size
        reuse = np.arange(1, n, 2)  # frequency_hz[j] = (j + 1) / W: even multiples at odd j
        reuse = reuse[(reuse - 1) // 2 < coarse.coefficients.shape[0]]
        fresh = np.setdiff1d(np.arange(n), reuse)
        new = self._coefficients(frequency_hz[fresh], water)
        orders = max(coarse.orders.size, new.orders.size)
        table = np.zeros((n, orders), dtype=complex)
        table[reuse, :coarse.orders.size] = coarse.coefficients[(reuse - 1) // 2]
        table[fresh, :new.orders.size] = new.coefficients
        k = water.wavenumber(2.0 * math.pi * frequency_hz)
        return ModalCoefficients(new.shape, np.arange(orders), table, k, new.radius_m)

    # ------------------------------------------------------------------ transfer functions
    def time_responses(self, sound_speed_m_s: float | None = None,
                       band_top_hz: float | None = None) -> tuple[NDArray[np.float64], float, float]:
        """Every flat row's tapered impulse response (R, M), its first sample's time and step (s)."""
        window = self.window(sound_speed_m_s, band_top_hz)
        key = ("time", window.window_s, window.band_top_hz, self.water(sound_speed_m_s).sound_speed_m_s)
        if key not in self.memo:
            spectra = np.zeros((self.n_rows, window.frequency_hz.size), dtype=complex)
            spectra[:, 1:] = series_transfer(self.target, self.flat, self.water(sound_speed_m_s), window.coefficients)
            n_time = 2 * (window.frequency_hz.size - 1)
            samples = np.fft.irfft(spectra * window.taper, n=n_time, axis=1)
            dt = window.window_s / n_time
            shift = int(round(window.pre_s / dt))
            self.memo[key] = (np.roll(samples, shift, axis=1) * edge_fade(n_time, int(round(0.5 * GUARD_S / dt))),
                              -shift * dt, dt)
        return self.memo[key]

    def transfers(self, frequency_hz: ArrayLike, sound_speed_m_s: float,
                  indices: ArrayLike | None = None) -> NDArray[np.complex128]:
        """H of rows ``indices`` (default all) at ``frequency_hz``: (len(indices), K), engineering convention.

        A few frequencies (at most :data:`EXACT_FREQUENCIES` distinct f cos(e) over the rows) are
        evaluated exactly (:meth:`exact_transfers`); more (a synthesis grid) through the time
        responses (module docstring, steps 3-4).
        """
        f = np.asarray(frequency_hz, dtype=float).ravel()
        c = float(sound_speed_m_s)
        key = ("transfer", c, f.tobytes())
        if key not in self.memo:
            if np.unique(np.multiply.outer(self.compression, f)).size <= EXACT_FREQUENCIES:
                self.memo[key] = self.exact_transfers(f, c)
            else:
                samples, start, step = self.time_responses(c, float(f.max()))
                self.memo[key] = response_spectrum(samples, start, step, f, self.compression) * self.factor[:, None]
        table = self.memo[key]
        return table if indices is None else table[np.asarray(indices, dtype=np.int64)]

    def exact_transfers(self, frequency_hz: ArrayLike, sound_speed_m_s: float | None = None
                        ) -> NDArray[np.complex128]:
        """H of every row at ``frequency_hz`` (K,) from coefficients at each f cos(e): (R, K), exact."""
        f = np.asarray(frequency_hz, dtype=float).ravel()
        water = self.water(sound_speed_m_s)
        scaled = np.multiply.outer(self.compression, f)
        out = np.zeros(scaled.shape, dtype=complex)
        positive = scaled > 0.0
        if np.any(positive):
            unique, which = np.unique(scaled[positive], return_inverse=True)
            index = np.zeros(scaled.shape, dtype=np.int64)
            index[positive] = which
            coefficients = self._coefficients(unique, water)
            values = series_transfer(self.target, self.flat, water, coefficients, row_bins=index)
            out = np.where(positive, values, 0.0) * self.factor[:, None]
        return out

    # ------------------------------------------------------------------ ground truth
    def internal_arrivals(self) -> tuple[InternalArrival, ...]:
        """The body's named arrivals after the specular echo (monostatic; :mod:`acoustisim.scattering.arrivals`)."""
        if "arrivals" not in self.memo:
            body, water = self.target.body, self.water()
            if isinstance(body, Shell):
                arrivals = shell_arrivals(body, self.target.radius_m, water)
            elif isinstance(body, Elastic):
                arrivals = internal_arrivals(body, self.target.radius_m, water)
            else:
                arrivals = ()
            self.memo["arrivals"] = arrivals
        return self.memo["arrivals"]

    def level_db(self, delay_s: ArrayLike) -> NDArray[np.float64]:
        """The pulse-filtered monostatic echo's envelope (dB re its peak) at ``delay_s`` after the
        specular delay (s): the level of an internal arrival in this sonar's echo."""
        window = self.window()
        return np.interp(np.asarray(delay_s, dtype=float), window.times_s, window.envelope_db)


@dataclass(frozen=True, eq=False)
class ElasticEchoResponse:
    """The transfer function of one echo row: the product of its elastic bodies' factors and of
    the responses the row had before (an :class:`~acoustisim.propagation.responses.EchoResponse`).

    Attributes
    ----------
    label : str
        What it is (ground truth).
    parts : tuple of (ElasticRows, int)
        Each elastic interaction of the row: its body's rows and the row's index there.
    others : tuple of EchoResponse
        Responses the row carried before (multiplied in).
    """

    label: str
    parts: tuple[tuple[ElasticRows, int], ...]
    others: tuple[Any, ...] = ()

    @property
    def span_s(self) -> tuple[float, float]:
        """The sum of the factors' spans (their impulse responses convolve)."""
        spans = [batch.span_s for batch, _ in self.parts] + [tuple(r.span_s) for r in self.others]
        return (float(sum(s[0] for s in spans)), float(sum(s[1] for s in spans)))

    def transfer(self, frequency_hz: NDArray[np.float64], sound_speed_m_s: float) -> NDArray[np.complex128]:
        """H at ``frequency_hz`` (Hz, (n,)): complex (n,)."""
        f = np.asarray(frequency_hz, dtype=float).ravel()
        out = np.ones(f.size, dtype=complex)
        for batch, index in self.parts:
            out *= batch.transfers(f, sound_speed_m_s, [index])[0]
        for other in self.others:
            out *= np.asarray(other.transfer(f, sound_speed_m_s), dtype=complex)
        return out
