"""Validated detector inputs: waveforms as (n_pings, n_channels, n_samples), and the template.

Everything a user can get wrong (shapes, NaN/inf, missing sample rate, a template longer than
the record, a template at another sample rate) is checked here, once, and reported as a
``RecordingError`` naming the source, the field and the value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.noise import MAD_TO_SIGMA, ROBUST_SAMPLES, ROBUST_SEGMENTS, robust_subsample, row_median
from binsonar.recording import Recording, RecordingError, Template


@dataclass(frozen=True, eq=False)
class Signals:
    """Waveforms ready for a detector.

    Attributes
    ----------
    waveforms : ndarray, shape (n_pings, n_channels, n_samples), float64
        Volts.
    sample_rate_hz : float
    t0_s : float
        Time of sample 0 after the transmit trigger (s).
    clipped : ndarray of bool, shape (n_pings, n_channels)
        Channels whose samples reached the ADC full scale.
    template : Template or None
        The recording's template (None for arrays).
    source : str
        File the waveforms came from, or "array".
    noise_floor_v : float
        Standard deviation (V) of the ADC's quantisation noise, q / sqrt(12) for a code step
        q (the variance of an error uniform over one step): the least noise a quantised record
        can carry, whatever quiet stretches of it look like (noise below one code step
        quantises to exactly constant samples). Every detector floors its noise estimates with
        it. 0 when the step is unknown (float arrays without ``adc_step_v``).
    dc_v : ndarray, shape (n_pings, n_channels), or None
        Each ping-channel's DC offset (its median, ``row_offsets``) still present in
        ``waveforms``; None when it has been removed (or is 0). Detectors that can fold the
        offset into their own arithmetic (threshold: compare x with median +/- level;
        local-matched: corrected energies and correlations) take the waveforms as recorded and
        the offsets, which saves a full copy of the record; the others get
        ``without_dc()``.
    """

    waveforms: NDArray[np.float64] = field(repr=False)
    sample_rate_hz: float
    t0_s: float
    clipped: NDArray[np.bool_] = field(repr=False)
    template: Template | None
    source: str
    noise_floor_v: float = 0.0
    dc_v: NDArray[np.float64] | None = field(default=None, repr=False)
    noise_sigma_v: NDArray[np.float64] | None = field(default=None, repr=False)
    """Robust noise standard deviation of each ping-channel (V), shape (n_pings, n_channels):
    1.4826 median |x - dc_v| over ``noise.robust_subsample``'s stretches, i.e.
    ``noise.noise_sigma``'s robust estimate (before its floor), measured together with
    ``dc_v`` (``robust_offsets``: one copy and two partitions of the few thousand samples per
    row, instead of two of each). None once the waveforms change (``with_waveforms``)."""
    volts_per_code: float | None = None
    """Set when ``waveforms`` are int16 ADC codes, not volts (volts = codes * volts_per_code;
    ``dc_v``, ``noise_sigma_v`` and ``noise_floor_v`` are in volts all the same). The detectors
    that read codes (``DetectionMethod.reads_codes``) take them (a quarter of the bytes of the volts); the others get
    ``in_volts()``."""
    pending_full_scales_v: tuple[float, ...] = ()
    """Full scales (V) the codes have not been tested against yet (``as_signals(...,
    defer_clipping=True)``): ``clipped`` then lacks that test until ``with_clipping_checked``
    (one pass over the codes) or ``with_extremes`` / ``clipped_flags`` (each row's extremes,
    measured by a detector that reads every sample anyway: ``local.detect_local_matched``'s
    ``extremes_out``) is applied."""

    def clipped_flags(self, extremes: NDArray) -> list[list[bool]]:
        """``clipped`` with the pending clipping test applied to each row's extremes, as nested
        Python lists (n_pings lists of n_channels bools).

        A row reaches one of the full scales exactly when it reaches the smallest of them, so
        one comparison per extreme (within a part in 1e9, as ``clipped_by_full_scale``), on
        Python floats: a few rows, and no numpy calls beyond one ``tolist`` of each array.

        Parameters
        ----------
        extremes : ndarray, shape (n_pings * n_channels, 2)
            Each ping-channel's largest and smallest value, in the units of ``waveforms``
            (codes).
        """
        flags = self.clipped.tolist()
        if not self.pending_full_scales_v:
            return flags
        step = 1.0 if self.volts_per_code is None else self.volts_per_code
        limit = min(self.pending_full_scales_v) * (1.0 - 1e-9)
        n_channels = self.n_channels
        for row, (high, low) in enumerate(np.asarray(extremes, dtype=float).tolist()):
            if high * step >= limit or low * step <= -limit:
                flags[row // n_channels][row % n_channels] = True
        return flags

    def with_extremes(self, extremes: NDArray) -> "Signals":
        """These signals with the pending clipping test applied to each row's extremes
        (``clipped_flags``; ``extremes`` of shape (n_pings * n_channels, 2)); self when none is
        pending."""
        if not self.pending_full_scales_v:
            return self
        return replace(self, clipped=np.array(self.clipped_flags(extremes), dtype=bool), pending_full_scales_v=())

    def with_clipping_checked(self) -> "Signals":
        """These signals with the pending clipping test done (one pass over the codes); self
        when none is pending."""
        if not self.pending_full_scales_v:
            return self
        from binsonar.detection.code_kernels import row_extremes

        rows = np.ascontiguousarray(self.waveforms).reshape(self.n_pings * self.n_channels, self.n_samples)
        largest = np.empty(rows.shape[0], dtype=np.int64)
        smallest = np.empty(rows.shape[0], dtype=np.int64)
        row_extremes(rows, largest, smallest)
        return self.with_extremes(np.stack([largest, smallest], axis=1))

    @property
    def n_pings(self) -> int:
        """Number of pings."""
        return int(self.waveforms.shape[0])

    @property
    def n_channels(self) -> int:
        """Channels per ping."""
        return int(self.waveforms.shape[1])

    @property
    def n_samples(self) -> int:
        """Samples per channel."""
        return int(self.waveforms.shape[2])

    def in_volts(self) -> "Signals":
        """These signals with the waveforms in volts (self when they are already), a pending
        clipping test done first (on the codes)."""
        if self.volts_per_code is None:
            return self
        return replace(self.with_clipping_checked(), waveforms=self.waveforms * self.volts_per_code, volts_per_code=None)

    def without_dc(self) -> "Signals":
        """These signals in volts with the DC offsets ``dc_v`` subtracted (self when they are
        volts without offsets)."""
        volts = self.in_volts()
        if volts.dc_v is None:
            return volts
        return volts.with_waveforms(volts.waveforms - volts.dc_v[:, :, np.newaxis])

    def with_waveforms(self, waveforms: NDArray[np.float64], clipped: NDArray[np.bool_] | None = None) -> "Signals":
        """A copy with other waveforms (same sample rate and time origin), offsets removed
        (``dc_v`` None): the caller gives waveforms with no DC left in them.

        Raises
        ------
        RecordingError
            A clipping test still pending (it must be judged on the codes as recorded).
        """
        if self.pending_full_scales_v:
            raise RecordingError(f"{self.source}: internal: new waveforms before the pending clipping test")
        return Signals(
            waveforms=waveforms,
            sample_rate_hz=self.sample_rate_hz,
            t0_s=self.t0_s,
            clipped=self.clipped if clipped is None else clipped,
            template=self.template,
            source=self.source,
            noise_floor_v=self.noise_floor_v,
        )


def clipped_by_full_scale(waveforms: NDArray[np.float64], full_scale_v: float) -> NDArray[np.bool_]:
    # A sample at (or beyond) the full scale, within a part in 1e9 for the int16 -> volts rounding:
    # |x| >= L exactly when max(x) >= L or min(x) <= -L (two reductions, no record-sized temporaries).
    limit = full_scale_v * (1.0 - 1e-9)
    return (waveforms.max(axis=-1) >= limit) | (waveforms.min(axis=-1) <= -limit)


def quantisation_noise_std_v(step_v: float) -> float:
    """Standard deviation (V) of the rounding error of an ADC with code step ``step_v``: q / sqrt(12)."""
    return float(step_v) / math.sqrt(12.0)


def row_offsets(waveforms: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """Each ping-channel's median (its DC offset), shape (n_pings, n_channels); None when
    every one is exactly 0.

    Real ADC data carry an offset, which the band detectors (energy, DWT) would otherwise see
    as energy switched on and off at the record's edges. The median, over the evenly spread
    stretches of ``noise.robust_subsample``, is robust to echoes (a few per cent of the
    samples move it by a few per cent of the noise) and, for data on an ADC's code grid, is
    itself a code, so the samples stay on a (shifted) code grid once it is subtracted
    (:meth:`Signals.without_dc`).
    """
    n_pings, n_channels, n = waveforms.shape
    median = row_median(robust_subsample(waveforms.reshape(n_pings * n_channels, n)))
    if not np.any(median != 0.0):
        return None
    return median.reshape(n_pings, n_channels)


def robust_offsets(waveforms: NDArray[np.float64]) -> tuple[NDArray[np.float64] | None, NDArray[np.float64]]:
    """``row_offsets`` and the robust noise estimate about them, from one subsample.

    Returns
    -------
    dc_v : ndarray, shape (n_pings, n_channels), or None
        As ``row_offsets`` (None when every median is exactly 0).
    sigma_v : ndarray, shape (n_pings, n_channels)
        ``noise.MAD_TO_SIGMA`` times the median of |x - dc_v| over the same samples: what
        ``noise.noise_sigma(rows, offset_v=dc_v)`` estimates (before its floor), equal to it
        exactly (the same elements selected from the same values).
    """
    n_pings, n_channels, n = waveforms.shape
    rows = waveforms.reshape(n_pings * n_channels, n)
    sample = robust_subsample(rows).reshape(rows.shape[0], -1)  # a copy, unless the rows are short
    if np.may_share_memory(sample, waveforms):
        sample = sample.copy()  # partitioned in place below: never the caller's samples
    k = sample.shape[1] // 2  # ``row_median``'s element
    sample.partition(k, axis=1)
    median = sample[:, k].copy()
    np.subtract(sample, median[:, np.newaxis], out=sample)
    np.abs(sample, out=sample)
    sample.partition(k, axis=1)
    sigma = MAD_TO_SIGMA * sample[:, k]
    dc = median.reshape(n_pings, n_channels) if np.any(median != 0.0) else None
    return dc, sigma.reshape(n_pings, n_channels)


def code_offsets(
    codes: NDArray[np.int16], volts_per_code: float, full_scales_v: tuple[float, ...] = ()
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64], NDArray[np.bool_]]:
    """``robust_offsets`` of records stored as ADC codes, in volts, and their clipping.

    The same subsample (``noise.robust_subsample``) and the same selected elements, counted by
    a histogram of the codes (``code_kernels.code_statistics``) rather than partitioned: the
    median code times ``volts_per_code`` is exactly the median of the volts (scaling by a
    positive number keeps the order); the deviation's median, taken in codes then scaled,
    equals the one taken in volts to the rounding of the volts' differences.

    Parameters
    ----------
    codes : ndarray of int16, shape (n_pings, n_channels, n_samples)
    volts_per_code : float
    full_scales_v : tuple of float
        Full scales (V) to test: a row is clipped when ``codes * volts_per_code`` reaches one
        (``clipped_by_full_scale``, judged on the codes' extremes, scaled: the volts'
        extremes). Empty: no clipping test, and no pass over the whole record.

    Returns
    -------
    dc_v : ndarray, shape (n_pings, n_channels), or None
        None when every median is 0.
    sigma_v : ndarray, shape (n_pings, n_channels)
    clipped : ndarray of bool, shape (n_pings, n_channels)
    """
    from binsonar.detection.code_kernels import code_statistics
    from binsonar.detection.kernel_types import CODE_SCALE, record

    n_pings, n_channels, n = codes.shape
    rows = np.ascontiguousarray(codes).reshape(n_pings * n_channels, n)
    if n <= ROBUST_SAMPLES:
        period, length, segments = n, n, 1
    else:
        period, length, segments = n // ROBUST_SEGMENTS, ROBUST_SAMPLES // ROBUST_SEGMENTS, ROBUST_SEGMENTS
    stats = np.empty((rows.shape[0], 3))
    scale = record(CODE_SCALE, period=period, length=length, segments=segments, volts_per_code=volts_per_code,
                   mad_to_sigma=MAD_TO_SIGMA)
    code_statistics(rows, scale, np.array(full_scales_v, dtype=float), stats)
    dc = stats[:, 0].reshape(n_pings, n_channels)
    return (dc if dc.any() else None), stats[:, 1].reshape(n_pings, n_channels), \
        (stats[:, 2] != 0.0).reshape(n_pings, n_channels)


def _code_signals(
    codes: NDArray[np.int16],
    volts_per_code: float,
    adc_bits: int | None,
    clipped: NDArray[np.bool_],
    full_scale_v: float | None,
    adc_step_v: float | None,
    sample_rate_hz: float,
    t0_s: float,
    template: Template | None,
    where: str,
    remove_dc: bool,
    defer_clipping: bool = False,
) -> Signals:
    """``Signals`` of ADC codes: clipping judged on the codes (the ADC's rails
    +/-(2^(bits - 1) - 1) codes, and ``full_scale_v``; left pending with ``defer_clipping``),
    offsets and noise from a histogram."""
    full_scales: tuple[float, ...] = () if full_scale_v is None else (float(full_scale_v),)
    if adc_bits is not None:
        full_scales += ((2 ** (int(adc_bits) - 1) - 1) * volts_per_code,)
    step = adc_step_v if adc_step_v is not None else volts_per_code
    defer = defer_clipping and not remove_dc
    dc, sigma, clipped_now = code_offsets(codes, volts_per_code, () if defer else full_scales)
    signals = Signals(codes, float(sample_rate_hz), float(t0_s), clipped | clipped_now, template, where,
                      quantisation_noise_std_v(step), dc, sigma, float(volts_per_code),
                      full_scales if defer else ())
    return signals.without_dc() if remove_dc else signals


def as_signals(
    data: Recording | NDArray[np.floating],
    sample_rate_hz: float | None = None,
    t0_s: float = 0.0,
    full_scale_v: float | None = None,
    adc_step_v: float | None = None,
    remove_dc: bool = True,
    volts_per_code: float | None = None,
    adc_bits: int | None = None,
    defer_clipping: bool = False,
) -> Signals:
    """Validate a recording or an array and return it as ``Signals``, each ping-channel's DC
    offset removed (or, with ``remove_dc=False``, measured and carried in ``Signals.dc_v``).

    The offset is the row's median (:func:`row_offsets`), subtracted before any detector runs;
    clipping is judged on the samples as recorded. An absolute threshold level (the threshold
    detector's ``level_v``) is therefore measured from that median.

    Parameters
    ----------
    data : Recording or array_like
        Shapes (n_samples,), (3, n_samples) or (n_pings, 3, n_samples), volts; or integer ADC
        codes with ``volts_per_code``. A recording that carries its codes
        (``Recording.codes``) is taken as codes.
    sample_rate_hz : float, optional
        Required for arrays; for a recording it must agree with the file if given.
    t0_s : float
        Time of sample 0 after the trigger (s), arrays only.
    full_scale_v : float, optional
        ADC full scale (V): channels with a sample at or beyond it are flagged as clipped. For a
        recording stored as ADC codes, the code full scale is used as well.
    adc_step_v : float, optional
        ADC code step q (V) of the data: sets ``Signals.noise_floor_v`` = q / sqrt(12). For a
        recording stored as ADC codes its ``volts_per_code`` is used when this is not given.
    remove_dc : bool
        Subtract the offsets from a copy of the waveforms (default), or leave the waveforms as
        they are and return the offsets as ``dc_v`` (the caller removes or folds them).
        Codes are converted to volts when the offsets are removed; kept as codes otherwise
        (``Signals.volts_per_code``).
    volts_per_code : float, optional
        Arrays only: ``data`` are integer ADC codes (int16 range) of this step (V); they stay
        codes (no conversion to volts here).
    adc_bits : int, optional
        Arrays of codes only: the ADC's resolution; a code at +/-(2^(bits - 1) - 1) is clipped.
    defer_clipping : bool
        ADC codes kept as codes (``remove_dc=False``) only: leave the full-scale test of the
        codes pending (``Signals.pending_full_scales_v``) for the caller to finish
        (``Signals.with_clipping_checked`` or ``with_extremes``), saving a pass over the codes
        when the detector reads every sample anyway. Ignored otherwise.

    Raises
    ------
    RecordingError
        Wrong shape, non-finite samples, missing or invalid sample rate.
    """
    if full_scale_v is not None and not (math.isfinite(full_scale_v) and full_scale_v > 0):
        raise RecordingError(f"full_scale_v must be a finite number > 0, got {full_scale_v!r}")
    if adc_step_v is not None and not (
        isinstance(adc_step_v, (int, float)) and math.isfinite(adc_step_v) and adc_step_v > 0
    ):
        raise RecordingError(f"adc_step_v must be a finite number > 0, got {adc_step_v!r}")
    if isinstance(data, Recording):
        where = data.source or "recording"
        if sample_rate_hz is not None and not math.isclose(sample_rate_hz, data.sample_rate_hz, rel_tol=1e-12):
            raise RecordingError(
                f"{where}: sample_rate_hz={sample_rate_hz!r} disagrees with the recording's {data.sample_rate_hz!r}"
            )
        if data.codes is not None:
            return _code_signals(data.codes, float(data.volts_per_code), data.adc_bits,  # type: ignore[arg-type]
                                 np.array(data.clipped, dtype=bool), full_scale_v, adc_step_v, data.sample_rate_hz,
                                 data.t0_s, data.template, where, remove_dc, defer_clipping)
        waveforms = np.asarray(data.waveforms, dtype=float)
        clipped = np.array(data.clipped, dtype=bool)
        if data.volts_per_code is not None and data.adc_bits is not None:
            code_full_scale = (2 ** (int(data.adc_bits) - 1) - 1) * data.volts_per_code
            clipped |= clipped_by_full_scale(waveforms, code_full_scale)
        if full_scale_v is not None:
            clipped |= clipped_by_full_scale(waveforms, full_scale_v)
        step = adc_step_v if adc_step_v is not None else data.volts_per_code
        floor = 0.0 if step is None else quantisation_noise_std_v(step)
        dc, sigma = robust_offsets(waveforms)
        signals = Signals(waveforms, float(data.sample_rate_hz), float(data.t0_s), clipped, data.template, where, floor,
                          dc, sigma)
        return signals.without_dc() if remove_dc else signals

    where = "array"
    if volts_per_code is not None:
        if not (isinstance(volts_per_code, (int, float)) and math.isfinite(volts_per_code) and volts_per_code > 0):
            raise RecordingError(f"{where}: volts_per_code must be a finite number > 0, got {volts_per_code!r}")
        if adc_bits is not None and not (isinstance(adc_bits, (int, np.integer)) and 2 <= adc_bits <= 16):
            raise RecordingError(f"{where}: adc_bits must be an integer in [2, 16], got {adc_bits!r}")
        kind = np.asarray(data).dtype
        if not np.issubdtype(kind, np.integer):
            raise RecordingError(f"{where}: volts_per_code is given, so the waveforms must be integer ADC codes, "
                                 f"got dtype {kind}")
        waveforms = np.asarray(data)
    elif adc_bits is not None:
        raise RecordingError(f"{where}: adc_bits={adc_bits!r} needs volts_per_code (integer ADC codes)")
    else:
        try:
            waveforms = np.asarray(data, dtype=float)  # no copy for float64 input: never written to
        except (TypeError, ValueError) as exc:
            raise RecordingError(f"{where}: waveforms are not a numeric array: {exc}") from None
    if waveforms.ndim == 1:
        waveforms = waveforms[np.newaxis, np.newaxis, :]
    elif waveforms.ndim == 2 and waveforms.shape[0] == 3:
        waveforms = waveforms[np.newaxis]
    if waveforms.ndim != 3 or waveforms.shape[1] != 3 and not (waveforms.shape[1] == 1 and np.ndim(data) == 1):
        raise RecordingError(
            f"{where}: waveforms must have shape (n_samples,), (3, n_samples) or (n_pings, 3, n_samples), "
            f"got {np.shape(data)}"
        )
    if waveforms.shape[0] < 1 or waveforms.shape[2] < 2:
        raise RecordingError(f"{where}: waveforms are empty (shape {np.shape(data)})")
    if volts_per_code is not None:
        if waveforms.dtype != np.int16:
            if waveforms.min() < -32768 or waveforms.max() > 32767:
                raise RecordingError(f"{where}: ADC codes must fit int16, got values in "
                                     f"[{waveforms.min()}, {waveforms.max()}]")
            waveforms = waveforms.astype(np.int16)
        _check_rate(where, sample_rate_hz, t0_s)
        return _code_signals(waveforms, float(volts_per_code), adc_bits, np.zeros(waveforms.shape[:2], dtype=bool),
                             full_scale_v, adc_step_v, float(sample_rate_hz), float(t0_s), None,  # type: ignore[arg-type]
                             where, remove_dc, defer_clipping)
    # The sum is finite unless a sample is NaN/inf (or it overflows): one cheap pass first.
    finite = np.isfinite(waveforms) if not np.isfinite(waveforms.sum()) else None
    if finite is not None and not finite.all():
        bad = np.argwhere(~finite)[0]
        raise RecordingError(
            f"{where}: waveforms contain NaN or infinite samples (first at ping {bad[0]}, channel {bad[1]}, "
            f"sample {bad[2]})"
        )
    _check_rate(where, sample_rate_hz, t0_s)
    clipped = np.zeros(waveforms.shape[:2], dtype=bool)
    if full_scale_v is not None:
        clipped |= clipped_by_full_scale(waveforms, full_scale_v)
    floor = 0.0 if adc_step_v is None else quantisation_noise_std_v(adc_step_v)
    dc, sigma = robust_offsets(waveforms)
    signals = Signals(waveforms, float(sample_rate_hz), float(t0_s), clipped, None, where, floor, dc, sigma)
    return signals.without_dc() if remove_dc else signals


def _check_rate(where: str, sample_rate_hz: float | None, t0_s: float) -> None:
    """An array's sample rate (required, finite, > 0) and time origin (finite)."""
    if sample_rate_hz is None:
        raise RecordingError(f"{where}: sample_rate_hz is required for array input")
    if not (isinstance(sample_rate_hz, (int, float)) and math.isfinite(sample_rate_hz) and sample_rate_hz > 0):
        raise RecordingError(f"{where}: sample_rate_hz must be a finite number > 0, got {sample_rate_hz!r}")
    if not math.isfinite(t0_s):
        raise RecordingError(f"{where}: t0_s must be finite, got {t0_s!r}")


def _resample_template(template: Template, sample_rate_hz: float) -> Template:
    """The template at another sample rate (band-limited Fourier interpolation, t0 preserved)."""
    from scipy.signal import resample

    s = template.samples
    pad = s.size  # zero padding on both sides so the periodic interpolation does not wrap
    padded = np.concatenate([np.zeros(pad), s, np.zeros(pad)])
    ratio = sample_rate_hz / template.sample_rate_hz
    n_new = int(round(padded.size * ratio))
    resampled = resample(padded, n_new) * 1.0
    # Keep the span that held the original samples (plus a sample of margin).
    start = max(int(math.floor(pad * ratio)) - 1, 0)
    stop = min(int(math.ceil((pad + s.size) * ratio)) + 1, n_new)
    # Time of resampled sample i: template.t0_s - pad / fs_old + i / fs_new.
    t0 = template.t0_s - pad / template.sample_rate_hz + start / sample_rate_hz
    return Template(resampled[start:stop], sample_rate_hz, t0, template.kind)


def resolve_template(
    template: Template | NDArray[np.floating] | None,
    signals: Signals,
    method: str,
) -> Template:
    """The template a method uses, at the signals' sample rate.

    Parameters
    ----------
    template : Template, array_like or None
        An explicit template (an array is taken at the signals' sample rate with t0_s = 0, i.e.
        a TOF refers to its first sample); None takes the recording's.
    signals : Signals
    method : str
        For the error message.

    Raises
    ------
    RecordingError
        No template available, an invalid one, or one longer than the record.
    """
    where = signals.source
    if template is None:
        template = signals.template
        if template is None:
            raise RecordingError(
                f"{where}: method {method!r} needs a template: the recording has none; pass template=..."
            )
    elif not isinstance(template, Template):
        try:
            template = Template(np.asarray(template, dtype=float), signals.sample_rate_hz, 0.0, "user")
        except (TypeError, ValueError) as exc:
            raise RecordingError(f"{where}: template: {exc}") from None
    if not math.isclose(template.sample_rate_hz, signals.sample_rate_hz, rel_tol=1e-9):
        template = _resample_template(template, signals.sample_rate_hz)
    if not np.any(template.samples != 0.0):
        raise RecordingError(f"{where}: template has no energy (all samples are zero)")
    if template.samples.size > signals.n_samples:
        raise RecordingError(
            f"{where}: template ({template.samples.size} samples) is longer than the record "
            f"({signals.n_samples} samples)"
        )
    return template


def template_rms_duration_s(template: Template) -> float:
    """RMS duration (s) of the template's energy, sqrt(sum (t - tc)^2 s^2 / sum s^2).

    0.67 us for the 5 us Gaussian pulse; 4 times it spans about 95 % of its energy.
    """
    s2 = template.samples ** 2
    t = np.arange(s2.size) / template.sample_rate_hz
    weight = s2 / s2.sum()
    centre = float(np.sum(t * weight))
    return float(math.sqrt(np.sum((t - centre) ** 2 * weight)))
