"""The transfer function of Keller's apex rows: sqrt(f0 / f), the half-integrated pulse of an edge.

An edge's diffracted wave near its onset is the pulse integrated by half an order (spectrum
falling 3 dB per octave, phase -45 deg: physics.md section 4; derivation and validity in
:mod:`acoustisim.propagation.reference.edge_apex`). The apex rows carry the phase in
``phase_rad`` and the gain at f0 in ``geometric_gain``; this response gives the rest, the
magnitude sqrt(f0 / f), and states its span measured on the sonar's pulse.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext

APEX_RESPONSE_ID = 0
"""The ``response_id`` of every apex row: the solver puts :class:`ApexResponse` first."""

LOWEST_FREQUENCY_FRACTION = 0.1
"""sqrt(f0 / f) is held at its value at this fraction of f0 below it (where k r < 1 for the
edge's shortest legs Keller's expansion fails; the seed's pulse is 60 dB down there)."""

SPAN_LEVEL = 1e-3
"""The span ends where the band-limited echo stays below this fraction of its peak (-60 dB,
the promise of the elastic echoes' spans)."""


@dataclass(frozen=True)
class ApexResponse:
    """sqrt(f0 / f) of the apex rows (held below ``LOWEST_FREQUENCY_FRACTION`` f0): an
    :class:`~acoustisim.propagation.responses.EchoResponse`.

    Attributes
    ----------
    centre_frequency_hz : float
        f0 (Hz), where the response is 1.
    pulse : object
        The transmitted pulse (its ``spectrum(f)``), on which :attr:`span_s` is measured.
    label : str
    """

    centre_frequency_hz: float
    pulse: Any
    label: str = "edge diffraction, Keller apex: sqrt(f0 / f), -45 deg"

    def transfer(self, frequency_hz: NDArray[np.float64], sound_speed_m_s: float) -> NDArray[np.complex128]:
        """H at ``frequency_hz`` (Hz, (n,)): complex (n,)."""
        f = np.maximum(np.abs(np.asarray(frequency_hz, dtype=float)),
                       LOWEST_FREQUENCY_FRACTION * self.centre_frequency_hz)
        return np.sqrt(self.centre_frequency_hz / f).astype(complex)

    @cached_property
    def span_s(self) -> tuple[float, float]:
        """(earliest, latest) time (s) of the band-limited apex echo relative to its delay,
        beyond the pulse's own extent: outside it the echo stays below :data:`SPAN_LEVEL` of its
        peak. Measured once (at synthesis) on the echo Q(f) sqrt(f0 / f) exp(-j pi / 4) sampled
        at 16 f0 over 2048 periods, from its first to its last sample above the level, less
        the pulse's own such extent."""
        f0 = float(self.centre_frequency_hz)
        fs = 16.0 * f0
        n = 2048 * 16
        f = np.fft.rfftfreq(n, 1.0 / fs)
        pulse = np.asarray(self.pulse.spectrum(f), dtype=complex)
        echo = np.fft.irfft(pulse * self.transfer(f, 0.0) * np.exp(-0.25j * np.pi), n)
        alone = np.fft.irfft(pulse, n)
        t = np.where(np.arange(n) < n // 2, np.arange(n), np.arange(n) - n) / fs

        def extent(signal: NDArray[np.float64]) -> tuple[float, float]:
            above = np.flatnonzero(np.abs(signal) >= SPAN_LEVEL * np.max(np.abs(signal)))
            return float(t[above].min()), float(t[above].max())

        (echo_lo, echo_hi), (pulse_lo, pulse_hi) = extent(echo), extent(alone)
        return (min(echo_lo - pulse_lo, 0.0), max(echo_hi - pulse_hi, 0.0))


def apex_response(context: SolveContext) -> ApexResponse:
    """The solve's :class:`ApexResponse` (the sonar's centre frequency and pulse)."""
    return ApexResponse(float(context.centre_frequency_hz), context.sonar.pulse)


__all__ = ("APEX_RESPONSE_ID", "ApexResponse", "LOWEST_FREQUENCY_FRACTION", "SPAN_LEVEL", "apex_response")
