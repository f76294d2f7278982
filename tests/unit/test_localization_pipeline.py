"""``localize``: detections (hand-built or from synthetic waveforms) -> targets, tank frame, fusion."""

import numpy as np
import pytest

from binsonar.bounds import rms_bandwidth_hz, tof_crlb_s
from binsonar.detection.echo import DetectionResult, Echo
from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.circle import circle_path_lengths
from binsonar.localization.frames import head_to_tank
from binsonar.localization.pipeline import LocalizationConfig, LocalizationError, localize
from binsonar.localization.point import point_path_lengths
from binsonar.recording import Recording, Template

from support.localization_signals import C, G, POSITIONS, synthetic_recording


def _detections(path_lengths_per_ping, tof_std_s=1.35e-7, extra=()):
    """DetectionResult from path lengths (n_pings, n_targets, 3); ``extra`` adds (ping, channel, L) clutter."""
    pings = []
    for k, targets in enumerate(path_lengths_per_ping):
        chans = []
        for c in range(3):
            ls = [L[c] for L in targets if np.isfinite(L[c])] + [L for (p, ch, L) in extra if p == k and ch == c]
            chans.append(tuple(Echo(c, L / C, 1.0, 20.0, 5.0, k, tof_std_s) for L in sorted(ls)))
        pings.append(tuple(chans))
    return DetectionResult("hand-built", tuple(pings))


def test_three_point_targets_with_pose():
    truth = np.array([[0.3, 1.0, 0.0], [-0.5, 2.0, 0.0], [0.1, 3.5, 0.0]])
    lengths = [[point_path_lengths(p, G)[0] for p in truth]]
    pose = [1.0, 1.5, 0.5, 0.0, 0.0, 0.0]
    res = localize(_detections(lengths), sound_speed_m_s=C, channel_positions_m=POSITIONS, pose=pose)
    assert res.n_pings == 1 and len(res.targets[0]) == 3 and res.unassociated == (0,)
    for t, p in zip(res.targets[0], truth):  # sorted by range
        assert t.cls == "point"
        np.testing.assert_allclose(t.position_head_m, p, atol=1e-9)
        np.testing.assert_allclose(t.position_tank_m, head_to_tank(p, pose), atol=1e-9)
        # Path std = c x tof_std, with the default 50 ns systematic floor in quadrature.
        np.testing.assert_allclose(t.path_length_std_m, C * np.hypot(1.35e-7, 50e-9), rtol=1e-12)
    d = res.to_dict()
    assert d["pings"][0]["targets"][0]["class"] == "point" and d["sound_speed_source"] == "argument"


def test_crlb_used_when_echo_has_no_std():
    lengths = [[point_path_lengths([0.0, 1.0, 0.0], G)[0]]]
    det = _detections(lengths, tof_std_s=float("nan"))
    with pytest.raises(LocalizationError, match="rms_bandwidth_hz"):
        localize(det, sound_speed_m_s=C, channel_positions_m=POSITIONS)
    res = localize(det, sound_speed_m_s=C, channel_positions_m=POSITIONS, rms_bandwidth_hz=118.2e3,
                   config=LocalizationConfig(tof_floor_s=0.0))
    expected = C * float(tof_crlb_s(100.0, 118.2e3))  # snr_db = 20 on every echo
    np.testing.assert_allclose(res.targets[0][0].path_length_std_m, expected, rtol=1e-12)
    with pytest.raises(LocalizationError, match="tof_floor_s"):
        LocalizationConfig(tof_floor_s=-1.0)


def test_missing_inputs_are_one_line_errors():
    det = _detections([[point_path_lengths([0.0, 1.0, 0.0], G)[0]]])
    with pytest.raises(LocalizationError, match="sound speed"):
        localize(det, channel_positions_m=POSITIONS)
    with pytest.raises(LocalizationError, match="channel_positions_m"):
        localize(det, sound_speed_m_s=C)
    with pytest.raises(LocalizationError, match="pose"):
        localize(det, sound_speed_m_s=C, channel_positions_m=POSITIONS, pose=[0, 0, 0])
    with pytest.raises(LocalizationError, match="out of range"):
        localize(det, sound_speed_m_s=15.0, channel_positions_m=POSITIONS)


def test_clutter_and_bad_echoes_do_not_raise():
    lengths = [[point_path_lengths([0.2, 1.5, 0.0], G)[0]]]
    # A lone centre echo (main bang at L ~ 0) and a lone left echo far away: left out, no exception.
    det = _detections(lengths, extra=((0, 1, 1e-4), (0, 0, 6.0)))
    res = localize(det, sound_speed_m_s=C, channel_positions_m=POSITIONS)
    assert len(res.targets[0]) == 1 and res.unassociated == (2,)


