"""``detect``: one entry point for every detection method, on recordings or arrays."""

from __future__ import annotations

import inspect
import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Hashable, Protocol

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.echo import DetectionResult, Echo
from binsonar.detection.inputs import Signals, as_signals, resolve_template
from binsonar.detection.seed import SEED_COMBINATIONS, seed_combination
from binsonar.recording import Recording, RecordingError, Template

BASE_METHODS: tuple[str, ...] = (
    "threshold",
    "energy",
    "matched",
    "whitened-matched",
    "local-matched",
    "dwt",
    "ca-cfar",
    "os-cfar",
)
METHODS: tuple[str, ...] = BASE_METHODS + tuple(c.name for c in SEED_COMBINATIONS)
CLIPPED_POLICIES: tuple[str, ...] = ("flag", "drop", "error")
# Rows (ping-channels) processed together: bounds the spectra held at once (24 x 250,000
# samples: about 50 MB of complex spectrum) while keeping the FFTs batched.
ROW_CHUNK = 24

RawEchoes = list[list[tuple[float, float, float, float, float]]]

# Parameters of the method functions that ``detect`` supplies itself (not user options).
_SUPPLIED = frozenset({"rows", "plan", "template", "sample_rate_hz", "t0_s", "where", "kind", "noise_floor_v", "dc_v",
                       "robust_sigma_v", "volts_per_code", "extremes_out"})
# Base methods that take the robust noise estimate measured with the offsets
# (``Signals.noise_sigma_v``, as ``robust_sigma_v``) instead of measuring it again.
TAKES_ROBUST_SIGMA = frozenset({"threshold", "local-matched"})
# Base methods that take the waveforms as recorded plus each row's DC offset (``dc_v``) and
# fold it into their arithmetic, with the result they would give on the offset-free copy:
# no pass over the record to make that copy. The others get ``Signals.without_dc()``.
FOLDS_DC = frozenset({"threshold", "local-matched", "matched"})
# Base methods that read int16 ADC codes as they are (``Signals.volts_per_code``: a quarter of
# the bytes of the volts), converting to volts only the samples they use, with the result
# they give on the volts to rounding (``tests/unit/test_detection_codes.py``). They take the codes
# when they run without averaging or band-pass; the others, and those, get volts.
TAKES_CODES = frozenset({"threshold", "local-matched", "matched"})
# Base methods that read every sample of the codes they take and report each row's extremes
# (``extremes_out``), so that the clipping test of a record of ADC codes is done on those
# extremes instead of by a pass of its own (``inputs.as_signals(..., defer_clipping=True)``).
MEASURES_EXTREMES = frozenset({"local-matched"})


def _method_function(base: str) -> Callable[..., RawEchoes]:
    """The function implementing a base method (imported on use: keeps ``import`` light)."""
    if base == "threshold":
        from binsonar.detection.threshold import detect_threshold

        return detect_threshold
    if base == "energy":
        from binsonar.detection.energy import detect_energy

        return detect_energy
    if base == "matched":
        from binsonar.detection.matched import detect_matched

        return detect_matched
    if base == "whitened-matched":
        from binsonar.detection.whitened import detect_whitened_matched

        return detect_whitened_matched
    if base == "local-matched":
        from binsonar.detection.local import detect_local_matched

        return detect_local_matched
    if base == "dwt":
        from binsonar.detection.wavelet import detect_dwt

        return detect_dwt
    from binsonar.detection.cfar import detect_cfar

    return detect_cfar


def method_options(method: str) -> dict[str, Any]:
    """The options a method accepts, with their defaults.

    Besides these, every method accepts ``average``, ``bandpass_hz``, ``bandpass_order``,
    ``full_scale_v`` and ``on_clipped`` (see ``detect``).
    """
    base = _base(method)[0]
    parameters = inspect.signature(_method_function(base)).parameters
    return {
        name: p.default for name, p in parameters.items()
        if name not in _SUPPLIED and p.kind == inspect.Parameter.KEYWORD_ONLY
    }


def _base(method: str) -> tuple[str, bool, bool]:
    """(base method, average, band-pass) for a method name."""
    if method in BASE_METHODS:
        return method, False, False
    try:
        combination = seed_combination(method)
    except KeyError:
        raise RecordingError(f"unknown detection method {method!r}; choose one of: {', '.join(METHODS)}") from None
    return combination.base, combination.average, combination.bandpass


