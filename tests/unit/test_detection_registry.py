"""The detector registry: every method registered once, its options declared and checked, one
signature (``detect`` is ``prepare(...).run(...)``), and each declared attribute true of the
method's behaviour (``binsonar.detection.methods``, ``registry``)."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from binsonar.detection import METHODS, Detector, DetectionSettings, detect, method_options, prepare
from binsonar.detection.methods import BASE_METHOD_OBJECTS, RecordContext, RowBatch
from binsonar.detection.registry import BASE_METHODS, REGISTRY, lookup
from binsonar.detection.seed import SEED_COMBINATIONS
from binsonar.recording import RecordingError
from support.detection_signals import FS, echo_rows, noise_sigma_for, pulse_template

N = 8192
# Inputs a detection call supplies itself (the rows, their plan, timing and measurements):
# every other keyword-only parameter of a method's function is a user option.
SUPPLIED = {"rows", "plan", "template", "sample_rate_hz", "t0_s", "where", "kind", "noise_floor_v", "dc_v",
            "robust_sigma_v", "volts_per_code", "extremes_out"}


def _functions() -> dict:
    from binsonar.detection.cfar import detect_cfar
    from binsonar.detection.energy import detect_energy
    from binsonar.detection.local import detect_local_matched
    from binsonar.detection.matched import detect_matched
    from binsonar.detection.threshold import detect_threshold
    from binsonar.detection.wavelet import detect_dwt
    from binsonar.detection.whitened import detect_whitened_matched

    return {"threshold": detect_threshold, "energy": detect_energy, "matched": detect_matched,
            "whitened-matched": detect_whitened_matched, "local-matched": detect_local_matched, "dwt": detect_dwt,
            "ca-cfar": detect_cfar, "os-cfar": detect_cfar}


def _record(n_pings: int = 1, seed: int = 3, offsets: tuple = (0.0, 0.0, 0.0)) -> np.ndarray:
    # Two echoes per channel 60 us apart (the second at half amplitude), 30 dB for the first.
    rng = np.random.default_rng(seed)
    sigma = noise_sigma_for(30.0)
    delays = np.array([100e-6, 110e-6, 120e-6])
    clean = echo_rows(delays, N) + echo_rows(delays + 60e-6, N, 0.5)
    return np.stack([clean + rng.standard_normal((3, N)) * sigma + np.asarray(offsets)[:, None]
                     for _ in range(n_pings)])


def test_every_name_is_registered_once_base_methods_first():
    assert METHODS == tuple(REGISTRY) == BASE_METHODS + tuple(c.name for c in SEED_COMBINATIONS)
    assert len(set(METHODS)) == len(METHODS)
    assert BASE_METHODS == ("threshold", "energy", "matched", "whitened-matched", "local-matched", "dwt", "ca-cfar",
                            "os-cfar")
    for name in METHODS:
        assert lookup(name).name == name
    for combination in SEED_COMBINATIONS:  # a seed name is its base method with its pre-processing
        registered = lookup(combination.name)
        assert registered.method.name == combination.base
        assert (registered.average, registered.bandpass_template) == (combination.average, combination.bandpass)
    with pytest.raises(RecordingError, match="unknown detection method 'fft'; choose one of: threshold, energy"):
        lookup("fft")


@pytest.mark.parametrize("method", BASE_METHOD_OBJECTS, ids=lambda m: m.name)
def test_declared_options_are_the_functions_keyword_options(method):
    # The registry's option table and the implementing function cannot drift apart: the same
    # names with the same defaults.
    parameters = inspect.signature(_functions()[method.name]).parameters
    expected = {name: p.default for name, p in parameters.items()
                if p.kind == inspect.Parameter.KEYWORD_ONLY and name not in SUPPLIED}
    assert method.defaults() == expected
    assert method_options(method.name) == expected


@pytest.mark.parametrize("method", BASE_METHOD_OBJECTS, ids=lambda m: m.name)
def test_options_are_checked_at_prepare(method):
    for option in method.options:  # every default passes its own check
        option.check(option.name, option.default)
    for option in method.options:  # and a value of the wrong kind is refused, naming method and option
        with pytest.raises(RecordingError, match=rf"method '{method.name}': {option.name}"):
            prepare(method.name, sample_rate_hz=FS, n_samples=N, template=pulse_template(),
                    **{option.name: object()})
    with pytest.raises(RecordingError, match=rf"method '{method.name}': unknown option\(s\) nope"):
        prepare(method.name, sample_rate_hz=FS, n_samples=N, template=pulse_template(), nope=1)


@pytest.mark.parametrize("name, option, value, message", [
    ("matched", "pfa", 1.0, "pfa must be in"),
    ("local-matched", "candidates", 17, r"candidates must be an integer in \[1, 16\]"),
    ("ca-cfar", "n_reference", 7, "n_reference must be an even integer"),
    ("ca-cfar", "guard_s", 1e300, r"guard_s must be >= 0 and at most the record's length"),
    ("energy", "tof", "middle", "tof must be one of"),
    ("threshold", "search_window_s", (1.0,), r"search_window_s must be \(start_s, stop_s\)"),
    ("seed-3", "single", 2, "single must be true or false"),
])
def test_out_of_range_values_are_refused_with_their_name(name, option, value, message):
    with pytest.raises(RecordingError, match=message):
        detect(_record(), name, sample_rate_hz=FS, template=pulse_template(), **{option: value})


@pytest.mark.parametrize("name", METHODS)
def test_detect_is_prepare_then_run(name):
    # One signature: detect, a prepared detector's run and a Detector give the same echoes.
    data = _record(2)
    options = dict(sample_rate_hz=FS, template=pulse_template())
    once = detect(data, name, **options)
    prepared = prepare(name, sample_rate_hz=FS, n_samples=N, template=pulse_template()).run(data)
    cached = Detector().detect(data, name, **options)
    # Compared by repr: bit for bit, NaN (a method without a TOF std) equal to NaN.
    assert repr(once.echoes) == repr(prepared.echoes) == repr(cached.echoes)
    assert once.options == prepared.options == cached.options
    assert once.method == prepared.method == name


def test_settings_split_detect_arguments_from_method_options():
    settings = DetectionSettings.from_arguments({"sample_rate_hz": FS, "average": True, "pfa": 1e-4,
                                                 "search_window_s": (0.0, 1e-3)})
    assert settings.sample_rate_hz == FS and settings.average is True
    assert settings.option_dict == {"pfa": 1e-4, "search_window_s": (0.0, 1e-3)}
    key = settings.plan_key("matched", pulse_template(), FS, N)
    assert key is not None and key == settings.plan_key("matched", pulse_template(), FS, N)
    assert DetectionSettings(options=(("search_window_s", [0.0, 1.0]),)).plan_key("matched", None, FS, N) is None


def _run(method, batch: RowBatch, options: dict | None = None) -> list:
    plan = method.plan(pulse_template(), N, FS)
    return method.run(batch, RecordContext(FS, 0.0, 0.0, "test"), plan, options or {})


@pytest.mark.parametrize("method", [m for m in BASE_METHOD_OBJECTS if m.folds_dc], ids=lambda m: m.name)
def test_methods_that_fold_dc_give_the_offset_free_echoes(method):
    # Offsets of volts against 1 V echoes: a method that ignored them would cross at sample 0
    # (threshold) or see them in its noise estimate and correlations. Folded, the arithmetic
    # differs from the copy's by rounding only (z(x) - dc sum(taps) against z(x - dc)): TOFs to
    # 1e-15 s and values to 1e-9 relative (tests/unit/test_detection_dc_fold.py's tolerances).
    offsets = np.array([2.0, -1.5, 0.3])
    rows = _record(offsets=tuple(offsets))[0]
    folded = _run(method, RowBatch(rows, None, offsets, None, None))
    copied = _run(method, RowBatch(rows - offsets[:, None], None, None, None, None))
    assert [len(e) for e in folded] == [len(e) for e in copied] == [1, 1, 1]
    for a, b in zip(folded, copied):
        assert abs(a[0][0] - b[0][0]) < 1e-15
        np.testing.assert_allclose(a[0][1:], b[0][1:], rtol=1e-9, atol=0.0)


@pytest.mark.parametrize("method", [m for m in BASE_METHOD_OBJECTS if m.reads_codes], ids=lambda m: m.name)
def test_methods_that_read_codes_give_the_echoes_of_the_volts(method):
    # int16 codes of a 12-bit ADC step: each sample the method uses is code * step, the value
    # the volts hold, so the echoes agree to the rounding of sums in another order (float32 block
    # sums for the local filter's coarse pass pick the same candidates): 1e-12 s and 1e-9.
    step = 2.5 / 2048
    codes = np.rint(_record()[0] / step).astype(np.int16)
    from_codes = _run(method, RowBatch(codes, step, None, None, None))
    from_volts = _run(method, RowBatch(codes * step, None, None, None, None))
    assert [len(e) for e in from_codes] == [len(e) for e in from_volts] == [1, 1, 1]
    for a, b in zip(from_codes, from_volts):
        assert abs(a[0][0] - b[0][0]) < 1e-12
        np.testing.assert_allclose(a[0][1:], b[0][1:], rtol=1e-9, atol=0.0)


@pytest.mark.parametrize("method", [m for m in BASE_METHOD_OBJECTS if m.measures_extremes], ids=lambda m: m.name)
def test_methods_that_measure_extremes_report_every_rows_extremes(method):
    step = 2.5 / 2048
    codes = np.rint(_record()[0] / step).astype(np.int16)
    codes[1, 17] = 2047  # at the rail, far from the echoes
    extremes = np.full((3, 2), np.nan)
    _run(method, RowBatch(codes, step, None, None, extremes))
    assert np.array_equal(extremes, np.stack([codes.max(axis=1), codes.min(axis=1)], axis=1).astype(float))


@pytest.mark.parametrize("method", BASE_METHOD_OBJECTS, ids=lambda m: m.name)
def test_multi_echo_methods_report_both_echoes_and_the_others_one(method):
    # Two echoes 60 us apart, the second 6 dB down (24 dB): a multi-echo method reports both on
    # every channel, the others (strongest or first) exactly one.
    rows = _record()[0]
    echoes = _run(method, RowBatch(rows, None, None, None, None))
    delays = np.array([100e-6, 110e-6, 120e-6])
    for c, found in enumerate(echoes):
        near = [any(abs(e[0] - t) < 3e-6 for e in found) for t in (delays[c], delays[c] + 60e-6)]
        if method.multi_echo:
            assert all(near), (method.name, c, found)
        else:
            assert len(found) == 1 and near[0], (method.name, c, found)