def test_multi_ping_fusion_through_the_pipeline():
    rng = np.random.default_rng(8)
    sig_t = float(tof_crlb_s(100.0, 118.2e3))
    poses = np.array([[x, 1.5, 0.5, 90.0, 0.0, 0.0] for x in np.linspace(4.0, 5.0, 20)])
    lengths = []
    for pose in poses:
        t = head_to_tank(G.transmitter_m, pose)
        r = head_to_tank(G.receivers_m, pose)
        L = circle_path_lengths([4.5, 2.5], 0.025, np.broadcast_to(t, (3, 3)), r)[0]
        lengths.append([L + C * sig_t * rng.standard_normal(3)])
    res = localize(_detections(lengths, tof_std_s=sig_t), sound_speed_m_s=C, channel_positions_m=POSITIONS,
                   pose=poses)
    assert len(res.fused) == 1
    f = res.fused[0]
    assert f.cls == "cylinder" and len(f.pings) == 20
    assert f.radius_m == pytest.approx(0.025, abs=0.005)
    np.testing.assert_allclose(f.position_tank_m[:2], [4.5, 2.5], atol=0.005)
    assert res.to_dict()["fused"][0]["class"] == "cylinder"


def test_end_to_end_on_synthetic_waveforms_with_the_detector():
    truth = np.array([[0.25, 1.2, 0.0], [-0.3, 2.0, 0.0]])
    rec, template = synthetic_recording(truth, pose=[1.0, 1.5, 0.5, 0.0, 0.0, 0.0])
    res = localize(rec)  # default detector: CA-CFAR, every echo
    assert res.sound_speed_source == "recording" and res.method == "ca-cfar"
    assert len(res.targets[0]) == 2 and res.unassociated == (0,)
    for t, p in zip(res.targets[0], truth):
        # Echo SNR ~ 58 dB: the detector's TOF std ~ 2 ns (3 um of path); the point fit's error is
        # ~ sigma D / d across range, i.e. < 0.1 mm; 1 mm allows for the detector's small bias.
        assert t.cls == "point"
        np.testing.assert_allclose(t.position_head_m, p, atol=1e-3)
        np.testing.assert_allclose(t.position_tank_m, head_to_tank(p, rec.pose[0]), atol=1e-3)
        assert t.echoes[0] is not None and t.echoes[0].tof_std_s > 0
    # The seed's "matched" reports only the strongest echo per channel: one target at most.
    single = localize(rec, method="matched")
    assert len(single.targets[0]) <= 1
    beta = rms_bandwidth_hz(template.samples, template.sample_rate_hz)
    assert 100e3 < beta < 140e3  # the test pulse is close to the thesis pulse (118.2 kHz)


def test_pose_reported_even_without_targets_and_clipped_echoes_flagged():
    det = DetectionResult("hand-built", (((), (), ()),))
    res = localize(det, sound_speed_m_s=C, channel_positions_m=POSITIONS, pose=[1, 2, 0.5, 0, 0, 0])
    assert res.to_dict()["pings"][0]["pose"] == [1, 2, 0.5, 0, 0, 0] and res.targets == ((),)
    L = point_path_lengths([0.0, 1.0, 0.0], G)[0]
    echoes = tuple((Echo(c, L[c] / C, 1.0, 20.0, 5.0, 0, 1e-7, clipped=(c == 1)),) for c in range(3))
    res = localize(DetectionResult("hand-built", (echoes,)), sound_speed_m_s=C, channel_positions_m=POSITIONS)
    assert "clipped channel(s) [1]" in res.targets[0][0].message


def test_averaged_pings_of_one_pose_keep_that_pose():
    """Averaging N pings gives one ping: its pose is the (common) pose of the N pings."""
    from binsonar.detection.echo import DetectionResult
    from binsonar.localization.pipeline import LocalizationError, localize

    echoes = ((), (), ())
    detections = DetectionResult("ca-cfar", (echoes,))
    positions = [[-0.065, 0, 0], [0, 0, 0], [0.065, 0, 0]]
    pose = np.tile([1.0, 1.5, 0.5, 10.0, 0.0, 0.0], (5, 1))
    result = localize(detections, sound_speed_m_s=1482.0, channel_positions_m=positions, pose=pose)
    assert result.n_pings == 1
    moved = pose.copy()
    moved[3, 0] += 0.1
    with pytest.raises(LocalizationError, match="different poses"):
        localize(detections, sound_speed_m_s=1482.0, channel_positions_m=positions, pose=moved)
