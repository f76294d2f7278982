"""The detection methods: one object per method, saying how it plans, how it runs, what it takes.

Every method implements the same two steps:

- ``plan(template, n_samples, sample_rate_hz)``: what does not depend on the samples (the
  matched filter's template spectrum, the local filter's tone table; for the methods that
  plan per record, the template itself);
- ``run(batch, record, plan, options)``: the echoes of a chunk of rows (``RowBatch``), as
  (tof_s, amplitude, snr_db, score, tof_std_s) per row.

and declares, as attributes, what the rows may look like when they reach it (``api`` prepares
them accordingly, reading these attributes, never the method's name):

- ``needs_template``: it cannot run without one (all but the threshold detector, which uses a
  template when there is one, for its measuring window and its calibration);
- ``reads_codes``: it takes int16 ADC codes as they are (``RowBatch.volts_per_code``), with
  the echoes of the volts to rounding; the others get volts;
- ``folds_dc``: it takes each row's DC offset (``RowBatch.dc_v``) and folds it into its own
  arithmetic, with the echoes of the offset-free rows; the others get the offsets removed;
- ``measures_extremes``: reading every sample anyway, it reports each row's largest and
  smallest value (``RowBatch.extremes_out``), on which the clipping test of ADC codes is
  finished instead of by a pass of its own;
- ``multi_echo``: it reports every echo it finds per row, not only the strongest or first;
- ``options``: its ``Option`` tuple (names, defaults, checks).

The implementations live in the modules named in each class and are imported when a method
plans or runs, so that importing this module loads numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar, Mapping, NamedTuple

import numpy as np
from numpy.typing import NDArray

from binsonar.detection.options import (
    Option,
    even_integer_from,
    finite,
    flag,
    integer_in,
    non_negative,
    one_of,
    optional,
    positive,
    probability,
    text,
    time_window,
)
from binsonar.recording import RecordingError, Template

RawEchoes = list[list[tuple[float, float, float, float, float]]]
"""Per row, its echoes as (tof_s, amplitude, snr_db, score, tof_std_s)."""


class RowBatch(NamedTuple):
    """A chunk of rows (ping-channels) and what was measured about them, for one ``run``.

    Attributes
    ----------
    samples : ndarray, shape (n_rows, n_samples)
        float64 volts, or int16 ADC codes when ``volts_per_code`` is set (methods with
        ``reads_codes`` only).
    volts_per_code : float or None
        Code step (V) of ``samples`` when they are codes.
    dc_v : ndarray, shape (n_rows,), or None
        DC offset of each row still in ``samples`` (methods with ``folds_dc`` only); None when
        removed or zero.
    robust_sigma_v : ndarray, shape (n_rows,), or None
        Each row's robust noise standard deviation (V), measured with the offsets
        (``inputs.Signals.noise_sigma_v``); None when not measured.
    extremes_out : ndarray, shape (n_rows, 2), or None
        To be written with each row's largest and smallest sample (units of ``samples``) by a
        method with ``measures_extremes``; None when not wanted.
    """

    samples: NDArray
    volts_per_code: float | None
    dc_v: NDArray[np.float64] | None
    robust_sigma_v: NDArray[np.float64] | None
    extremes_out: NDArray[np.float64] | None

    def rows(self, start: int, stop: int) -> "RowBatch":
        """The rows ``start:stop`` of this batch (views)."""

        def part(array: NDArray | None) -> NDArray | None:
            return None if array is None else array[start:stop]

        return RowBatch(self.samples[start:stop], self.volts_per_code, part(self.dc_v), part(self.robust_sigma_v),
                        part(self.extremes_out))


class RecordContext(NamedTuple):
    """What every row of a record shares.

    Attributes
    ----------
    sample_rate_hz : float
    t0_s : float
        Time of sample 0 after the transmit trigger (s).
    noise_floor_v : float
        Least noise standard deviation (V): the ADC's quantisation noise (0 when unknown).
    source : str
        The file the rows came from, or "array" (for messages).
    """

    sample_rate_hz: float
    t0_s: float
    noise_floor_v: float
    source: str


@dataclass(frozen=True)
class DetectionMethod:
    """A detection method (module notes): class attributes describe it, ``plan`` and ``run`` do it."""

    name: ClassVar[str]
    summary: ClassVar[str]
    options: ClassVar[tuple[Option, ...]]
    needs_template: ClassVar[bool] = True
    reads_codes: ClassVar[bool] = False
    folds_dc: ClassVar[bool] = False
    measures_extremes: ClassVar[bool] = False
    multi_echo: ClassVar[bool] = False

    def defaults(self) -> dict[str, Any]:
        """The options with their defaults."""
        return {option.name: option.default for option in self.options}

    def check_options(self, options: Mapping[str, Any], label: str) -> None:
        """Refuse unknown option names and values the method's checks refuse.

        Raises
        ------
        RecordingError
            Naming ``label`` (the method as the user called it), the option and the value.
        """
        known = {option.name: option for option in self.options}
        unknown = sorted(set(options) - set(known))
        if unknown:
            raise RecordingError(f"method {label!r}: unknown option(s) {', '.join(unknown)}; it accepts: "
                                 f"{', '.join(sorted(known)) or 'none'}")
        for name, value in options.items():
            known[name].check(f"method {label!r}: {name}", value)

    def plan(self, template: Template | None, n_samples: int, sample_rate_hz: float) -> Any:
        """What ``run`` needs that depends on the template and record length only.

        The default: the template itself (methods that plan per record).
        """
        return template

    def run(self, batch: RowBatch, record: RecordContext, plan: Any, options: Mapping[str, Any]) -> RawEchoes:
        """The echoes of each row of ``batch`` (``options``: those the user gave, checked)."""
        raise NotImplementedError


@dataclass(frozen=True)
class Threshold(DetectionMethod):
    """First crossing of a level (``threshold.detect_threshold``)."""

    name = "threshold"
    summary = "first crossing of a level (absolute, or times the noise), timed by interpolation"
    needs_template = False
    reads_codes = True
    folds_dc = True
    options = (
        Option("level_v", None, optional(positive), "absolute level (V); None: level_sigma times the noise"),
        Option("level_sigma", 6.0, positive, "level over the noise standard deviation"),
        Option("noise_window_s", None, optional(time_window), "noise-only window (s); None: robust estimate"),
        Option("offset_s", 0.0, finite, "calibrated offset subtracted from the crossing time (s)"),
        Option("calibrate_amplitude_v", None, optional(positive),
               "offset of the template scaled to this peak (V) instead of offset_s; needs level_v"),
        Option("search_window_s", None, optional(time_window), "only crossings in this window (s)"),
    )

    def run(self, batch: RowBatch, record: RecordContext, plan: Any, options: Mapping[str, Any]) -> RawEchoes:
        from binsonar.detection.threshold import detect_threshold

        return detect_threshold(batch.samples, sample_rate_hz=record.sample_rate_hz, t0_s=record.t0_s, template=plan,
                                where=record.source, noise_floor_v=record.noise_floor_v, dc_v=batch.dc_v,
                                robust_sigma_v=batch.robust_sigma_v, volts_per_code=batch.volts_per_code, **options)


@dataclass(frozen=True)
class Energy(DetectionMethod):
    """Band energy detector (``energy.detect_energy``)."""

    name = "energy"
    summary = "energy in sub-bands of the template's band, integrated over the pulse"
    multi_echo = True
    options = (
        Option("n_bands", 4, integer_in(1, 64), "sub-bands of the template's band"),
        Option("band_db", -20.0, finite, "band edges: where the template's power is this far below its peak (dB)"),
        Option("integration_s", None, optional(positive), "integration time (s); None: 4 RMS durations"),
        Option("pfa", 1e-3, probability, "design false-alarm probability per record"),
        Option("tof", "peak", one_of("peak", "crossing"), "TOF at the statistic's peak or its threshold crossing"),
    )

    def run(self, batch: RowBatch, record: RecordContext, plan: Any, options: Mapping[str, Any]) -> RawEchoes:
        from binsonar.detection.energy import detect_energy

        return detect_energy(batch.samples, plan, sample_rate_hz=record.sample_rate_hz, t0_s=record.t0_s,
                             where=record.source, noise_floor_v=record.noise_floor_v, **options)


@dataclass(frozen=True)
class Matched(DetectionMethod):
    """Matched filter, strongest echo per row (``matched.detect_matched``, overlap-save plan)."""

    name = "matched"
    summary = "matched filter's envelope maximum, refined to a sub-sample lag"
    reads_codes = True
    folds_dc = True
    options = (
        Option("pfa", 1e-3, probability, "design false-alarm probability over the searched lags"),
        Option("search_window_s", None, optional(time_window), "only TOFs in this window (s)"),
        Option("single", True, flag, "FFTs in float32 (the TOF refinement stays float64)"),
    )

    def plan(self, template: Template | None, n_samples: int, sample_rate_hz: float) -> Any:
        from binsonar.detection.matched import plan_matched

        # The decimated envelope by overlap-save: no record-size spectrum to plan.
        return plan_matched(template, n_samples, sample_rate_hz, full=False, overlap_save=True)

    def run(self, batch: RowBatch, record: RecordContext, plan: Any, options: Mapping[str, Any]) -> RawEchoes:
        from binsonar.detection.matched import detect_matched

        return detect_matched(batch.samples, plan, t0_s=record.t0_s, noise_floor_v=record.noise_floor_v,
                              dc_v=batch.dc_v, volts_per_code=batch.volts_per_code, **options)


@dataclass(frozen=True)
class WhitenedMatched(DetectionMethod):
    """Matched filter after whitening by each row's noise spectrum (``whitened.detect_whitened_matched``)."""

    name = "whitened-matched"
    summary = "matched filter whitened by each row's own noise spectrum (Welch)"
    options = (
        Option("pfa", 1e-3, probability, "design false-alarm probability per record"),
        Option("nperseg", 1024, integer_in(16), "Welch segment length (samples)"),
        Option("noise_window_s", None, optional(time_window), "noise-only window for the spectrum (s)"),
    )

    def run(self, batch: RowBatch, record: RecordContext, plan: Any, options: Mapping[str, Any]) -> RawEchoes:
        from binsonar.detection.whitened import detect_whitened_matched

        return detect_whitened_matched(batch.samples, plan, sample_rate_hz=record.sample_rate_hz, t0_s=record.t0_s,
                                       where=record.source, noise_floor_v=record.noise_floor_v, **options)


