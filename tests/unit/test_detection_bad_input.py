"""Bad input to detection: clear RecordingError messages, and clipped channels flagged."""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.detection import METHODS, detect, method_options
from binsonar.recording import Recording, RecordingError, Template, read_recording, write_recording
from support.detection_signals import FS, echo_rows, pulse_template

N = 4096


def _record(n_pings: int = 1) -> np.ndarray:
    rng = np.random.default_rng(0)
    clean = echo_rows(np.array([60e-6, 61e-6, 62e-6]), N)
    return clean[np.newaxis] + 0.05 * rng.standard_normal((n_pings, 3, N))


@pytest.mark.parametrize("value, where", [(np.nan, "NaN"), (np.inf, "inf"), (-np.inf, "-inf")])
def test_non_finite_samples_are_rejected_with_their_position(value, where):
    data = _record()
    data[0, 2, 17] = value
    with pytest.raises(RecordingError, match=r"NaN or infinite.*ping 0, channel 2, sample 17"):
        detect(data, "matched", sample_rate_hz=FS, template=pulse_template())


@pytest.mark.parametrize("shape", [(2, N), (4, 2, N), (1, 1, 1, N), (3, 1), (0,)])
def test_wrong_shapes_are_rejected(shape):
    with pytest.raises(RecordingError, match="shape|empty"):
        detect(np.zeros(shape), "threshold", sample_rate_hz=FS)


def test_one_dimensional_arrays_are_one_channel():
    result = detect(_record()[0, 1], "matched", sample_rate_hz=FS, template=pulse_template())
    assert len(result.echoes) == 1 and len(result.echoes[0]) == 1
    assert abs(result.echoes[0][0][0].tof_s - 61e-6) < 50e-9


def test_missing_or_bad_sample_rate():
    with pytest.raises(RecordingError, match="sample_rate_hz is required"):
        detect(_record(), "matched", template=pulse_template())
    with pytest.raises(RecordingError, match="sample_rate_hz must be"):
        detect(_record(), "matched", sample_rate_hz=-1.0, template=pulse_template())


def test_template_longer_than_the_record():
    with pytest.raises(RecordingError, match=r"template \(401 samples\) is longer than the record \(300 samples\)"):
        detect(np.zeros((3, 300)), "matched", sample_rate_hz=FS, template=np.ones(401))


def test_missing_template_unknown_method_and_options():
    with pytest.raises(RecordingError, match="needs a template"):
        detect(_record(), "matched", sample_rate_hz=FS)
    with pytest.raises(RecordingError, match="unknown detection method 'fft'"):
        detect(_record(), "fft", sample_rate_hz=FS)
    with pytest.raises(RecordingError, match="unknown option.*levl_v"):
        detect(_record(), "threshold", sample_rate_hz=FS, levl_v=0.1)
    for bad in (0.0, 1.0, -1e-3):
        with pytest.raises(RecordingError, match="pfa must be in"):
            detect(_record(), "matched", sample_rate_hz=FS, template=pulse_template(), pfa=bad)
    with pytest.raises(RecordingError, match="noise_window_s"):
        detect(_record(), "threshold", sample_rate_hz=FS, noise_window_s=(0.0, 1.0))
    with pytest.raises(RecordingError, match="template has no energy"):
        detect(_record(), "matched", sample_rate_hz=FS, template=np.zeros(10))


def test_every_method_runs_and_lists_its_options():
    data = _record(2)
    for method in METHODS:
        options = method_options(method)
        assert isinstance(options, dict)
        result = detect(data, method, sample_rate_hz=FS, template=pulse_template())
        assert result.method == method and result.elapsed_s > 0
        averaged = method in ("seed-2", "seed-4", "seed-6", "seed-8", "seed-9")
        assert result.n_pings == (1 if averaged else 2)
        # The centre channel's echo (61 us, 2E/N0 = 38 dB) is found by every method.
        assert any(abs(e.tof_s - 61e-6) < 3e-6 for e in result.echoes[0][1]), method


