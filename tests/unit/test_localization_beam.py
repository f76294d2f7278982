"""``localize`` times targets with the beams the recording describes (binsonar only, no simulator).

The ping is the independent construction of ``support.beam_echoes`` (analytic pulse spectrum,
scipy's J1, exact delays) of a point target whose left receiver sees it past the 500 kHz first
null, where the plain matched filter's timing is biased by microseconds.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from binsonar.array_description import ArrayDescription, BeamTable, PistonDirectivity
from binsonar.localization.beam_model import PistonTransducers
from binsonar.localization.classify import classify
from binsonar.localization.fit import ModelFit
from binsonar.localization.pipeline import LocalizationConfig, LocalizationError, localize
from binsonar.recording import Recording, open_recording, write_recording
from binsonar.streaming import localize_source
from support.beam_echoes import FS, C, POSITIONS, RADIUS, point_echoes, template

TARGET = 0.35 * np.array([math.sin(math.radians(6.0)), math.cos(math.radians(6.0)), 0.0])
"""0.35 m at 6 deg: the left receiver sees it 16 deg off its axis (the null is at 11 deg)."""
BOARD = np.tile([0.0, 1.0, 0.0], (3, 1))


def array_with(directivity) -> ArrayDescription:
    base = ArrayDescription.default(POSITIONS, FS)
    return replace(base, channels=tuple(replace(c, directivity=directivity) for c in base.channels))


def recording(n_pings: int = 1, seed: int = 0, directivity=PistonDirectivity(2 * RADIUS)) -> Recording:
    rows, tof, t0 = point_echoes(TARGET, BOARD)
    rng = np.random.default_rng(seed)
    sigma = np.sqrt(np.sum(rows ** 2, axis=1) / 10 ** 3.5)[:, np.newaxis]  # 2E/N0 = 35 dB per channel
    pings = rows[np.newaxis] + sigma * rng.standard_normal((n_pings, *rows.shape))
    return Recording(pings, FS, t0, channel_positions_m=POSITIONS, template=template(), sound_speed_m_s=C,
                     array=array_with(directivity))


def truth() -> tuple[float, float]:
    return float(np.linalg.norm(TARGET)), math.degrees(math.atan2(TARGET[0], TARGET[1]))


def the_target(result, ping: int = 0):
    r, b = truth()
    return min(result.targets[ping], key=lambda t: abs(t.range_m - r))


def test_beam_aware_by_default_and_off_on_request() -> None:
    rec = recording()
    r, b = truth()
    beam = localize(rec, method="matched")
    assert beam.beam_aware and beam.beam == "pistons 19/19/19 mm"
    t = the_target(beam)
    assert t.echo_model == "point" and t.cls == "point"
    # 35 dB: the reported stds are tens of um and a few hundredths of a degree; the errors within 4 of them.
    assert abs(t.range_m - r) < 4 * t.range_std_m and abs(t.bearing_deg - b) < 4 * t.bearing_std_deg
    assert t.bearing_std_deg < 0.1
    plain = localize(rec, method="matched", config=LocalizationConfig(beam=False))
    assert not plain.beam_aware and plain.beam == "off"
    p = the_target(plain)
    assert p.echo_model == ""
    # Past the left receiver's null the plain filter's left TOF is microseconds off: tenths of a
    # degree of bearing, many of its (floored) stds.
    assert abs(p.bearing_deg - b) > 0.2 and abs(p.bearing_deg - b) > 5 * p.bearing_std_deg
    d = beam.to_dict()
    assert d["beam_aware"] is True and d["pings"][0]["targets"][0]["echo_model"] in ("point", "vertical-edge")
    assert all(v is not None and v > 0 for v in d["pings"][0]["targets"][0]["tof_std_s"])


def test_without_described_beams_the_times_stay_plain_and_say_why() -> None:
    rec = recording()
    bare = replace(rec, array=ArrayDescription.default(POSITIONS, FS))
    result = localize(bare, method="matched")
    assert not result.beam_aware and "does not describe the beams" in result.beam
    # ... unless the caller hands the pistons over.
    given = localize(bare, method="matched", transducers=PistonTransducers.uniform(2 * RADIUS))
    assert given.beam_aware and the_target(given).echo_model == "point"
    table = BeamTable.from_db([4e5, 6e5], [0.0, 90.0], np.zeros((2, 2)))
    tabled = localize(recording(directivity=table), method="matched")
    assert not tabled.beam_aware and "beam tables" in tabled.beam
    # A DetectionResult carries no samples.
    from binsonar.detection import detect

    detections = detect(rec, "matched")
    assert "without samples" in localize(detections, sound_speed_m_s=C, channel_positions_m=POSITIONS).beam


@pytest.mark.parametrize("field, value", [("beam", 1), ("echo_model", "plane"), ("beam_tof_floor_s", -1.0),
                                          ("beam_association_floor_s", float("nan"))])
def test_bad_beam_settings_are_refused(field: str, value: object) -> None:
    with pytest.raises(LocalizationError, match=field):
        LocalizationConfig(**{field: value})


def test_range_by_range_is_localize_of_the_whole_with_beams(tmp_path) -> None:
    path = write_recording(tmp_path / "pings.h5", recording(n_pings=3, seed=4))
    from binsonar.recording import read_recording

    whole = localize(read_recording(path), method="matched")
    with open_recording(path) as source:
        streamed = localize_source(source, method="matched", max_bytes=3 * 8192 * 8)  # one ping per range
    assert streamed.beam_aware and streamed.to_dict() == whole.to_dict()


def test_a_fixed_echo_model_is_used_for_every_target() -> None:
    result = localize(recording(), method="matched", config=LocalizationConfig(echo_model="vertical-edge"))
    assert the_target(result).echo_model == "vertical-edge"


def _fit(model: str, chi2: float, dof: int = 1) -> ModelFit:
    return ModelFit(model, ("a",), np.zeros(1), np.eye(1), np.zeros(3), chi2, dof)


def test_ambiguity_between_point_and_plane_follows_the_echo_s_shape() -> None:
    point, circle, plane = _fit("point", 2.0), _fit("circle", 0.0, 0), _fit("plane", 1.0)
    assert classify(point, circle, plane)[0] == "plane"  # the smaller chi2
    cls, reason = classify(point, circle, plane, prefer="point")
    assert cls == "point" and reason.startswith("ambiguous") and "echo's shape" in reason
    # A preference never overrides a test: a rejected point stays rejected.
    assert classify(_fit("point", 40.0), circle, plane, prefer="point")[0] == "plane"
