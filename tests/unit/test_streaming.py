"""``binsonar.streaming``: detection and localisation range by range give what the whole
recording in memory gives."""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.detection import detect
from binsonar.localization.pipeline import LocalizationConfig, localize
from binsonar.recording import Recording, RecordingError, open_recording, read_recording, write_recording
from binsonar.streaming import average_source, detect_source, localize_source
from support.detection_signals import FS, echo_rows, noise_sigma_for, pulse_template

N = 4096
STEP = 2.0 / 4096
PING_BYTES = 3 * N * 2


@pytest.fixture()
def ping_file(tmp_path):
    """Seven pings of int16 codes, echoes of one point target, poses moving along x, ping 4 clipped."""
    rng = np.random.default_rng(21)
    delays = np.array([100.4e-6, 100.0e-6, 100.6e-6])
    clean = echo_rows(delays, N, 0.3)
    volts = clean[np.newaxis] + rng.standard_normal((7, 3, N)) * noise_sigma_for(35.0, 0.3)
    codes = np.round(volts / STEP).astype(np.int16)
    codes[4, 1, 50] = 2047  # the 12-bit ADC's rail
    pose = np.zeros((7, 6))
    pose[:, 0] = np.linspace(1.0, 1.006, 7)
    pose[:, 1] = 1.5
    recording = Recording(None, FS, 0.0, codes=codes, volts_per_code=STEP, adc_bits=12, template=pulse_template(),
                          pose=pose, sound_speed_m_s=1482.0)
    return write_recording(tmp_path / "pings.h5", recording)


def _tofs(result):
    return [[[e.tof_s for e in channel] for channel in ping] for ping in result.echoes]


@pytest.mark.parametrize("method", ["matched", "ca-cfar", "threshold", "local-matched"])
def test_range_by_range_is_the_whole_recordings_detection(ping_file, method):
    whole = detect(read_recording(ping_file, keep_codes=True), method)
    with open_recording(ping_file) as source:
        streamed = detect_source(source, method, max_bytes=2 * PING_BYTES)  # ranges of 2, 2, 2 and 1 pings
    assert streamed.n_pings == 7 and streamed.method == whole.method
    assert streamed.clipped == whole.clipped and streamed.clipped[4][1]
    assert [[[e.ping for e in c] for c in p] for p in streamed.echoes] == \
        [[[e.ping for e in c] for c in p] for p in whole.echoes]
    assert _tofs(streamed) == _tofs(whole)  # the same codes, the same arithmetic: equal, not close


def test_averaging_range_by_range_matches_the_average_in_memory(ping_file):
    whole = detect(read_recording(ping_file, keep_codes=True), "seed-4")
    with open_recording(ping_file) as source:
        averaged = average_source(source, max_bytes=PING_BYTES)
        streamed = detect_source(source, "seed-4", max_bytes=PING_BYTES)
    assert averaged.n_pings == 1 and averaged.clipped[0].tolist() == [False, True, False]
    assert streamed.n_pings == 1 and streamed.clipped == whole.clipped
    # The DC offset is measured on the average (streamed) or averaged over pings (in memory): the
    # two estimates differ by a fraction of the averaged noise, and the TOFs by far less than
    # their CRLB (about 5 ns at 35 dB + 8.5 dB of averaging).
    for ours, theirs in zip(streamed.first(0), whole.first(0)):
        assert abs(ours.tof_s - theirs.tof_s) < 0.1e-9


def test_a_clipped_ping_is_named_by_its_index_in_the_file(ping_file):
    with open_recording(ping_file) as source:
        with pytest.raises(RecordingError, match="ping 4, channel 1 clipped"):
            detect_source(source, "matched", on_clipped="error", max_bytes=2 * PING_BYTES)


def test_localize_range_by_range_is_localize_of_the_whole(ping_file):
    config = LocalizationConfig(min_pings_to_fuse=3)
    whole = localize(read_recording(ping_file), method="matched", config=config)
    with open_recording(ping_file) as source:
        streamed = localize_source(source, method="matched", config=config, max_bytes=3 * PING_BYTES)
    assert streamed.to_dict() == whole.to_dict()
    assert streamed.fused and streamed.sound_speed_source == "recording"


def test_localize_without_a_sound_speed_names_the_file(tmp_path):
    path = write_recording(tmp_path / "quiet.h5", Recording(np.zeros((1, 3, 512)), FS, template=pulse_template()))
    with open_recording(path) as source:
        with pytest.raises(RecordingError, match=f"{path}: no sound speed"):
            localize_source(source)