def _preprocess(
    signals: Signals,
    average: bool,
    bandpass_hz: tuple[float, float] | None,
    bandpass_order: int,
) -> Signals:
    """Average the pings and/or band-pass them (``binsonar.preprocess``).

    The quantisation noise floor (``Signals.noise_floor_v``) is kept as it is: exact for
    noise below one code step, whose rounding errors are the same in every ping (averaging
    does not reduce them); conservative (an over-estimate, by up to sqrt(n_pings) and by the
    band-pass's share of the band) when the noise dithers the ADC.
    """
    from binsonar.preprocess import average_pings, bandpass

    waveforms = signals.waveforms
    clipped = signals.clipped
    if average:
        waveforms = average_pings(waveforms)
        clipped = clipped.any(axis=0, keepdims=True)
    if bandpass_hz is not None:
        waveforms = bandpass(waveforms, signals.sample_rate_hz, bandpass_hz[0], bandpass_hz[1], bandpass_order)
    if waveforms is signals.waveforms:
        return signals
    return signals.with_waveforms(waveforms, clipped)


def _average_keeping_offsets(signals: Signals) -> Signals:
    """The pings' average (eq. 4.33) with its DC offset carried, not removed, for the methods
    that fold it (``FOLDS_DC``): mean_p(x_p - dc_p) = mean_p(x_p) - mean_p(dc_p) exactly, so the
    average of the waveforms as recorded plus the mean offset is the average of the
    offset-free pings, without a copy of each. One ping is its own average (no copy at all).
    """
    from binsonar.preprocess import average_pings

    if signals.n_pings == 1:
        return signals
    dc = None if signals.dc_v is None else signals.dc_v.mean(axis=0, keepdims=True)
    averaged = signals.with_waveforms(average_pings(signals.waveforms), signals.clipped.any(axis=0, keepdims=True))
    return replace(averaged, dc_v=dc)