def test_clipped_channels_are_flagged_dropped_or_refused():
    data = _record(2)
    clipped = np.zeros((2, 3), dtype=bool)
    clipped[1, 0] = True
    recording = Recording(data, FS, 0.0, clipped=clipped, template=pulse_template())
    flagged = detect(recording, "matched")
    assert flagged.clipped == ((False, False, False), (True, False, False))
    assert flagged.echoes[1][0][0].clipped and not flagged.echoes[0][0][0].clipped
    dropped = detect(recording, "matched", on_clipped="drop")
    assert dropped.echoes[1][0] == () and dropped.echoes[0][0]
    with pytest.raises(RecordingError, match="ping 1, channel 0 clipped"):
        detect(recording, "matched", on_clipped="error")
    with pytest.raises(RecordingError, match="on_clipped"):
        detect(recording, "matched", on_clipped="ignore")
    # Arrays: the full scale given flags the channels reaching it.
    saturated = np.clip(data * 30, -1.0, 1.0)
    result = detect(saturated, "matched", sample_rate_hz=FS, template=pulse_template(), full_scale_v=1.0)
    assert all(all(row) for row in result.clipped)
    # Averaging: a clipped ping makes the averaged channel clipped.
    assert detect(recording, "seed-4").clipped == ((True, False, False),)


def test_clipping_of_int16_codes_is_detected_from_the_adc_full_scale(tmp_path):
    data = _record()
    volts_per_code = 1.0 / 2048
    codes = np.clip(np.round(data * 40 / volts_per_code), -2047, 2047).astype(np.int16)
    recording = Recording(codes * volts_per_code, FS, 0.0, template=pulse_template(), volts_per_code=volts_per_code,
                          adc_bits=12)
    path = write_recording(tmp_path / "codes.h5", recording, codes=codes)
    result = detect(read_recording(path), "matched")
    assert result.clipped == ((True, True, True),)


def test_empty_and_truncated_files(tmp_path):
    empty = tmp_path / "empty.h5"
    empty.write_bytes(b"")
    with pytest.raises(RecordingError, match="empty"):
        read_recording(empty)
    good = write_recording(tmp_path / "good.h5", Recording(_record(), FS, 0.0, template=pulse_template()))
    truncated = tmp_path / "truncated.h5"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(RecordingError, match="truncated|cannot read"):
        detect(read_recording(truncated), "matched")


def test_template_at_another_sample_rate_is_resampled():
    # The template sampled at 10 MHz (t0 kept): band-limited resampling to 20 MHz must leave
    # the TOF within 1 ns of the native template's (the pulse's band, below ~1.2 MHz, is far
    # under both Nyquist frequencies, so the resampling is exact up to the truncated tails).
    t = (np.arange(101) - 50) / 10e6
    slow = Template(np.exp(-13.8 * t ** 2 / 5e-6 ** 2) * np.cos(2 * np.pi * 500e3 * t), 10e6, -50 / 10e6)
    data = _record()
    native = detect(data, "matched", sample_rate_hz=FS, template=pulse_template())
    resampled = detect(data, "matched", sample_rate_hz=FS, template=slow)
    for a, b in zip(native.echoes[0], resampled.echoes[0]):
        assert abs(a[0].tof_s - b[0].tof_s) < 1e-9


def test_prepared_detector_matches_detect_and_checks_the_record():
    from binsonar.detection import prepare

    data = _record(3)
    for method in ("matched", "local-matched", "threshold", "seed-8", "os-cfar"):
        prepared = prepare(method, sample_rate_hz=FS, n_samples=N, template=pulse_template())
        once = detect(data, method, sample_rate_hz=FS, template=pulse_template())
        again = prepared.run(data)
        assert [[[(e.tof_s, e.score) for e in ch] for ch in ping] for ping in again.echoes] == \
            [[[(e.tof_s, e.score) for e in ch] for ch in ping] for ping in once.echoes]
    with pytest.raises(RecordingError, match="prepared for 4096 samples"):
        prepare("matched", sample_rate_hz=FS, n_samples=N, template=pulse_template()).run(data[..., :4000])
    with pytest.raises(RecordingError, match="needs a template"):
        prepare("matched", sample_rate_hz=FS, n_samples=N)
    with pytest.raises(RecordingError, match="n_samples"):
        prepare("matched", sample_rate_hz=FS, n_samples=1, template=pulse_template())
