"""Echo rows whose spectrum is more than a gain and a phase: transfer functions and roughness.

Physics
-------
A row's echo at a receiver face is, per frequency (engineering convention, a delay d is
exp(-j 2 pi f d); ``acoustisim.synthesis.synthesiser``),

    P(f) = g Q(f) D(theta_tx, f) D(theta_rx, f) 10^(-alpha(f) L / 20) exp(j phi)
           exp(-S k^2) H(f) exp(-j 2 pi f tau),

the two extra factors being the coherent-roughness factor exp(-S k^2) (k = 2 pi f / c, S the
row's ``roughness_m2``) and the echo's transfer function H (``Paths.responses[response_id]``;
1 for a row without one). See :mod:`acoustisim.propagation.responses`.

Method
------
The table-driven kernels of :class:`~acoustisim.synthesis.synthesiser.PathSynthesiser` hold
an echo as short as the pulse; an elastic echo rings for tens of microseconds. These rows
(few: the echoes of elastic objects, the reflections on rough surfaces) get kernels of their
own, one length for all, long enough for the pulse, the directivity spread and the longest
response span: each row's spectrum is evaluated exactly on that kernel's bins (piston
directivity and absorption by their formulas, no tables), in blocks of rows, inverse
transformed and added into the decimated record at its start sample.

Accuracy
--------
Exact to float64 rounding within the synthesised band (the pulse's spectrum above -100 dB of
its peak), as long as H's impulse response lies within ``span_s`` (the response's promise).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.medium import Medium
from acoustisim.propagation.directivity import piston_directivity
from acoustisim.propagation.responses import EchoResponse, evaluate_transfers, roughness_factor, roughness_span_s
from acoustisim.synthesis.transducer import Pulse, pulse_spectrum, pulse_support_s

BLOCK_ROWS = 256
"""Rows whose spectra are built at once (bounds the (rows, bins) working arrays)."""


def needs_spectral_path(rows: NDArray[Any]) -> NDArray[np.bool_]:
    """Rows with a transfer function or a rough reflection, shape (n,)."""
    return (rows["response_id"] >= 0) | (rows["roughness_m2"] > 0.0)


def add_spectral_rows(record: NDArray[np.float64], rows: NDArray[Any], responses: Sequence[EchoResponse], *,
                      pulse: Pulse, medium: Medium, radius_m: float, sound_speed_m_s: float, fs_dec: float,
                      band_top_hz: float, keep: int) -> None:
    """Add the echoes of ``rows`` into the decimated ``record`` (3, M / q), in place.

    Parameters
    ----------
    record : ndarray, shape (3, M / q)
        Pressure at the receivers sampled at ``fs_dec`` (Pa), accumulated in place.
    rows : structured ndarray of PATH_DTYPE, shape (r,)
        Rows with derived columns filled; those with ``response_id`` >= 0 name an entry of
        ``responses``.
    responses : sequence of EchoResponse
    pulse, medium, radius_m, sound_speed_m_s
        The transmitted pulse, the water, the piston radius (m), c for the directivity (m/s).
    fs_dec : float
        Sample rate of ``record`` (Hz).
    band_top_hz : float
        Highest synthesised frequency (Hz); bins above are 0.
    keep : int
        Samples of ``record`` that count (later ones are dropped).
    """
    if rows.size == 0:
        return
    ids = rows["response_id"]
    if ids.max() >= len(responses):
        bad = int(np.flatnonzero(ids >= len(responses))[0])
        raise InputError(f"paths.response_id = {int(ids[bad])} at row {bad}: only {len(responses)} response(s) given")
    used = np.unique(ids[ids >= 0])
    position = np.searchsorted(used, ids)  # row -> its response among ``used`` (rows without: unused)
    spans = np.zeros((rows.size, 2))
    if used.size:
        spans = np.where((ids >= 0)[:, None], np.array([responses[int(rid)].span_s for rid in used])[
            np.minimum(position, used.size - 1)], 0.0)
    rough = np.array([roughness_span_s(s, sound_speed_m_s) for s in np.unique(rows["roughness_m2"])]).max()
    start, stop = pulse_support_s(pulse)
    spread = (np.abs(np.sin(rows["angle_tx_rad"])) + np.abs(np.sin(rows["angle_rx_rad"]))) * radius_m / sound_speed_m_s
    lead = rows["delay_s"] + spans[:, 0] - rough + start - spread
    tail = rows["delay_s"] + spans[:, 1] + rough + stop + spread
    first = np.floor(lead * fs_dec).astype(np.int64) - 2
    length = 1 << int(math.ceil(math.log2(float(np.max(tail * fs_dec - first)) + 4.0)))
    bins = np.arange(length // 2 + 1) * (fs_dec / length)
    inside = bins <= min(band_top_hz, 0.5 * fs_dec)
    f = bins[inside]
    q = fs_dec * pulse_spectrum(pulse, f)
    alpha_db_per_m = np.asarray(medium.absorption_db_per_m(f), dtype=float)
    # one row per distinct response (batched responses evaluated together), then a row of ones
    transfer = np.vstack([evaluate_transfers([responses[int(rid)] for rid in used], f, sound_speed_m_s),
                          np.ones((1, f.size), dtype=complex)])
    row_transfer = np.where(ids >= 0, np.minimum(position, used.size - 1), used.size)
    live = np.flatnonzero(first < keep)
    for lo in range(0, live.size, BLOCK_ROWS):
        block = live[lo:lo + BLOCK_ROWS]
        r = rows[block]
        spectra = np.zeros((block.size, bins.size), dtype=complex)
        shift = r["delay_s"] - first[block] / fs_dec
        values = (q * piston_directivity(r["angle_tx_rad"][:, None], f, radius_m, sound_speed_m_s)
                  * piston_directivity(r["angle_rx_rad"][:, None], f, radius_m, sound_speed_m_s)
                  * 10.0 ** (-np.multiply.outer(r["path_length_m"], alpha_db_per_m) / 20.0)
                  * (r["geometric_gain"] * np.exp(1j * r["phase_rad"]))[:, None]
                  * roughness_factor(r["roughness_m2"], f, sound_speed_m_s)
                  * np.exp(-2j * np.pi * np.multiply.outer(shift, f))
                  * transfer[row_transfer[block]])
        spectra[:, inside] = values
        kernels = np.fft.irfft(spectra, n=length, axis=1)
        samples = first[block][:, None] + np.arange(length)
        valid = (samples >= 0) & (samples < keep)
        channel = np.broadcast_to(r["channel"].astype(np.intp)[:, None], samples.shape)
        np.add.at(record, (channel[valid], samples[valid]), kernels[valid])


__all__ = ("BLOCK_ROWS", "add_spectral_rows", "needs_spectral_path")