@dataclass(frozen=True, eq=False)
class PreparedDetector:
    """A detection method set up once for a template, sample rate and record length.

    Everything that does not depend on the samples (the matched filter's template spectrum and
    analytic template, its bounds and thresholds) is computed once, so that ``run`` on each new
    ping costs only the detection itself: the way to run live. Build it with ``prepare``.

    Attributes
    ----------
    method : str
    base : str
        The base method ("matched" for "seed-4", ...).
    sample_rate_hz : float
    n_samples : int
        Record length (samples) the detector accepts.
    template : Template or None
    average : bool
        Average the pings of each ``run`` first.
    bandpass_hz : (low_hz, high_hz) or None
        Zero-phase band-pass first.
    bandpass_order : int
    options : tuple of (str, value)
        Method options.
    """

    method: str
    base: str
    sample_rate_hz: float
    n_samples: int
    template: Template | None
    average: bool
    bandpass_hz: tuple[float, float] | None
    bandpass_order: int
    options: tuple[tuple[str, Any], ...]
    _plan: Any = field(default=None, repr=False)

    def run(
        self,
        data: Recording | NDArray[np.floating],
        *,
        t0_s: float = 0.0,
        full_scale_v: float | None = None,
        on_clipped: str = "flag",
        adc_step_v: float | None = None,
        volts_per_code: float | None = None,
        adc_bits: int | None = None,
    ) -> DetectionResult:
        """Detect echoes in one recording or array (see ``detect`` for the arguments).

        Raises
        ------
        RecordingError
            Bad data, or a sample rate or record length other than the prepared ones.
        """
        start = time.perf_counter()
        signals = as_signals(data, None if isinstance(data, Recording) else self.sample_rate_hz, t0_s, full_scale_v,
                             adc_step_v, remove_dc=False, volts_per_code=volts_per_code, adc_bits=adc_bits,
                             defer_clipping=self.base in MEASURES_EXTREMES and on_clipped != "error")
        if not math.isclose(signals.sample_rate_hz, self.sample_rate_hz, rel_tol=1e-12) or signals.n_samples != self.n_samples:
            raise RecordingError(
                f"{signals.source}: {signals.n_samples} samples at {signals.sample_rate_hz:g} Hz, but the detector was "
                f"prepared for {self.n_samples} samples at {self.sample_rate_hz:g} Hz"
            )
        return self._detect(signals, on_clipped, start)

    def _detect(self, signals: Signals, on_clipped: str, start: float) -> DetectionResult:
        if on_clipped not in CLIPPED_POLICIES:
            raise RecordingError(f"on_clipped must be one of {CLIPPED_POLICIES}, got {on_clipped!r}")
        # A clipping test left pending (codes, ``MEASURES_EXTREMES``) is finished on the extremes
        # the method measures when it reads the codes as they are; otherwise here, by a pass.
        deferred = bool(signals.pending_full_scales_v) and self.base in MEASURES_EXTREMES and on_clipped != "error" \
            and not self.average and self.bandpass_hz is None and signals.volts_per_code is not None
        if not deferred:
            signals = signals.with_clipping_checked()
        if on_clipped == "error" and signals.clipped.any():
            ping, channel = (int(v) for v in np.argwhere(signals.clipped)[0])
            raise RecordingError(
                f"{signals.source}: ping {ping}, channel {channel} clipped ({int(signals.clipped.sum())} clipped "
                f"channel(s))"
            )
        if signals.volts_per_code is not None and not (
            self.base in TAKES_CODES and not self.average and self.bandpass_hz is None
        ):
            signals = signals.in_volts()
        if self.base in FOLDS_DC and self.bandpass_hz is None:
            if self.average:
                signals = _average_keeping_offsets(signals)
        else:
            signals = signals.without_dc()
            signals = _preprocess(signals, self.average, self.bandpass_hz, self.bandpass_order)
        n_pings, n_channels, n = signals.waveforms.shape
        rows = signals.waveforms.reshape(n_pings * n_channels, n)
        extremes = np.empty((rows.shape[0], 2)) if deferred else None
        raw = _run(self, rows, signals, extremes)
        # Python bools, one conversion (and the pending clipping test on the extremes, in Python).
        flags = signals.clipped.tolist() if extremes is None else signals.clipped_flags(extremes)
        drop = on_clipped == "drop"
        echoes = tuple(
            tuple(
                () if drop and flags[p][c] else tuple(
                    Echo(c, e[0], e[1], e[2], e[3], p, e[4], flags[p][c]) for e in raw[p * n_channels + c]
                )
                for c in range(n_channels)
            )
            for p in range(n_pings)
        )
        return DetectionResult(
            method=self.method,
            echoes=echoes,
            elapsed_s=time.perf_counter() - start,
            clipped=tuple(tuple(row) for row in flags),
            options=self._used_options,
        )

    @property
    def _used_options(self) -> tuple[tuple[str, Any], ...]:
        """``DetectionResult.options``: average, band and the method options, sorted, None left out."""
        used = {"average": self.average, "bandpass_hz": self.bandpass_hz, **dict(self.options)}
        return tuple(sorted((k, v) for k, v in used.items() if v is not None))


def _prepare(
    method: str,
    template: Template | None,
    sample_rate_hz: float,
    n_samples: int,
    average: bool | None,
    bandpass_hz: tuple[float, float] | str | None,
    bandpass_order: int,
    options: dict[str, Any],
) -> PreparedDetector:
    from binsonar.preprocess import template_band_hz

    base, seed_average, seed_bandpass = _base(method)
    # Options are checked against the method's signature only when there are some (reading a
    # signature costs tens of microseconds: much of a sub-millisecond detection).
    allowed = method_options(method) if options else {}
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise RecordingError(
            f"method {method!r}: unknown option(s) {', '.join(unknown)}; it accepts: {', '.join(sorted(allowed)) or 'none'}"
        )
    band_request = ("template" if seed_bandpass else None) if bandpass_hz is None else bandpass_hz
    band: tuple[float, float] | None = None
    if isinstance(band_request, str):
        if band_request != "template":
            raise RecordingError(f"bandpass_hz must be (low_hz, high_hz) or 'template', got {band_request!r}")
        if template is None:
            raise RecordingError("bandpass_hz='template' needs a template")
        band = template_band_hz(template.samples, sample_rate_hz)
    elif band_request is not None:
        try:
            low, high = (float(v) for v in band_request)
        except (TypeError, ValueError):
            raise RecordingError(f"bandpass_hz must be (low_hz, high_hz), got {band_request!r}") from None
        band = (low, high)
    plan = None
    if base != "threshold":
        if template is None:
            raise RecordingError(f"method {method!r} needs a template")
        if base == "matched":
            from binsonar.detection.matched import plan_matched

            # The decimated envelope by overlap-save (short cache-sized FFTs): no record-size
            # spectrum, nor the response's properties (CFAR's side lobes), to plan.
            plan = plan_matched(template, n_samples, sample_rate_hz, full=False, overlap_save=True)
        elif base in ("ca-cfar", "os-cfar"):
            from binsonar.detection.matched import plan_matched

            plan = plan_matched(template, n_samples, sample_rate_hz)
        elif base == "local-matched":
            from binsonar.detection.local import plan_local

            plan = plan_local(template, n_samples, sample_rate_hz)
    return PreparedDetector(
        method=method,
        base=base,
        sample_rate_hz=float(sample_rate_hz),
        n_samples=int(n_samples),
        template=template,
        average=seed_average if average is None else bool(average),
        bandpass_hz=band,
        bandpass_order=int(bandpass_order),
        options=tuple(sorted(options.items())),
        _plan=plan,
    )