@dataclass(frozen=True)
class LocalMatched(DetectionMethod):
    """Local matched filter around coarse peaks (``local.detect_local_matched``)."""

    name = "local-matched"
    summary = "matched filter around the strongest coarse windows only (the seed's method 9)"
    reads_codes = True
    folds_dc = True
    measures_extremes = True
    options = (
        Option("pfa", 1e-3, probability, "design false-alarm probability over the searched lags"),
        Option("search_window_s", None, optional(time_window), "only TOFs in this window (s)"),
        Option("noise_window_s", None, optional(time_window), "noise-only window (s); None: robust estimate"),
        Option("candidates", 3, integer_in(1, 16), "coarse windows searched by the local filter"),
    )

    def plan(self, template: Template | None, n_samples: int, sample_rate_hz: float) -> Any:
        from binsonar.detection.local import plan_local

        return plan_local(template, n_samples, sample_rate_hz)

    def run(self, batch: RowBatch, record: RecordContext, plan: Any, options: Mapping[str, Any]) -> RawEchoes:
        from binsonar.detection.local import detect_local_matched

        return detect_local_matched(batch.samples, plan, t0_s=record.t0_s, where=record.source,
                                    noise_floor_v=record.noise_floor_v, dc_v=batch.dc_v,
                                    robust_sigma_v=batch.robust_sigma_v, volts_per_code=batch.volts_per_code,
                                    extremes_out=batch.extremes_out, **options)


