"""The matched filter's decimated analytic envelope by overlap-save in short blocks.

The plain matched filter needs z(l) = sum_n x[n + l] s_a*[n] (s_a the template's analytic
signal) only at a decimated rate for detection: z is band limited to the template's band
[0, f_hi), so samples every D <= 1 / f_hi full-rate samples describe it completely (complex
sampling at a rate above its bandwidth), and the peak is refined at full rate afterwards
(``matched.refine_peaks``, in the time domain). ``matched.filtered_spectrum`` and
``matched.envelope`` get these samples from one real FFT of the whole record (n_fft ~ 256,000
points); here the record is cut into overlapping blocks of L samples (a few thousand) instead:

1. Block b holds record samples ``b H - lead .. b H - lead + L - 1`` (zero outside the record),
   ``lead`` the analytic template's taps before template sample 0 (``MatchedPlan.analytic_offset``).
2. Its real FFT, times the weights 2 conj(S_L) e^{2 pi i k lead / L} on the band's bins
   k < k_hi (S_L the template's spectrum on the L grid, DC weighted once; the phase factor
   puts lag 0 at block sample ``lead``), is the spectrum of the block's circular analytic
   correlation; an inverse FFT of only those bins, of length ``n_env`` = L / D, samples it
   every D full-rate samples.
3. Lags 0 .. H - 1 of a block (H = ``per_block`` D) see only samples of the block through the
   truncated analytic template's taps (H <= L - m_a + 1, m_a the taps' length), so the
   block's circular correlation there is the record's linear one up to the tails beyond that
   truncation (next paragraph); consecutive blocks' lags abut, giving z at lags 0, D, 2D, ...
   with H a whole number of samples.

What differs from the record-size FFT: both are the correlation with the template's
band-limited analytic signal, whose Hilbert tails decay only like 1/t (the analytic spectrum
steps at f = 0, where the 500 kHz pulse still has ~1 % of its peak amplitude). The record-size
FFT sums them over the whole record; a block sums them over its own span and wraps the rest
around (those beyond ``matched.ANALYTIC_TAIL`` = 1e-5 of the peak, the part the time-domain
refinement also truncates). On white noise the two envelopes differ by up to ~6e-3 of the
noise's RMS |z| at a block's first lags, less further in, and by ~1e-4 of an echo's peak
(``tests/unit/test_detection_overlap_save.py``): as much as the refinement's truncated template
already differs from either (``tests/unit/test_detection_matched.py``, ~1e-3 of the peak), and far
below the noise on any cell. The decimated grids differ too (D ~ 14.6 against ~14.9), which
changes neither the noise statistics (the median of |z|^2 over the cells: the same exponential
law) nor the false-alarm design (Rice's rate over the searched lags, a property of the
continuous envelope that both grids sample completely), nor the refined peak (recomputed at
full rate around the best cell).

Why: pocketfft's large transforms leave the cache, short ones stay in it; 35 real FFTs of
8,192 points per channel transform ~14 % more samples (the blocks' overlap) than one of
256,000 points, at a fraction of its time (``benchmarks/bench_detection.py`` compares the filter
with an FFT of the record).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.kernel_types import BLOCK_LAYOUT, read_only, record

# Block FFT sizes tried (powers of 2: pocketfft's fastest single-precision sizes). The cost
# model (``_cost``) picks one per template; longer templates need longer blocks.
BLOCK_SIZES: tuple[int, ...] = (2048, 4096, 8192, 16384, 32768, 65536)


@dataclass(frozen=True, eq=False)
class BlockEnvelopePlan:
    """Overlap-save parameters of the decimated analytic envelope for one template and record.

    Attributes
    ----------
    block : int
        Real FFT size L of a block (samples).
    n_env : int
        Inverse FFT size per block: the envelope's decimation is ``block / n_env``.
    per_block : int
        Decimated samples of z each block contributes (its lags 0, D, .., (per_block - 1) D).
    hop : int
        Lags (full-rate samples) between consecutive blocks: ``per_block * decimation``, whole.
    lead : int
        Record samples before lag 0 in a block (the analytic taps before template sample 0).
    n_cells : int
        Decimated samples computed: lags 0 .. (n_cells - 1) D cover every full-overlap lag
        [0, n_samples - template_length].
    n_blocks : int
    weights : ndarray, shape (k_hi,), complex
        2 conj(S_L[k]) e^{2 pi i k lead / L} on the band's rfft bins (DC weighted once).
    n_samples : int
        Record length the plan is for.
    """

    block: int
    n_env: int
    per_block: int
    hop: int
    lead: int
    n_cells: int
    n_blocks: int
    weights: NDArray[np.complex128] = field(repr=False)
    n_samples: int
    noise_gain: float
    """E|z|^2 / sigma^2 for white input noise of variance sigma^2: sum |w_k|^2 / L (Parseval,
    as ``matched.white_noise_power``)."""
    layout: NDArray[np.void] = field(repr=False)
    """``hop`` and ``lead`` as the gather kernel's read-only ``kernel_types.BLOCK_LAYOUT`` record."""

    @property
    def decimation(self) -> float:
        """Full-rate samples per decimated envelope sample, L / n_env."""
        return self.block / self.n_env


