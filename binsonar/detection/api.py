"""``detect``: one entry point for every detection method, on recordings or arrays.

``detect(data, method, ...)`` is ``prepare(method, ...).run(data, ...)``: the method is looked up
in the registry (``registry.lookup``), planned once for the template and record length
(``PreparedDetector``), and run on the rows (ping-channels) of the data. What the rows look like
when they reach the method (int16 codes or volts, DC offsets folded or removed, the clipping
test finished on the method's own extremes or by a pass) follows from the method's attributes
(``methods.DetectionMethod``). ``Detector`` (``detector``) keeps prepared detectors across calls
through the ``PlanStore`` protocol.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Hashable, Protocol

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.conditioning import average_and_bandpass, average_keeping_offsets
from binsonar.detection.echo import DetectionResult, Echo
from binsonar.detection.inputs import Signals, as_signals, resolve_template
from binsonar.detection.methods import DetectionMethod, RawEchoes, RecordContext, RowBatch
from binsonar.detection.registry import RegisteredMethod, lookup
from binsonar.detection.settings import DetectionSettings
from binsonar.recording import Recording, RecordingError, Template

__all__ = (
    "CLIPPED_POLICIES",
    "PlanStore",
    "PreparedDetector",
    "detect",
    "detect_with_settings",
    "method_options",
    "prepare",
)

CLIPPED_POLICIES: tuple[str, ...] = ("flag", "drop", "error")
ROW_CHUNK = 24
"""Rows (ping-channels) a method processes at once: bounds the spectra held at once (24 x
250,000 samples: about 50 MB of complex spectrum) while keeping the FFTs batched."""


def method_options(method: str) -> dict[str, Any]:
    """The options a method accepts, with their defaults.

    Besides these, every method accepts ``average``, ``bandpass_hz``, ``bandpass_order``,
    ``full_scale_v`` and ``on_clipped`` (see ``detect``).

    Raises
    ------
    RecordingError
        An unknown method.
    """
    return lookup(method).method.defaults()


def _check_policy(on_clipped: str) -> None:
    if on_clipped not in CLIPPED_POLICIES:
        raise RecordingError(f"on_clipped must be one of {CLIPPED_POLICIES}, got {on_clipped!r}")


@dataclass(frozen=True, eq=False)
class PreparedDetector:
    """A detection method set up once for a template, sample rate and record length.

    Everything that does not depend on the samples (the matched filter's template spectrum and
    analytic template, its bounds and thresholds) is computed once, so that ``run`` on each new
    ping costs only the detection itself: the way to run live. Build it with ``prepare``.

    Attributes
    ----------
    method : str
        The name it was prepared under ("seed-4", "matched", ...).
    implementation : DetectionMethod
        The base method that detects (``methods``).
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
        Method options, sorted by name.
    plan : object
        The method's plan (``DetectionMethod.plan``).
    """

    method: str
    implementation: DetectionMethod
    sample_rate_hz: float
    n_samples: int
    template: Template | None
    average: bool
    bandpass_hz: tuple[float, float] | None
    bandpass_order: int
    options: tuple[tuple[str, Any], ...]
    plan: Any = field(default=None, repr=False)

    @property
    def base(self) -> str:
        """The base method's name ("matched" for "seed-4", ...)."""
        return self.implementation.name

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
                             defer_clipping=self.implementation.measures_extremes and on_clipped != "error")
        if not math.isclose(signals.sample_rate_hz, self.sample_rate_hz, rel_tol=1e-12) or signals.n_samples != self.n_samples:
            raise RecordingError(
                f"{signals.source}: {signals.n_samples} samples at {signals.sample_rate_hz:g} Hz, but the detector was "
                f"prepared for {self.n_samples} samples at {self.sample_rate_hz:g} Hz"
            )
        return self.run_signals(signals, on_clipped, start)

    def run_signals(self, signals: Signals, on_clipped: str, start: float) -> DetectionResult:
        """Detect echoes in validated signals (``inputs.as_signals(..., remove_dc=False)``);
        ``start``: the ``time.perf_counter()`` the result's ``elapsed_s`` counts from."""
        _check_policy(on_clipped)
        implementation = self.implementation
        direct = not self.average and self.bandpass_hz is None  # the rows reach the method as recorded
        # A clipping test left pending (codes, a method measuring extremes) is finished on the
        # extremes the method measures when it reads the codes as they are; otherwise here.
        deferred = bool(signals.pending_full_scales_v) and implementation.measures_extremes and on_clipped != "error" \
            and direct and signals.volts_per_code is not None
        if not deferred:
            signals = signals.with_clipping_checked()
        if on_clipped == "error" and signals.clipped.any():
            ping, channel = (int(v) for v in np.argwhere(signals.clipped)[0])
            raise RecordingError(
                f"{signals.source}: ping {ping}, channel {channel} clipped ({int(signals.clipped.sum())} clipped "
                f"channel(s))"
            )
        if signals.volts_per_code is not None and not (implementation.reads_codes and direct):
            signals = signals.in_volts()
        if implementation.folds_dc and self.bandpass_hz is None:
            if self.average:
                signals = average_keeping_offsets(signals)
        else:
            signals = average_and_bandpass(signals.without_dc(), self.average, self.bandpass_hz, self.bandpass_order)
        n_pings, n_channels, n = signals.waveforms.shape
        extremes = np.empty((n_pings * n_channels, 2)) if deferred else None
        raw = self._raw_echoes(signals, extremes)
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
            options=self.used_options,
        )

    def _raw_echoes(self, signals: Signals, extremes: NDArray[np.float64] | None) -> RawEchoes:
        """The method's echoes of every row, ``ROW_CHUNK`` rows at a time (every method treats
        rows independently); with ``extremes`` (shape (n_rows, 2)) the method writes each row's
        largest and smallest sample there."""
        n_pings, n_channels, n = signals.waveforms.shape
        batch = RowBatch(
            samples=signals.waveforms.reshape(n_pings * n_channels, n),
            volts_per_code=signals.volts_per_code,
            dc_v=None if signals.dc_v is None else signals.dc_v.reshape(-1),
            robust_sigma_v=None if signals.noise_sigma_v is None else signals.noise_sigma_v.reshape(-1),
            extremes_out=extremes,
        )
        if batch.dc_v is not None and not self.implementation.folds_dc:
            raise RecordingError(f"{signals.source}: internal: method {self.base!r} was given waveforms with their DC "
                                 "offset in them")
        record = RecordContext(signals.sample_rate_hz, signals.t0_s, signals.noise_floor_v, signals.source)
        options = dict(self.options)
        n_rows = batch.samples.shape[0]
        if n_rows <= ROW_CHUNK:  # one chunk (a ping or a few): the arrays as they are, no views
            return self.implementation.run(batch, record, self.plan, options)
        out: RawEchoes = []
        for first in range(0, n_rows, ROW_CHUNK):
            out.extend(self.implementation.run(batch.rows(first, first + ROW_CHUNK), record, self.plan, options))
        return out

    @property
    def used_options(self) -> tuple[tuple[str, Any], ...]:
        """``DetectionResult.options``: average, band and the method options, sorted, None left out."""
        used = {"average": self.average, "bandpass_hz": self.bandpass_hz, **dict(self.options)}
        return tuple(sorted((k, v) for k, v in used.items() if v is not None))