@dataclass(frozen=True)
class Wavelet(DetectionMethod):
    """Discrete wavelet transform detector (``wavelet.detect_dwt``)."""

    name = "dwt"
    summary = "energy of the wavelet detail levels in the template's band"
    multi_echo = True
    options = (
        Option("wavelet", "sym8", text, "an orthogonal discrete PyWavelets wavelet"),
        Option("levels", None, optional(integer_in(1, 20)), "decomposition depth; None: below the template's band"),
        Option("pfa", 1e-3, probability, "false-alarm probability per record"),
    )

    def run(self, batch: RowBatch, record: RecordContext, plan: Any, options: Mapping[str, Any]) -> RawEchoes:
        from binsonar.detection.wavelet import detect_dwt

        return detect_dwt(batch.samples, plan, sample_rate_hz=record.sample_rate_hz, t0_s=record.t0_s,
                          where=record.source, noise_floor_v=record.noise_floor_v, **options)


_CFAR_OPTIONS = (
    Option("pfa", 1e-6, probability, "design false-alarm probability per cell"),
    Option("guard_s", 3e-6, non_negative, "guard interval each side of the cell under test (s)"),
    Option("n_reference", 24, even_integer_from(2), "reference cells (half each side)"),
    Option("order", None, optional(integer_in(1)), "OS-CFAR rank; None: round(3 n_reference / 4)"),
    Option("min_separation_s", None, optional(non_negative), "least time between echoes (s); None: main lobe FWHM"),
    Option("sidelobe_margin_db", 6.0, finite, "margin over the predicted side lobes (dB)"),
    Option("max_echoes", 64, integer_in(1), "most echoes per row (the strongest)"),
    Option("censor", True, flag, "CA-CFAR: censor first-pass detections from the reference cells"),
    Option("search_window_s", None, optional(time_window), "only TOFs in this window (s)"),
)


