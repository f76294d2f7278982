"""Records as int16 ADC codes: the detectors that read codes (threshold, local-matched, matched) give the
echoes they give on the volts ``codes * volts_per_code``, and so does every other method (it
converts); the code statistics (median, MAD, extremes by counting) equal numpy's; clipping is
judged at the ADC's rails on the codes; bad code input is refused with a clear message.
"""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.detection import METHODS, detect
from binsonar.detection.code_kernels import code_statistics, median_and_mad, row_extremes
from binsonar.detection.kernel_types import CODE_SCALE, record
from binsonar.detection.inputs import as_signals, robust_offsets
from binsonar.detection.noise import MAD_TO_SIGMA, robust_subsample, row_median
from binsonar.recording import Recording, RecordingError, read_recording, write_recording
from support.detection_signals import FS, echo_rows, noise_sigma_for, pulse_template

N = 20_000
BITS = 12
Q = 2.5 / 2 ** (BITS - 1)  # volts per code of a +/-2.5 V 12-bit ADC


def _codes(seed: int = 3, offset_codes: int = 9) -> np.ndarray:
    """(1, 3, N) int16 codes: three echoes (20 dB, 30 dB, 25 dB) in white noise, a DC offset."""
    rng = np.random.default_rng(seed)
    clean = echo_rows(np.array([300e-6, 402.37e-6, 655.5e-6]), N, np.array([0.3, 1.0, 0.6]))
    volts = clean + noise_sigma_for(20.0, 0.3) * rng.standard_normal(clean.shape)
    return (np.rint(volts / Q) + offset_codes).astype(np.int16)[np.newaxis]


def _values(result) -> np.ndarray:
    return np.array([(e.ping, e.channel, e.tof_s, e.amplitude, e.snr_db, e.score, e.tof_std_s)
                     for ping in result.echoes for ch in ping for e in ch])


def _assert_same_echoes(a, b, rtol: float) -> None:
    va, vb = _values(a), _values(b)
    assert va.shape == vb.shape and va.size
    np.testing.assert_allclose(vb, va, rtol=rtol, atol=0.0)
    assert a.clipped == b.clipped


@pytest.mark.parametrize("k", [1, 2, 7, 256, 4096])
def test_median_and_mad_by_counting_equal_numpy_partitions(k):
    rng = np.random.default_rng(k)
    sample = np.concatenate([rng.integers(-2048, 2048, (3, k)), rng.integers(-3, 4, (2, k)),
                             np.full((1, k), -17)]).astype(np.int16)
    median = np.empty(6, dtype=np.int64)
    mad = np.empty(6, dtype=np.int64)
    median_and_mad(sample, median, mad)
    expected = row_median(sample.astype(np.int64))
    assert median.tolist() == expected.tolist()
    assert mad.tolist() == row_median(np.abs(sample.astype(np.int64) - expected[:, np.newaxis])).tolist()
    largest = np.empty(6, dtype=np.int64)
    smallest = np.empty(6, dtype=np.int64)
    row_extremes(sample, largest, smallest)
    assert largest.tolist() == sample.max(axis=1).tolist() and smallest.tolist() == sample.min(axis=1).tolist()


def test_code_statistics_equal_the_volts_robust_offsets_and_clipping():
    codes = _codes()
    codes[0, 1, 5000] = 2047  # the 12-bit ADC's positive rail on channel 1
    dc, sigma = robust_offsets(codes * Q)
    signals = as_signals(Recording(None, FS, codes=codes, volts_per_code=Q, adc_bits=BITS), remove_dc=False)
    assert signals.volts_per_code == Q and signals.waveforms.dtype == np.int16
    # The median code scaled is the volts' median exactly (scaling keeps the order); the MAD
    # is taken on codes, then scaled: equal to the volts' to the rounding of their differences.
    assert np.array_equal(signals.dc_v, dc)
    np.testing.assert_allclose(signals.noise_sigma_v, sigma, rtol=1e-12)
    assert signals.clipped.tolist() == [[False, True, False]]
    # Short rows: the whole row is the subsample.
    short = codes[..., :1000]
    out = np.empty((3, 3))
    scale = record(CODE_SCALE, period=1000, length=1000, segments=1, volts_per_code=Q, mad_to_sigma=MAD_TO_SIGMA)
    code_statistics(np.ascontiguousarray(short[0]), scale, np.empty(0), out)
    assert np.array_equal(out[:, 0], row_median(short[0].astype(float)) * Q)
    assert not out[:, 2].any()  # no full scale given: no clipping test
    assert robust_subsample(short[0]).shape == (3, 1000)


