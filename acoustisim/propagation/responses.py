"""Frequency-dependent echo responses: what a path row cannot say with one gain and one phase.

Most rows are an impulse ``geometric_gain * delta(t - delay_s)`` with a constant phase, to which
synthesis adds directivity and absorption per frequency. Two effects need more:

* **coherent roughness** (every reflection on a rough surface): the Kirchhoff (Eckart) factor
  exp(-2 (k h sin theta_g)^2) per reflection (h the rms height, theta_g the grazing angle,
  k = 2 pi f / c; physics.md section 8). Over a row's reflections it is exp(-S k^2) with
  S = 2 sum_i (h_i sin theta_g,i)^2: one number per row, the ``roughness_m2`` column;
* **echo transfer functions** (``response_id`` >= 0): an echo whose spectrum is shaped by the
  object itself, e.g. an elastic post ringing after its specular echo, or the field
  diffracted into an obstacle's shadow. The row then stands for the whole echo, and
  ``Paths.responses[response_id]`` gives H(f), which multiplies the row's spectrum.

Conventions: H is in the engineering convention of synthesis (a delay d is exp(-j 2 pi f d));
H = 1 leaves the row as it is. ``span_s`` bounds the impulse response of H relative to the
row's delay (s), so that synthesis can size the kernel that holds it.

Batches: responses of many rows are cheaper together (the elastic echoes of one body share
their modal coefficients and are evaluated as one array). A response may therefore say that it
is the product of rows of :class:`ResponseBatch` es (``parts``: (batch, index) pairs) and of
other responses (``others``); :func:`evaluate_transfers` calls each batch once for all the rows
it serves. A response without ``parts`` is evaluated by its own ``transfer``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray


class EchoResponse(Protocol):
    """A transfer function multiplying one echo row's spectrum.

    Attributes
    ----------
    label : str
        What it is, for the ground truth (e.g. "elastic cylinder, pvc, bistatic 3.2 deg").
    span_s : tuple of 2 float
        (earliest, latest) time (s) of its impulse response relative to the row's delay:
        H's energy outside it is negligible for the synthesised echo (each response states its
        level: the elastic echoes' ring-down is below -60 dB of the echo's peak outside it).
    """

    label: str
    span_s: tuple[float, float]

    def transfer(self, frequency_hz: NDArray[np.float64], sound_speed_m_s: float) -> NDArray[np.complex128]:
        """H at ``frequency_hz`` (Hz, shape (n,)), complex, shape (n,)."""


class ResponseBatch(Protocol):
    """Transfer functions of many rows evaluated together.

    Its ``transfers`` gives the rows ``indices`` at ``frequency_hz``, complex (len(indices), n);
    a batch keeps what it computed, so asking again (other indices, the same frequencies) is cheap.
    """

    def transfers(self, frequency_hz: ArrayLike, sound_speed_m_s: float,
                  indices: ArrayLike | None = None) -> NDArray[np.complex128]:
        """H of rows ``indices`` (default all) at ``frequency_hz``."""


def evaluate_transfers(responses: Sequence[Any], frequency_hz: NDArray[np.float64],
                       sound_speed_m_s: float) -> NDArray[np.complex128]:
    """H of each response at ``frequency_hz``: (len(responses), n), complex.

    A response with ``parts`` (a tuple of (ResponseBatch, index)) is the product of those batch
    rows and of the transfer functions of its ``others``; every batch is asked once, for all its
    rows that the responses use. Any other response is asked for its own ``transfer``.
    """
    f = np.asarray(frequency_hz, dtype=float).ravel()
    out = np.ones((len(responses), f.size), dtype=complex)
    wanted: dict[int, tuple[Any, list[int]]] = {}
    for response in responses:
        for batch, index in getattr(response, "parts", ()):
            wanted.setdefault(id(batch), (batch, []))[1].append(int(index))
    tables = {}
    for key, (batch, indices) in wanted.items():
        unique = np.unique(indices)
        tables[key] = (unique, np.asarray(batch.transfers(f, sound_speed_m_s, unique), dtype=complex))
    for i, response in enumerate(responses):
        parts = getattr(response, "parts", None)
        if parts is None:
            out[i] = np.asarray(response.transfer(f, sound_speed_m_s), dtype=complex)
            continue
        for batch, index in parts:
            unique, table = tables[id(batch)]
            out[i] *= table[np.searchsorted(unique, int(index))]
        for other in getattr(response, "others", ()):
            out[i] *= np.asarray(other.transfer(f, sound_speed_m_s), dtype=complex)
    return out


def roughness_factor(roughness_m2: NDArray[np.float64], frequency_hz: NDArray[np.float64],
                     sound_speed_m_s: float) -> NDArray[np.float64]:
    """The coherent factor exp(-S k^2), k = 2 pi f / c, of rows with ``roughness_m2`` S (m^2).

    Parameters
    ----------
    roughness_m2 : ndarray, shape (r,)
        S = 2 sum over the row's reflections of (h sin theta_g)^2 (m^2).
    frequency_hz : ndarray, shape (n,)
    sound_speed_m_s : float

    Returns
    -------
    ndarray, shape (r, n)
    """
    k = 2.0 * np.pi * np.asarray(frequency_hz, dtype=float) / float(sound_speed_m_s)
    return np.exp(-np.multiply.outer(np.asarray(roughness_m2, dtype=float), k * k))


def roughness_span_s(roughness_m2: float, sound_speed_m_s: float) -> float:
    """Half-width (s) of the impulse response of exp(-S k^2): a Gaussian of standard deviation
    sqrt(2 S) / c in time; 7 standard deviations hold it to exp(-24.5) (-213 dB)."""
    return 7.0 * np.sqrt(2.0 * max(float(roughness_m2), 0.0)) / float(sound_speed_m_s)


__all__ = ("EchoResponse", "ResponseBatch", "evaluate_transfers", "roughness_factor", "roughness_span_s")