@dataclass(frozen=True)
class Cfar(DetectionMethod):
    """Constant false-alarm rate detection on the matched filter's envelope (``cfar.detect_cfar``)."""

    options = _CFAR_OPTIONS
    multi_echo = True
    kind: ClassVar[str]

    def plan(self, template: Template | None, n_samples: int, sample_rate_hz: float) -> Any:
        from binsonar.detection.matched import plan_matched

        return plan_matched(template, n_samples, sample_rate_hz)  # CFAR reads the record-size spectrum

    def run(self, batch: RowBatch, record: RecordContext, plan: Any, options: Mapping[str, Any]) -> RawEchoes:
        from binsonar.detection.cfar import detect_cfar

        return detect_cfar(batch.samples, plan, t0_s=record.t0_s, kind=self.kind, noise_floor_v=record.noise_floor_v,
                           **options)


@dataclass(frozen=True)
class CellAveragingCfar(Cfar):
    """CA-CFAR: the reference level is the mean of the reference cells."""

    name = "ca-cfar"
    summary = "every echo above a cell-averaging CFAR threshold on the matched filter's envelope"
    kind = "ca"


@dataclass(frozen=True)
class OrderStatisticCfar(Cfar):
    """OS-CFAR: the reference level is a rank of the reference cells."""

    name = "os-cfar"
    summary = "every echo above an order-statistic CFAR threshold on the matched filter's envelope"
    kind = "os"


BASE_METHOD_OBJECTS: tuple[DetectionMethod, ...] = (
    Threshold(),
    Energy(),
    Matched(),
    WhitenedMatched(),
    LocalMatched(),
    Wavelet(),
    CellAveragingCfar(),
    OrderStatisticCfar(),
)
"""The base methods, in the order ``METHODS`` lists them."""

BASE_BY_NAME: Mapping[str, DetectionMethod] = MappingProxyType({m.name: m for m in BASE_METHOD_OBJECTS})