def _band(
    registered: RegisteredMethod, template: Template | None, sample_rate_hz: float,
    bandpass_hz: tuple[float, float] | str | None,
) -> tuple[float, float] | None:
    """The band-pass a prepared detector applies: the caller's, or the method's own choice."""
    request = ("template" if registered.bandpass_template else None) if bandpass_hz is None else bandpass_hz
    if request is None:
        return None
    if isinstance(request, str):
        if request != "template":
            raise RecordingError(f"bandpass_hz must be (low_hz, high_hz) or 'template', got {request!r}")
        if template is None:
            raise RecordingError("bandpass_hz='template' needs a template")
        from binsonar.preprocess import template_band_hz

        return template_band_hz(template.samples, sample_rate_hz)
    try:
        low, high = (float(v) for v in request)
    except (TypeError, ValueError):
        raise RecordingError(f"bandpass_hz must be (low_hz, high_hz), got {request!r}") from None
    return (low, high)


def _prepare(
    registered: RegisteredMethod, template: Template | None, sample_rate_hz: float, n_samples: int,
    settings: DetectionSettings,
) -> PreparedDetector:
    """The prepared detector of a registered method for a resolved template (or None)."""
    implementation = registered.method
    if settings.options:
        implementation.check_options(settings.option_dict, registered.name)
    band = _band(registered, template, sample_rate_hz, settings.bandpass_hz)
    if implementation.needs_template and template is None:
        raise RecordingError(f"method {registered.name!r} needs a template")
    return PreparedDetector(
        method=registered.name,
        implementation=implementation,
        sample_rate_hz=float(sample_rate_hz),
        n_samples=int(n_samples),
        template=template,
        average=registered.average if settings.average is None else bool(settings.average),
        bandpass_hz=band,
        bandpass_order=int(settings.bandpass_order),
        options=tuple(sorted(settings.options)),
        plan=implementation.plan(template, int(n_samples), float(sample_rate_hz)),
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
    registered = lookup(method)
    if not (isinstance(n_samples, (int, np.integer)) and n_samples >= 2):
        raise RecordingError(f"n_samples must be an integer >= 2, got {n_samples!r}")
    shell = Signals(np.broadcast_to(np.zeros(1), (1, 1, int(n_samples))), float(sample_rate_hz), 0.0,
                    np.zeros((1, 1), dtype=bool), None, "prepare")
    resolved = None if template is None else resolve_template(template, shell, method)
    settings = DetectionSettings(average=average, bandpass_hz=bandpass_hz, bandpass_order=bandpass_order,
                                 options=tuple(options.items()))
    return _prepare(registered, resolved, float(sample_rate_hz), int(n_samples), settings)


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
        ``read_recording(..., keep_codes=True)`` carries its codes). Each ping-channel's
        median (its DC offset) is removed first (``inputs.row_offsets``, ``Signals.without_dc``); the methods that
        fold it (``DetectionMethod.folds_dc``: threshold, matched, local-matched) fold it into
        their arithmetic instead, with the same result (to rounding) and no copy of the record.
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
        that read codes (``DetectionMethod.reads_codes``: threshold, local-matched, matched)
        take them as they are (a quarter of the bytes of volts); the others get volts. The
        echoes are those of the volts ``data * volts_per_code``, to rounding.
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
    settings = DetectionSettings(
        sample_rate_hz=sample_rate_hz, t0_s=t0_s, template=template, average=average, bandpass_hz=bandpass_hz,
        bandpass_order=bandpass_order, full_scale_v=full_scale_v, on_clipped=on_clipped, adc_step_v=adc_step_v,
        volts_per_code=volts_per_code, adc_bits=adc_bits, options=tuple(options.items()),
    )
    return detect_with_settings(data, method, settings)