def prepare(
    method: str,
    *,
    sample_rate_hz: float,
    n_samples: int,
    template: Template | NDArray[np.floating] | None = None,
    average: bool | None = None,
    bandpass_hz: tuple[float, float] | str | None = None,
    bandpass_order: int = 4,
    **options: Any,
) -> PreparedDetector:
    """Set a method up once for records of ``n_samples`` at ``sample_rate_hz``.

    ``prepare(...).run(data)`` gives what ``detect(data, ...)`` gives, without redoing the
    per-template work for every ping. Arguments as for ``detect``.

    Raises
    ------
    RecordingError
        Unknown method or option, a missing or unusable template.
    """
    if not (isinstance(n_samples, (int, np.integer)) and n_samples >= 2):
        raise RecordingError(f"n_samples must be an integer >= 2, got {n_samples!r}")
    shell = Signals(np.broadcast_to(np.zeros(1), (1, 1, int(n_samples))), float(sample_rate_hz), 0.0,
                    np.zeros((1, 1), dtype=bool), None, "prepare")
    resolved = None if template is None else resolve_template(template, shell, method)
    return _prepare(method, resolved, float(sample_rate_hz), int(n_samples), average, bandpass_hz, bandpass_order,
                    options)


def detect(
    data: Recording | NDArray[np.floating],
    method: str,
    *,
    sample_rate_hz: float | None = None,
    t0_s: float = 0.0,
    template: Template | NDArray[np.floating] | None = None,
    average: bool | None = None,
    bandpass_hz: tuple[float, float] | str | None = None,
    bandpass_order: int = 4,
    full_scale_v: float | None = None,
    on_clipped: str = "flag",
    adc_step_v: float | None = None,
    volts_per_code: float | None = None,
    adc_bits: int | None = None,
    **options: Any,
) -> DetectionResult:
    """Detect echoes and estimate their times of flight.

    Parameters
    ----------
    data : Recording or array_like
        Volts; arrays of shape (n_samples,), (3, n_samples) or (n_pings, 3, n_samples), or
        integer ADC codes with ``volts_per_code`` (a recording read with
        ``read_recording(..., keep_codes=True)`` carries its codes). Each
        ping-channel's median (its DC offset) is removed first (``inputs.remove_median``);
        the methods in ``FOLDS_DC`` (threshold, matched, local-matched) instead fold it into their
        arithmetic, with the same result (to rounding) and no copy of the record.
    method : str
        One of ``METHODS``: "threshold", "energy", "matched", "whitened-matched",
        "local-matched", "dwt", "ca-cfar", "os-cfar", or the seed's "seed-1" ... "seed-9"
        (see ``binsonar.detection.seed``).
    sample_rate_hz : float, optional
        Required for arrays.
    t0_s : float
        Time of sample 0 after the transmit trigger (s), arrays only.
    template : Template or array_like, optional
        The matched-filter template (the transmitted pulse, a calibration echo or a user array;
        an array is at the data's sample rate with t0_s = 0). Default: the recording's. Its
        ``t0_s`` defines the reference instant a TOF refers to.
    average : bool, optional
        Average all pings first (eq. 4.33; the result has one ping). Set by the seed methods.
    bandpass_hz : (low_hz, high_hz) or "template", optional
        Zero-phase band-pass first ("template": the template's -20 dB band). Set by the seed
        methods (to "template").
    bandpass_order : int
        Butterworth order of the band-pass.
    full_scale_v : float, optional
        ADC full scale (V): channels reaching it are flagged as clipped (recordings stored as
        ADC codes are checked against their code full scale anyway).
    on_clipped : {"flag", "drop", "error"}
        Clipped channels: keep their echoes marked ``clipped`` ("flag"), drop them, or raise.
    adc_step_v : float, optional
        ADC code step q (V) of the data (default: a recording's ``volts_per_code``, none for
        arrays). Every noise estimate is floored at the quantisation noise q / sqrt(12):
        noise below one code step quantises quiet stretches to constant samples, which would
        otherwise look noise-free (zero TOF std, SNRs of 150 dB, spurious CFAR echoes).
    volts_per_code : float, optional
        Arrays only: ``data`` are integer ADC codes (int16 range) of this step (V). The methods
        in ``TAKES_CODES`` (threshold, local-matched, matched) read the codes as they are (a quarter of
        the bytes of volts); the others get volts. The echoes are those of the volts
        ``data * volts_per_code``, to rounding.
    adc_bits : int, optional
        Arrays of codes only: the ADC's resolution; channels with a code at +/-(2^(bits - 1) - 1)
        are flagged as clipped (a recording's own ``adc_bits`` is used for its codes).
    **options
        Method options; ``method_options(method)`` lists them with their defaults.

    Returns
    -------
    DetectionResult
        ``elapsed_s`` covers validation, set-up, pre-processing and detection (not file
        reading; the first call also pays for importing scipy).

    Raises
    ------
    RecordingError
        Bad data, template or option (one-line message naming the field and value).
    """
    return detect_with_plans(data, method, None, sample_rate_hz=sample_rate_hz, t0_s=t0_s, template=template,
                             average=average, bandpass_hz=bandpass_hz, bandpass_order=bandpass_order,
                             full_scale_v=full_scale_v, on_clipped=on_clipped, adc_step_v=adc_step_v,
                             volts_per_code=volts_per_code, adc_bits=adc_bits, **options)


