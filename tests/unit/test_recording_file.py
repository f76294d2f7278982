"""Recording files: lazy reading ping range by ping range, codes without volts, the 1.0 layout,
the streaming writer and its determinism."""

from __future__ import annotations

import dataclasses
import tracemalloc

import numpy as np
import pytest

from binsonar.recording import (
    FORMAT_VERSION,
    Recording,
    RecordingError,
    open_recording,
    read_recording,
    write_recording,
    write_recording_chunks,
)
from support.hostile_recordings import VOLTS_PER_CODE, clean_codes, write_raw_recording

FS = 20e6


def _codes_recording(n_pings: int = 5, n: int = 4096) -> Recording:
    codes = clean_codes(n_pings, n, seed=4)
    pose = np.column_stack([np.arange(n_pings), np.zeros((n_pings, 5))]).astype(float)
    clipped = np.zeros((n_pings, 3), dtype=bool)
    clipped[min(3, n_pings - 1), 2] = True
    return Recording(None, FS, 12e-6, codes=codes, volts_per_code=VOLTS_PER_CODE, adc_bits=12, pose=pose,
                     clipped=clipped, sound_speed_m_s=1482.0, created_by="test")


def test_chunks_join_to_the_whole_recording(tmp_path):
    recording = _codes_recording()
    path = write_recording(tmp_path / "ping.h5", recording)
    whole = read_recording(path, keep_codes=True)
    with open_recording(path) as source:
        per_ping = 3 * 4096 * 2
        chunks = list(source.chunks(max_bytes=2 * per_ping))
        assert [start for start, _ in chunks] == [0, 2, 4] and [c.n_pings for _, c in chunks] == [2, 2, 1]
        np.testing.assert_array_equal(np.concatenate([c.codes for _, c in chunks]), whole.codes)
        np.testing.assert_array_equal(np.concatenate([c.pose for _, c in chunks]), whole.pose)
        np.testing.assert_array_equal(np.concatenate([c.clipped for _, c in chunks]), whole.clipped)
        middle = source.read(1, 4)
        np.testing.assert_array_equal(middle.waveforms, whole.codes[1:4] * VOLTS_PER_CODE)
        with pytest.raises(RecordingError, match="outside"):
            source.read(4, 9)
    np.testing.assert_array_equal(whole.codes, recording.codes)
    assert whole.t0_s == 12e-6 and whole.sound_speed_m_s == 1482.0 and whole.clipped[3, 2]


def test_keeping_codes_makes_no_volts_until_asked(tmp_path):
    recording = _codes_recording(n_pings=8, n=65536)
    path = write_recording(tmp_path / "ping.h5", recording)
    codes_bytes = 8 * 3 * 65536 * 2
    read_recording(path, keep_codes=True)  # imports h5py first, outside the measurement
    tracemalloc.start()
    try:
        kept = read_recording(path, keep_codes=True)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # The codes (1x, plus one copy at most while reading), never the 4x of float64 volts.
    assert peak < 2.2 * codes_bytes
    np.testing.assert_array_equal(kept.waveforms, kept.codes * VOLTS_PER_CODE)  # made on demand
    assert kept.waveforms is kept.waveforms  # then kept


def test_a_format_1_0_file_is_read_with_the_default_array(tmp_path):
    path = write_raw_recording(tmp_path / "old.h5")
    recording = read_recording(path)
    assert recording.array.names == ("left", "centre", "right") and not recording.array.describes_beams
    assert recording.array.volts_per_code == VOLTS_PER_CODE and recording.array.adc_bits == 12
    rewritten = write_recording(tmp_path / "new.h5", recording)
    import h5py

    with h5py.File(rewritten) as h5:
        assert h5.attrs["format_version"] == FORMAT_VERSION == "1.1" and "array" in h5


def test_codes_missing_adc_bits_take_the_storage_width(tmp_path):
    path = write_raw_recording(tmp_path / "old.h5", edit=lambda h5: h5["waveforms"].attrs.__delitem__("adc_bits"))
    assert read_recording(path).adc_bits == 16


def test_the_streaming_writer_matches_the_whole_writer_byte_for_byte(tmp_path):
    recording = _codes_recording()
    one = write_recording(tmp_path / "one.h5", recording)
    again = write_recording(tmp_path / "again.h5", recording)
    parts = (Recording(None, codes=recording.codes[a:b], pose=recording.pose[a:b], clipped=recording.clipped[a:b],
                       **recording.header_fields()) for a, b in ((0, 2), (2, 5)))
    streamed = write_recording_chunks(tmp_path / "streamed.h5", parts, 5, store_codes=True)
    assert one.read_bytes() == again.read_bytes() == streamed.read_bytes()


def test_the_streaming_writer_refuses_a_wrong_count_and_leaves_nothing(tmp_path):
    recording = _codes_recording()
    with pytest.raises(RecordingError, match="announced"):
        write_recording_chunks(tmp_path / "short.h5", (recording,), 7, store_codes=True)
    assert list(tmp_path.iterdir()) == []


def test_float32_volts_are_read_as_float64(tmp_path):
    volts = (clean_codes(2) * VOLTS_PER_CODE).astype(np.float32)
    path = write_raw_recording(tmp_path / "f32.h5", edit=lambda h5: (
        h5.__delitem__("waveforms"), h5.create_dataset("waveforms", data=volts)))
    recording = read_recording(path, keep_codes=True)
    assert recording.codes is None and recording.waveforms.dtype == np.float64
    np.testing.assert_array_equal(recording.waveforms, volts.astype(np.float64))


def test_recordings_stay_immutable_and_replace_still_works():
    recording = _codes_recording(2, 256)
    with pytest.raises(dataclasses.FrozenInstanceError):
        recording.waveforms = None  # type: ignore[misc]
    assert not recording.codes.flags.writeable and not recording.waveforms.flags.writeable
    moved = dataclasses.replace(recording, t0_s=0.0)
    np.testing.assert_array_equal(moved.codes, recording.codes)
    volts = dataclasses.replace(recording, waveforms=recording.waveforms[..., :100], codes=None, volts_per_code=None)
    assert volts.n_samples == 100 and volts.codes is None
    with pytest.raises(RecordingError, match="codes \\* volts_per_code"):
        Recording(recording.waveforms + 1.0, FS, codes=recording.codes, volts_per_code=VOLTS_PER_CODE)