@pytest.mark.parametrize("code, clipped", [(2047, True), (-2047, True), (-2048, True), (2046, False), (-2046, False)])
def test_codes_at_the_adc_rails_are_clipped(code, clipped):
    codes = _codes()
    codes[0, 2, 12_345] = code
    for data in (Recording(None, FS, template=pulse_template(), codes=codes, volts_per_code=Q, adc_bits=BITS),):
        for method in ("threshold", "local-matched", "matched"):
            result = detect(data, method)
            assert result.clipped == ((False, False, clipped),)
            assert all(e.clipped == clipped for e in result.echoes[0][2])
    from_array = detect(codes[0], "threshold", sample_rate_hz=FS, volts_per_code=Q, adc_bits=BITS)
    assert from_array.clipped == ((False, False, clipped),)
    # Without the ADC's resolution, an array is judged against full_scale_v only.
    assert detect(codes[0], "threshold", sample_rate_hz=FS, volts_per_code=Q).clipped == ((False, False, False),)
    if clipped:
        with pytest.raises(RecordingError, match="channel 2 clipped"):
            detect(codes[0], "local-matched", sample_rate_hz=FS, volts_per_code=Q, adc_bits=BITS,
                   template=pulse_template(), on_clipped="error")


@pytest.mark.parametrize("method", METHODS)
def test_codes_give_the_echoes_of_their_volts(method):
    codes = _codes()
    volts = codes * Q
    template = pulse_template()
    reference = detect(volts, method, sample_rate_hz=FS, template=template, adc_step_v=Q)
    from_array = detect(codes, method, sample_rate_hz=FS, template=template, volts_per_code=Q)
    from_recording = detect(Recording(None, FS, template=template, codes=codes, volts_per_code=Q, adc_bits=BITS),
                            method)
    # Threshold and matched: the same products code * step, the same operations on them:
    # identical values. Local matched: the block correlations and direct sums are scaled once
    # instead of per sample (relative rounding of ~1e-16 per operation over ~200-term sums):
    # 1e-12. The other methods convert the codes to the same volts: identical.
    rtol = 1e-12 if method == "local-matched" else 0.0
    _assert_same_echoes(reference, from_array, rtol)
    _assert_same_echoes(reference, from_recording, rtol)


def test_codes_with_noise_and_search_windows():
    codes = _codes(seed=5)
    window = {"noise_window_s": (10e-6, 250e-6), "search_window_s": (350e-6, 900e-6)}
    for method in ("threshold", "local-matched"):
        options = dict(window) if method == "threshold" else {"search_window_s": window["search_window_s"]}
        reference = detect(codes * Q, method, sample_rate_hz=FS, template=pulse_template(), adc_step_v=Q, **options)
        coded = detect(codes, method, sample_rate_hz=FS, template=pulse_template(), volts_per_code=Q, **options)
        _assert_same_echoes(reference, coded, 1e-12)
        # Channel 0's only echo (300 us) is outside the search window; channel 1's (402 us) is found
        # (the threshold's TOF is its uncalibrated crossing, on the pulse's rising edge: within
        # 2 us, the pulse's half-length at the 6-sigma level; the local filter's within 20 ns).
        tolerance = 2e-6 if method == "threshold" else 20e-9
        assert not coded.echoes[0][0] and coded.echoes[0][1][0].tof_s == pytest.approx(402.37e-6, abs=tolerance)


def test_recording_keeps_its_codes_when_asked(tmp_path):
    codes = _codes()
    recording = Recording(codes * Q, FS, template=pulse_template(), volts_per_code=Q, adc_bits=BITS)
    path = write_recording(tmp_path / "codes.h5", recording, codes=codes)
    plain = read_recording(path)
    kept = read_recording(path, keep_codes=True)
    assert plain.codes is None and kept.codes.dtype == np.int16 and np.array_equal(kept.codes, codes)
    assert np.array_equal(kept.waveforms, plain.waveforms) and not kept.codes.flags.writeable
    for method in ("threshold", "local-matched", "seed-2"):
        _assert_same_echoes(detect(plain, method), detect(kept, method), 1e-12)
    # A file of volts has no codes to keep.
    volts_path = write_recording(tmp_path / "volts.h5", recording)
    assert read_recording(volts_path, keep_codes=True).codes is None