class PlanStore(Protocol):
    """Where ``detect_with_plans`` keeps prepared detectors (``detector.Detector``'s cache)."""

    def prepared(self, key: Hashable, build: Callable[[], PreparedDetector]) -> PreparedDetector:
        """The detector stored under ``key``, built (and stored) by ``build()`` if absent."""
        ...


def _template_key(template: Template | NDArray[np.floating] | None) -> Hashable:
    """What identifies a template input: its samples' bytes and, for a ``Template``, its sample
    rate, time origin and kind (an array is taken at the record's rate, part of the plan key)."""
    if template is None:
        return None
    if isinstance(template, Template):
        return (template.samples.tobytes(), template.sample_rate_hz, template.t0_s, template.kind)
    array = np.asarray(template, dtype=float)
    return ("array", array.shape, array.tobytes())


def detect_with_plans(
    data: Recording | NDArray[np.floating],
    method: str,
    plans: PlanStore | None,
    *,
    sample_rate_hz: float | None = None,
    t0_s: float = 0.0,
    template: Template | NDArray[np.floating] | None = None,
    average: bool | None = None,
    bandpass_hz: tuple[float, float] | str | None = None,
    bandpass_order: int = 4,
    full_scale_v: float | None = None,
    on_clipped: str = "flag",
    adc_step_v: float | None = None,
    volts_per_code: float | None = None,
    adc_bits: int | None = None,
    **options: Any,
) -> DetectionResult:
    """``detect``, taking the prepared detector (the method's plan for the template, sample
    rate, record length and options) from ``plans`` when it holds one, and storing the one it
    builds there otherwise; with ``plans`` None, ``detect`` itself (planned on every call).

    The key is the method, the template input (its bytes, or the recording's template when
    none is given), the sample rate, the record length, ``average``, ``bandpass_hz``,
    ``bandpass_order`` and the options; options that cannot be hashed (a list, an array) make
    the call plan afresh, uncached.
    """
    start = time.perf_counter()
    base, _, seed_bandpass = _base(method)
    if on_clipped not in CLIPPED_POLICIES:
        raise RecordingError(f"on_clipped must be one of {CLIPPED_POLICIES}, got {on_clipped!r}")
    signals = as_signals(data, sample_rate_hz, t0_s, full_scale_v, adc_step_v, remove_dc=False,
                         volts_per_code=volts_per_code, adc_bits=adc_bits,
                         defer_clipping=base in MEASURES_EXTREMES and on_clipped != "error")
    band_from_template = isinstance(bandpass_hz, str) or (bandpass_hz is None and seed_bandpass)

    def build() -> PreparedDetector:
        resolved: Template | None = None
        if base != "threshold" or band_from_template or template is not None or signals.template is not None:
            resolved = resolve_template(template, signals, method)  # raises if there is none
        return _prepare(method, resolved, signals.sample_rate_hz, signals.n_samples, average, bandpass_hz,
                        bandpass_order, options)

    prepared = None
    if plans is not None:
        key = (method, _template_key(signals.template if template is None else template), signals.sample_rate_hz,
               signals.n_samples, average, bandpass_hz, bandpass_order, tuple(sorted(options.items())))
        try:
            hash(key)
        except TypeError:  # an unhashable option value: plan afresh
            pass
        else:
            prepared = plans.prepared(key, build)
    if prepared is None:
        prepared = build()
    return prepared._detect(signals, on_clipped, start)


