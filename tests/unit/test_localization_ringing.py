"""A body's ringing must not capture it: an elastic echo a few tens of microseconds behind a
strong specular echo at the same bearing, heard on the centre and right channels only, plus
another reflector's echo on the right, make a triple with the body's left echo that fits the
association gate better than the body's own triple (whose centre path lies half the
point/plane spread off the gate's middle). The construction reproduces the demo's post-1 at
about 2 m and 8.5 deg, whose compressional echo through the diameter follows 62 mm of path
behind and whose triple with the right channel's floor multipath points at -54 deg.

binsonar only: path lengths for ``associate`` and ``localize_ping``, and a synthetic recording
(``support.beam_echoes``: analytic pulse spectrum, piston directivities, exact delays) for
``localize`` with the recording's beams and without.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import brentq

from binsonar.array_description import ArrayDescription, PistonDirectivity
from binsonar.detection.echo import Echo
from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.association import associate, trailing_echoes
from binsonar.localization.pipeline import LocalizationConfig, localize, localize_ping
from binsonar.localization.point import point_from_path_lengths, point_path_lengths
from binsonar.recording import Recording
from support.beam_echoes import FS, C, POSITIONS, RADIUS, point_echoes, template

G = ArrayGeometry.seed(0.065)
SIG = 2e-4
RING_M = 0.062
"""Path by which the compressional echo follows the specular one (the demo's post-1: 42 us)."""
BODY_BEARING_DEG = 4.0


def gate_middle(left_m: float, right_m: float) -> float:
    """The association gate's middle for the centre path of a left/right pair (``association``)."""
    d = G.half_baseline_m
    r, th = point_from_path_lengths(left_m, right_m, d)
    pos = np.array([r * math.sin(th), r * math.cos(th), 0.0])
    return float(np.linalg.norm(pos) + np.linalg.norm(pos - G.receivers_m[1]) + d * d * math.cos(th) ** 2 / (8 * r))


def trap(range_m: float = 2.0, bearing_deg: float = 8.5) -> tuple[np.ndarray, float]:
    """The body's path lengths (3,) and the right-channel path that completes the false triple:
    with the body's left echo and its ringing on the centre, exactly at the gate's middle."""
    b = math.radians(bearing_deg)
    body = point_path_lengths(range_m * np.array([math.sin(b), math.cos(b), 0.0]), G)[0]
    left, centre = body[0], body[1] + RING_M
    d2 = 2 * G.half_baseline_m
    false_right = brentq(lambda r: gate_middle(left, r) - centre, left - 0.999 * d2, left + 0.999 * d2)
    return body, float(false_right)


def lengths_and_strengths(floor_strength: float) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
    body, false_right = trap()
    lengths = [np.array([body[0]]), np.array([body[1], body[1] + RING_M]),
               np.array([body[2], body[2] + RING_M, false_right])]
    strengths = [np.array([1.0]), np.array([1.0, 0.3]), np.array([1.0, 0.3, floor_strength])]
    return lengths, strengths, body


def test_the_trap_is_real_without_the_ringing_order() -> None:
    # Without trailing flags the greedy gate order takes the false triple first (the body's own
    # costs half its point/plane spread): the construction does trap the plain association.
    lengths, _, _ = lengths_and_strengths(0.2)
    _, false_right = trap()
    groups = associate(lengths, [np.full(v.size, SIG) for v in lengths], G)
    first = min(groups, key=lambda g: g.cost)
    assert (first.left, first.centre, first.right) == (0, 1, 2)
    assert lengths[2][first.right] == pytest.approx(false_right)
    assert not any((g.left, g.centre, g.right) == (0, 0, 0) for g in groups)


@pytest.mark.parametrize("floor_strength", [0.2, 4.0], ids=["weak-other-echo", "strong-other-echo"])
def test_ringing_is_grouped_after_the_leading_echoes(floor_strength: float) -> None:
    # The other reflector's echo on the right trails the body's only when it is not 6 dB
    # stronger; either way the body's triple is formed first, and its ringing paired afterwards.
    lengths, strengths, _ = lengths_and_strengths(floor_strength)
    trailing = [trailing_echoes(v, s, span_m=C * 100e-6) for v, s in zip(lengths, strengths)]
    assert [t.tolist() for t in trailing] == [[False], [False, True], [False, True, floor_strength < 2.0]]
    groups = associate(lengths, [np.full(v.size, SIG) for v in lengths], G, trailing=trailing,
                       centre_side_pairs=True)
    assert (0, 0, 0) in [(g.left, g.centre, g.right) for g in groups]
    ring = next(g for g in groups if g.centre == 1)
    assert (ring.left, ring.right) == (None, 1)  # the ringing's centre echo with its right echo


def test_trailing_echoes_rule() -> None:
    lengths = np.array([1.0, 1.05, 1.2, 1.21])
    # 1.05 follows 1.0 within 0.1 m and is weaker; 1.2 is 0.2 m after 1.0 and 0.15 after 1.05;
    # 1.21 follows 1.2 but is 12 dB stronger than it, beyond the 6 dB margin.
    flags = trailing_echoes(lengths, [1.0, 0.9, 0.5, 2.0], span_m=0.1)
    assert flags.tolist() == [False, True, False, False]
    # An earlier echo 4.4 dB weaker (0.6 against 1.0) is within the margin.
    assert trailing_echoes(lengths, [1.0, 0.9, 0.6, 1.0], span_m=0.1).tolist() == [False, True, False, True]
    assert not trailing_echoes(lengths, [1.0] * 4, span_m=0.0).any()
    with pytest.raises(ValueError, match="strengths"):
        trailing_echoes(lengths, [1.0], span_m=0.1)


def echoes_of(lengths: list[np.ndarray], strengths: list[np.ndarray]) -> tuple[tuple[Echo, ...], ...]:
    return tuple(tuple(Echo(ch, float(L / C), float(a), 40.0, 10.0, 0, tof_std_s=SIG / C)
                       for L, a in zip(lengths[ch], strengths[ch])) for ch in range(3))


def test_localize_ping_keeps_the_body() -> None:
    lengths, strengths, body = lengths_and_strengths(0.2)
    cfg = LocalizationConfig(tof_floor_s=0.0)
    targets, _ = localize_ping(echoes_of(lengths, strengths), G, C, config=cfg)
    near = [t for t in targets if abs(t.range_m - 2.0) < 2e-3]
    assert len(near) == 1 and abs(near[0].bearing_deg - 8.5) < 0.05
    # Without the ringing order (span 0) the body is lost, as in the demo.
    plain, _ = localize_ping(echoes_of(lengths, strengths), G, C, config=replace(cfg, ringing_span_s=0.0))
    assert not [t for t in plain if abs(t.range_m - 2.0) < 2e-3 and abs(t.bearing_deg - 8.5) < 0.5]


def shifted(rows: np.ndarray, t0: float, to_t0: float) -> np.ndarray:
    """``rows`` starting at ``t0`` re-expressed on a record starting at ``to_t0`` (both on the grid)."""
    n = int(round((t0 - to_t0) * FS))
    out = np.zeros_like(rows)
    out[:, n:] = rows[:, :rows.shape[1] - n] if n >= 0 else rows[:, -n:]
    return out


def trap_recording() -> Recording:
    """One ping at 35 dB: a point body at 1 m, 4 deg (every receiver inside its main lobe) with a
    ringing echo 62 mm of path behind it (at 0.3 of its amplitude) on the centre and right
    channels, and another reflector's echo on the right channel at the false triple's path."""
    axes = np.tile([0.0, 1.0, 0.0], (3, 1))
    b = math.radians(BODY_BEARING_DEG)
    body_pos = np.array([math.sin(b), math.cos(b), 0.0])
    rows, tof, t0 = point_echoes(body_pos, axes)
    ring, _, t0_ring = point_echoes(body_pos * (1 + 0.5 * RING_M / np.linalg.norm(body_pos)), axes)
    rows = rows + 0.3 * shifted(ring, t0_ring, t0) * np.array([[0.0], [1.0], [1.0]])
    body_l = C * tof
    d2 = 2 * G.half_baseline_m
    centre = point_path_lengths(body_pos * (1 + 0.5 * RING_M), G)[0][1]
    false_right = brentq(lambda r: gate_middle(body_l[0], r) - centre, body_l[0] - 0.999 * d2, body_l[0] + 0.999 * d2)
    # The other reflector: on the right receiver's axis, at the path false_right.
    y = brentq(lambda y: math.hypot(0.065, y) + y - false_right, 0.1, 5.0)
    other, _, t0_other = point_echoes(np.array([0.065, y, 0.0]), axes)
    rows = rows + 0.5 * shifted(other, t0_other, t0) * np.array([[0.0], [0.0], [1.0]])
    rng = np.random.default_rng(7)
    sigma = np.sqrt(np.sum(rows ** 2, axis=1).max() / 10 ** 3.5)
    array = ArrayDescription.default(POSITIONS, FS)
    array = replace(array, channels=tuple(replace(c, directivity=PistonDirectivity(2 * RADIUS)) for c in array.channels))
    return Recording((rows + sigma * rng.standard_normal(rows.shape))[np.newaxis], FS, t0,
                     channel_positions_m=POSITIONS, template=template(), sound_speed_m_s=C, array=array)


@pytest.mark.parametrize("beam", [True, False], ids=["beam", "no-beam"])
def test_recording_with_ringing_keeps_the_body(beam: bool) -> None:
    # CA-CFAR detects every echo (the body's three, the ringing on the centre and right, the other
    # reflector on the right). Without the ringing order (span 0) the false triple (bearing about
    # -59 deg) is formed in both modes and, without beams, the body is lost; with it, the body is
    # found within 4 of its reported stds and nothing points at the false triple.
    rec = trap_recording()
    for span_s, kept in ((100e-6, True), (0.0, False)):
        result = localize(rec, config=LocalizationConfig(beam=beam, ringing_span_s=span_s))
        targets = result.targets[0]
        assert result.beam_aware is beam
        assert any(t.bearing_deg < -30 for t in targets) is not kept
        if kept:
            body = [t for t in targets if abs(t.range_m - 1.0) < 1e-3]
            assert len(body) == 1, [(t.range_m, t.bearing_deg) for t in targets]
            assert abs(body[0].range_m - 1.0) < 4 * body[0].range_std_m
            assert abs(body[0].bearing_deg - BODY_BEARING_DEG) < 4 * body[0].bearing_std_deg