def test_bad_code_input_is_refused():
    codes = _codes()
    with pytest.raises(RecordingError, match="integer ADC codes"):
        detect(codes * Q, "threshold", sample_rate_hz=FS, volts_per_code=Q)
    with pytest.raises(RecordingError, match="volts_per_code must be"):
        detect(codes, "threshold", sample_rate_hz=FS, volts_per_code=-1.0)
    with pytest.raises(RecordingError, match="adc_bits=12 needs volts_per_code"):
        detect(codes * Q, "threshold", sample_rate_hz=FS, adc_bits=12)
    with pytest.raises(RecordingError, match="adc_bits must be"):
        detect(codes, "threshold", sample_rate_hz=FS, volts_per_code=Q, adc_bits=20)
    with pytest.raises(RecordingError, match="must fit int16"):
        detect(codes.astype(np.int32) * 100, "threshold", sample_rate_hz=FS, volts_per_code=Q)
    with pytest.raises(RecordingError, match="sample_rate_hz is required"):
        detect(codes, "threshold", volts_per_code=Q)
    with pytest.raises(RecordingError, match="codes need volts_per_code"):
        Recording(None, FS, codes=codes)
    with pytest.raises(RecordingError, match="integer ADC codes"):
        Recording(None, FS, codes=codes * Q, volts_per_code=Q)
    with pytest.raises(RecordingError, match="codes shape"):
        Recording(np.zeros((1, 3, 10)), FS, codes=codes, volts_per_code=Q)
    with pytest.raises(RecordingError, match="not codes \\* volts_per_code"):
        Recording(codes * Q * 1.5, FS, codes=codes, volts_per_code=Q)
    # Int32 codes within the int16 range are taken (as int16).
    result = detect(codes.astype(np.int32), "threshold", sample_rate_hz=FS, volts_per_code=Q)
    _assert_same_echoes(detect(codes, "threshold", sample_rate_hz=FS, volts_per_code=Q), result, 0.0)


@pytest.mark.parametrize("where", [0, 12_345, N - 1])
@pytest.mark.parametrize("window", [None, (250e-6, 450e-6)])
def test_local_matched_judges_clipping_on_the_extremes_its_coarse_pass_reads(where, window):
    # local-matched on codes leaves the rails test to its own pass over the codes (one read of
    # the record, not two): the first and last samples (outside its groups of blocks) and,
    # with a search window, samples it does not search must still be judged, as the separate
    # pass judges them (``as_signals`` without deferral).
    from binsonar.detection import Detector, prepare

    codes = _codes()
    codes[0, 1, where] = -2047  # the negative rail on channel 1
    codes[0, 2, where] = 1000  # below the rails, at a lower full scale given by the caller
    recording = Recording(None, FS, template=pulse_template(), codes=codes, volts_per_code=Q, adc_bits=BITS)
    options = {} if window is None else {"search_window_s": window}
    separate = as_signals(recording, full_scale_v=1000 * Q, remove_dc=False).clipped
    assert separate.tolist() == [[False, True, True]]
    prepared = prepare("local-matched", sample_rate_hz=FS, n_samples=N, template=pulse_template(), **options)
    for full_scale, expected in ((None, ((False, True, False),)), (1000 * Q, ((False, True, True),))):
        results = [detect(recording, "local-matched", full_scale_v=full_scale, **options),
                   prepared.run(recording, full_scale_v=full_scale),
                   Detector().detect(recording, "local-matched", full_scale_v=full_scale, **options)]
        for result in results:
            assert result.clipped == expected
            assert all(e.clipped == expected[0][c] for c in range(3) for e in result.echoes[0][c])
    dropped = detect(recording, "local-matched", on_clipped="drop", **options)
    assert dropped.echoes[0][1] == () and dropped.echoes[0][0]
    with pytest.raises(RecordingError, match="channel 1 clipped"):
        prepared.run(recording, on_clipped="error")
    # Averaged (seed-9's variant through volts): the separate pass, same flags.
    assert detect(recording, "local-matched", average=True, **options).clipped == ((False, True, False),)