class PlanStore(Protocol):
    """Where ``detect_with_settings`` keeps prepared detectors (``detector.Detector``'s cache)."""

    def prepared(self, key: Hashable, build: Callable[[], PreparedDetector]) -> PreparedDetector:
        """The detector stored under ``key``, built (and stored) by ``build()`` if absent."""
        ...


def detect_with_settings(
    data: Recording | NDArray[np.floating],
    method: str,
    settings: DetectionSettings,
    plans: PlanStore | None = None,
) -> DetectionResult:
    """``detect`` with its arguments in one bundle, taking the prepared detector from ``plans``
    when it holds one (and storing the one it builds there otherwise); with ``plans`` None, the
    method is planned for this call only.

    The key (``DetectionSettings.plan_key``) is the method, the template input (its bytes, or
    the recording's template when none is given), the sample rate, the record length,
    ``average``, ``bandpass_hz``, ``bandpass_order`` and the options; options that cannot be
    hashed (a list, an array) make the call plan afresh, uncached.
    """
    start = time.perf_counter()
    registered = lookup(method)
    implementation = registered.method
    _check_policy(settings.on_clipped)
    signals = as_signals(data, settings.sample_rate_hz, settings.t0_s, settings.full_scale_v, settings.adc_step_v,
                         remove_dc=False, volts_per_code=settings.volts_per_code, adc_bits=settings.adc_bits,
                         defer_clipping=implementation.measures_extremes and settings.on_clipped != "error")
    template = settings.template
    band_from_template = isinstance(settings.bandpass_hz, str) or (
        settings.bandpass_hz is None and registered.bandpass_template)

    def build() -> PreparedDetector:
        resolved: Template | None = None
        if implementation.needs_template or band_from_template or template is not None or signals.template is not None:
            resolved = resolve_template(template, signals, method)  # raises if there is none
        return _prepare(registered, resolved, signals.sample_rate_hz, signals.n_samples, settings)

    key = None if plans is None else settings.plan_key(
        method, signals.template if template is None else template, signals.sample_rate_hz, signals.n_samples)
    prepared = build() if key is None else plans.prepared(key, build)  # type: ignore[union-attr]
    return prepared.run_signals(signals, settings.on_clipped, start)
