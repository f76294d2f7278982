"""``Detector``: ``detect`` with the prepared detector of each set-up kept, bounded, per object."""

from __future__ import annotations

import numpy as np
import pytest

from binsonar.detection import Detector, detect
from binsonar.recording import Recording, RecordingError, Template
from support.detection_signals import FS, echo_rows, noise_sigma_for, pulse_template

N = 8192


def _ping(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    clean = echo_rows(np.array([100e-6, 101e-6, 102e-6]) + seed * 1e-6, N)
    return clean + noise_sigma_for(25.0) * rng.standard_normal(clean.shape)


def _echoes(result) -> list:
    return [[(e.tof_s, e.amplitude, e.snr_db, e.score, e.tof_std_s) for e in ch] for ping in result.echoes for ch in ping]


@pytest.mark.parametrize("method", ["matched", "local-matched", "threshold", "seed-4", "ca-cfar"])
def test_a_loop_of_pings_plans_once_and_gets_what_detect_gets(method):
    detector = Detector()
    for seed in range(3):
        ping = _ping(seed)
        # A new but equal template object each time: the key is its content, not its identity.
        got = detector.detect(ping, method, sample_rate_hz=FS, template=pulse_template())
        assert _echoes(got) == _echoes(detect(ping, method, sample_rate_hz=FS, template=pulse_template()))
    assert detector.builds == 1 and len(detector) == 1


def test_the_key_tells_set_ups_apart_and_the_store_is_bounded():
    detector = Detector(max_plans=2)
    ping = _ping(0)
    template = pulse_template()
    detector.detect(ping, "matched", sample_rate_hz=FS, template=template)
    # Another template (shape, or only its time origin), options, record length: new plans.
    shifted = Template(template.samples, FS, template.t0_s + 1e-6)
    moved = detector.detect(ping, "matched", sample_rate_hz=FS, template=shifted)
    assert detector.builds == 2
    assert moved.echoes[0][0][0].tof_s == pytest.approx(
        detect(ping, "matched", sample_rate_hz=FS, template=template).echoes[0][0][0].tof_s - 1e-6, abs=1e-15)
    detector.detect(ping, "matched", sample_rate_hz=FS, template=template, pfa=1e-2)
    assert detector.builds == 3 and len(detector) == 2  # the least recently used was dropped
    detector.detect(ping, "matched", sample_rate_hz=FS, template=template, pfa=1e-2)
    assert detector.builds == 3
    detector.detect(ping, "matched", sample_rate_hz=FS, template=template)  # dropped above: planned again
    assert detector.builds == 4
    detector.detect(ping[:, :4096], "matched", sample_rate_hz=FS, template=template)
    assert detector.builds == 5
    # The recording's own template is part of the key too.
    recording = Recording(ping, FS, template=template)
    other = Recording(ping, FS, template=shifted)
    a = detector.detect(recording, "local-matched")
    b = detector.detect(other, "local-matched")
    assert a.echoes[0][1][0].tof_s - b.echoes[0][1][0].tof_s == pytest.approx(1e-6, abs=1e-15)
    assert detector.builds == 7


def test_unhashable_options_plan_afresh_and_bad_sizes_are_refused():
    detector = Detector()
    ping = _ping(1)
    listed = detector.detect(ping, "threshold", sample_rate_hz=FS, search_window_s=[90e-6, 200e-6])
    assert detector.builds == 0 and len(detector) == 0
    assert _echoes(listed) == _echoes(detect(ping, "threshold", sample_rate_hz=FS, search_window_s=(90e-6, 200e-6)))
    with pytest.raises(RecordingError, match="max_plans"):
        Detector(max_plans=0)
    # Errors are those of detect, and a failed plan is not stored.
    with pytest.raises(RecordingError, match="needs a template"):
        detector.detect(ping, "matched", sample_rate_hz=FS)
    assert len(detector) == 0