def _fast_sizes(low: int, count: int) -> list[int]:
    """The ``count`` smallest of pocketfft's fast complex FFT lengths (``scipy.fft.next_fast_len``)
    >= low, increasing."""
    import scipy.fft as sfft

    sizes: list[int] = []
    size = sfft.next_fast_len(max(int(low), 1))
    while len(sizes) < count:
        sizes.append(int(size))
        size = sfft.next_fast_len(size + 1)
    return sizes


def _cost(block: int, n_env: int, n_blocks: int) -> float:
    """Relative cost of the blocks' FFT pairs (n log n each; the complex inverse counts twice)."""
    return n_blocks * (block * math.log2(block) + 2.0 * n_env * math.log2(max(n_env, 2)))


def plan_blocks(
    samples: NDArray[np.float64],
    n_samples: int,
    band_edge_cycles: float,
    lead: int,
    taps_length: int,
    *,
    block: int | None = None,
) -> BlockEnvelopePlan:
    """Choose the block size and decimation and precompute the block weights.

    Parameters
    ----------
    samples : ndarray, shape (m,)
        The template (V), at the record's sample rate.
    n_samples : int
        Record length (samples).
    band_edge_cycles : float
        f_hi / fs: all but ``matched.BAND_ENERGY_TAIL`` of the template's energy lies below it.
    lead : int
        Analytic taps before template sample 0 (``MatchedPlan.analytic_offset``).
    taps_length : int
        Length m_a of the truncated analytic template (``MatchedPlan.analytic_template_conj``):
        a block's lags see only its own samples for the first L - m_a + 1 lags.
    block : int, optional
        Force this block FFT size (even, > the taps' span); default: the cheapest of
        ``BLOCK_SIZES`` by ``_cost``.

    Raises
    ------
    ValueError
        A forced block too short for the template.
    """
    import scipy.fft as sfft

    s = np.asarray(samples, dtype=float)
    m = s.size
    lead = int(lead)
    span = max(int(taps_length), m + lead)
    n_lags = n_samples - m + 1  # full-overlap lags 0 .. n - m
    best: tuple[float, int, int, int] | None = None
    forced = block
    if forced is not None and not (isinstance(forced, (int, np.integer)) and forced % 2 == 0 and forced > span):
        raise ValueError(f"plan_blocks: block must be an even integer > {span} (the analytic taps' span), "
                         f"got {forced!r}")
    for block in BLOCK_SIZES if forced is None else (int(forced),):
        if forced is None and block < 2 * span and block != BLOCK_SIZES[-1]:
            continue  # mostly overlap: a longer block is cheaper
        k_hi = int(min(block // 2 + 1, math.ceil(band_edge_cycles * block) + 2))
        for n_env in _fast_sizes(k_hi, 4):  # a few sizes just above the band
            step = block // math.gcd(block, n_env)  # hops that are a whole number of decimated samples
            hop = ((block - span + 1) // step) * step
            if hop <= 0:
                continue
            decimation = block / n_env
            n_cells = int(math.floor((n_lags - 1) / decimation)) + 1
            cost = _cost(block, n_env, -(-n_cells // int(round(hop / decimation))))
            if best is None or cost < best[0]:
                best = (cost, block, n_env, hop)
    if best is None:  # a template too long for any block: one block over the whole record
        block = int(sfft.next_fast_len(n_samples + span, real=True))
        k_hi = int(min(block // 2 + 1, math.ceil(band_edge_cycles * block) + 2))
        n_env = int(sfft.next_fast_len(k_hi))
        step = block // math.gcd(block, n_env)
        best = (0.0, block, n_env, ((block - span + 1) // step) * step)
    _, block, n_env, hop = best
    decimation = block / n_env
    per_block = int(round(hop / decimation))
    k_hi = int(min(block // 2 + 1, math.ceil(band_edge_cycles * block) + 2))
    n_cells = int(math.floor((n_lags - 1) / decimation)) + 1
    n_blocks = -(-n_cells // per_block)
    spectrum = sfft.rfft(s, block)[:k_hi]
    k = np.arange(k_hi)
    weights = 2.0 * np.conj(spectrum) * np.exp(2j * np.pi * k * lead / block)
    weights[0] *= 0.5
    return BlockEnvelopePlan(
        block=int(block),
        n_env=int(n_env),
        per_block=per_block,
        hop=int(hop),
        lead=int(lead),
        n_cells=n_cells,
        n_blocks=int(n_blocks),
        weights=weights,
        n_samples=int(n_samples),
        noise_gain=float(np.sum(np.abs(weights) ** 2)) / block,
        layout=read_only(record(BLOCK_LAYOUT, hop=int(hop), lead=int(lead))),
    )


def block_samples(
    plan: BlockEnvelopePlan, rows: NDArray[np.float64], dc: NDArray[np.float64] | None = None, single: bool = True,
    scale: float = 1.0,
) -> NDArray[np.floating]:
    """The blocks of every row, offsets removed, shape (n_rows, n_blocks, L): float32 with
    ``single`` (the default), else float64. Samples outside the record are 0. ``rows`` may be
    int16 ADC codes with ``scale`` their volts per code (read as they are, 2 bytes a sample).

    One compiled pass over the record (``overlap_save_kernels.gather_blocks``: the cast, the
    offset subtraction and the blocks' overlap together).
    """
    from binsonar.detection.overlap_save_kernels import gather_blocks

    n_rows, n = rows.shape
    if n != plan.n_samples:
        raise ValueError(f"block_samples: rows have {n} samples, the plan is for {plan.n_samples}")
    out = np.empty((n_rows, plan.n_blocks, plan.block), dtype=np.float32 if single else np.float64)
    offset = np.zeros(n_rows) if dc is None else np.ascontiguousarray(dc, dtype=float).reshape(n_rows)
    rows = np.ascontiguousarray(rows, dtype=np.int16 if np.issubdtype(rows.dtype, np.integer) else float)
    gather_blocks(rows, offset, float(scale), plan.layout, out)
    return out


def block_envelope(
    plan: BlockEnvelopePlan, rows: NDArray[np.float64], dc: NDArray[np.float64] | None = None, single: bool = True,
    scale: float = 1.0,
) -> NDArray[np.complexfloating]:
    """Decimated analytic filter output z at lags 0, D, 2D, .., shape (n_rows, n_cells).

    complex64 with ``single`` (the blocks' FFTs in float32, as ``matched.filtered_spectrum``'s
    ``single``: the TOF is refined from the float64 samples anyway), else complex128.

    Parameters
    ----------
    rows : ndarray, shape (n_rows, n_samples)
        Volts.
    dc : ndarray, shape (n_rows,), optional
        Offsets still in ``rows``: the result is that of ``rows - dc``.
    scale : float
        Volts per unit of ``rows``: 1.0 for volts, the code step for int16 ADC codes.
    """
    import scipy.fft as sfft

    n_rows = rows.shape[0]
    blocks = block_samples(plan, rows, dc, single, scale)
    spectrum = sfft.rfft(blocks, axis=-1, overwrite_x=True)[..., : plan.weights.size]
    spectrum *= plan.weights.astype(np.complex64) if single else plan.weights
    z = sfft.ifft(spectrum, plan.n_env, axis=-1, overwrite_x=True)[..., : plan.per_block]
    z = z.reshape(n_rows, plan.n_blocks * plan.per_block)[:, : plan.n_cells]
    z *= z.real.dtype.type(plan.n_env / plan.block)
    return z