def _run(
    prepared: PreparedDetector, rows: NDArray[np.float64], signals: Signals, extremes: NDArray[np.float64] | None = None
) -> RawEchoes:
    """Call the base method with what it needs, on chunks of rows (bounded memory: every
    method treats rows independently); with ``extremes`` (shape (n_rows, 2), a method in
    ``MEASURES_EXTREMES``), the method writes each row's largest and smallest value there."""
    base, function = prepared.base, _method_function(prepared.base)
    options = dict(prepared.options)
    options["noise_floor_v"] = signals.noise_floor_v
    template, plan = prepared.template, prepared._plan
    fs, t0, where = signals.sample_rate_hz, signals.t0_s, signals.source
    if signals.volts_per_code is not None:  # codes: only the methods in ``TAKES_CODES`` get here
        options["volts_per_code"] = signals.volts_per_code
    dc = None if signals.dc_v is None else signals.dc_v.reshape(-1)  # per row, as ``rows``
    robust = None if signals.noise_sigma_v is None else signals.noise_sigma_v.reshape(-1)
    if base in TAKES_ROBUST_SIGMA and robust is not None and options.get("noise_window_s") is None:
        # Per chunk below: the rows' robust noise estimate, already measured with their offsets.
        options["robust_sigma_v"] = None
    else:
        robust = None
    if base == "threshold":
        call = lambda chunk, dc_v: function(chunk, sample_rate_hz=fs, t0_s=t0, template=template, where=where,  # noqa: E731
                                            dc_v=dc_v, **options)
    elif base in ("energy", "whitened-matched", "dwt"):
        call = lambda chunk, dc_v: function(chunk, template, sample_rate_hz=fs, t0_s=t0, where=where, **options)  # noqa: E731
    elif base == "matched":
        call = lambda chunk, dc_v: function(chunk, plan, t0_s=t0, dc_v=dc_v, **options)  # noqa: E731
    elif base == "local-matched":
        call = lambda chunk, dc_v: function(chunk, plan, t0_s=t0, where=where, dc_v=dc_v, **options)  # noqa: E731
        if extremes is not None:
            options["extremes_out"] = None  # per chunk below
    else:
        kind = "ca" if base == "ca-cfar" else "os"
        call = lambda chunk, dc_v: function(chunk, plan, t0_s=t0, kind=kind, **options)  # noqa: E731
    if dc is not None and base not in FOLDS_DC:
        raise RecordingError(f"{where}: internal: method {base!r} was given waveforms with their DC offset in them")
    if rows.shape[0] <= ROW_CHUNK:  # one chunk (a ping or a few): the arrays as they are, no views
        if robust is not None:
            options["robust_sigma_v"] = robust
        if extremes is not None:
            options["extremes_out"] = extremes
        return call(rows, dc)
    out: RawEchoes = []
    for start in range(0, rows.shape[0], ROW_CHUNK):  # chunks of rows, vectorised inside
        if robust is not None:
            options["robust_sigma_v"] = robust[start:start + ROW_CHUNK]
        if extremes is not None:
            options["extremes_out"] = extremes[start:start + ROW_CHUNK]
        out.extend(call(rows[start:start + ROW_CHUNK], None if dc is None else dc[start:start + ROW_CHUNK]))
    return out
