"""binsonar's cued search for a missing channel's echo (``beam_cue``), on echoes synthesised here.

The echoes come from ``test_beam_refine``'s independent construction (the pulse's analytic
spectrum, scipy's J1 for the pistons, exact delays). The scene: a point target 1 m away at 12 deg,
the head's three pistons on the boresight. The far (left) receiver sees it 15.6 deg off axis, past
its 500 kHz null (11 deg), so its echo is weak and low-passed.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from support.beam_echoes import C, FS, POSITIONS, RADIUS, point_echoes, template

from binsonar.detection import detect
from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.beam_cue import cue_missing_echo, filter_noise_level, predicted_tof
from binsonar.localization.beam_model import BeamModelConfig, PistonTransducers
from binsonar.localization.beam_correlation import CorrelationGrid
from binsonar.localization.beam_refine import BeamRefinementConfig, refine_echoes

BEARING = math.radians(12.0)
TARGET = np.array([math.sin(BEARING), math.cos(BEARING), 0.0])
AXES = np.array([[0.0, 1.0, 0.0]] * 3)
TRANSDUCERS = PistonTransducers.uniform(2 * RADIUS)
CONFIG = BeamRefinementConfig(model=BeamModelConfig(target="point"))


def scene() -> tuple[np.ndarray, np.ndarray, float]:
    """Noise-free record (3, n), true TOFs (3,), t0 (s)."""
    return point_echoes(TARGET, AXES)


def noisy(rows: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    return rows + sigma * rng.standard_normal(rows.shape)


def plain_echoes(rows: np.ndarray, t0: float) -> tuple:
    return detect(rows, "matched", sample_rate_hz=FS, t0_s=t0, template=template()).first(0)


def cue(rows: np.ndarray, echoes: tuple, t0: float, config: BeamRefinementConfig = CONFIG) -> tuple:
    return cue_missing_echo(rows, echoes, sample_rate_hz=FS, t0_s=t0, template=template(),
                            channel_positions_m=POSITIONS, sound_speed_m_s=C, transducers=TRANSDUCERS, config=config)


def test_two_echoes_predict_the_third_channel_s_tof() -> None:
    rows, truth, t0 = scene()
    echoes = list(plain_echoes(rows, t0))
    # Exact TOFs on the centre and right: the fit is exact, so the prediction is the left
    # channel's geometric TOF to rounding (1e-13 s ~ 0.1 nm of path).
    echoes = [None, replace(echoes[1], tof_s=float(truth[1]), tof_std_s=1e-9),
              replace(echoes[2], tof_s=float(truth[2]), tof_std_s=1e-9)]
    geometry = ArrayGeometry.from_channel_positions(POSITIONS, 1)
    position, tof, std = predicted_tof(echoes, 0, geometry, C)
    assert tof == pytest.approx(truth[0], abs=1e-13)
    assert np.allclose(position, TARGET, atol=1e-9)
    # 1 ns on each echo: the predicted TOF's std is a few ns (the left channel's path changes
    # about as much as the right one's, through the fitted bearing) and scales with the input std.
    assert 1e-9 < std < 20e-9
    doubled = [None, replace(echoes[1], tof_std_s=2e-9), replace(echoes[2], tof_std_s=2e-9)]
    assert predicted_tof(doubled, 0, geometry, C)[2] == pytest.approx(2 * std, rel=1e-6)


def test_filter_noise_level_is_the_white_noise_output_power() -> None:
    # White noise of variance s^2 through z = sum_k X_k conj(A_k) e^(j 2 pi f_k tau) (one-sided):
    # E|z|^2 = s^2 n_fft sum_k |A_k|^2. The median/ln 2 estimate over 64 segments of ~480 lags
    # each (correlated over ~100 lags: ~300 independent values) is within 10 % (3 sigma ~ 6 %).
    rng = np.random.default_rng(5)
    sigma = 1e-3
    row = sigma * rng.standard_normal(200_000)
    half = 12e-6
    grid = CorrelationGrid.create(template(), TRANSDUCERS, BeamModelConfig(target="point"), C, half)
    expected = grid.template_spectrum * np.exp(-0.3 * grid.frequency_hz / 1e6)  # any smooth shape
    level = filter_noise_level(row, expected, grid, half, FS)
    assert level == pytest.approx(sigma ** 2 * grid.n_fft * np.sum(np.abs(expected) ** 2), rel=0.1)


def test_cued_search_finds_the_far_channel_the_matched_filter_misses() -> None:
    rows, truth, t0 = scene()
    # Noise so that the far (left) channel's echo sits near the matched filter's threshold: the
    # plain filter finds it in about a quarter of the draws, the other two channels always
    # (their echoes are 2-2.3x stronger).
    sigma = 0.45 * float(np.max(np.abs(rows[0])))
    rng = np.random.default_rng(11)
    missed = found = 0
    errors, stds = [], []
    for _ in range(40):
        x = noisy(rows, sigma, rng)
        plain = plain_echoes(x, t0)
        if plain[1] is None or plain[2] is None:
            continue
        if plain[0] is not None and abs(plain[0].tof_s - truth[0]) < 5e-6:
            continue  # the plain filter found it: nothing to cue
        missed += 1
        out = cue(x, (None, plain[1], plain[2]), t0)
        if out[0] is not None:
            found += 1
            errors.append(out[0].tof_s - truth[0])
            stds.append(out[0].tof_std_s)
            assert out[0].channel == 0 and out[0].score >= 1.0 and out[0].snr_db > 10.0
    # The plain filter misses this channel most of the time; the cued search finds nearly all of
    # those (its filter matches the low-passed echo and its window is microseconds, not the record).
    assert missed >= 20
    assert found >= 0.9 * missed
    # Its TOF is efficient: RMS error within 1.5x the CRLB it reports (the beam's per-frequency
    # shaping is in its filter, so no bias; 1.5x covers the RMS of ~25 draws, +/-15 %).
    assert np.sqrt(np.mean(np.square(errors))) < 1.5 * np.sqrt(np.mean(np.square(stds)))


def test_cued_search_rarely_fires_on_noise_alone() -> None:
    # The far channel holds noise only: with cue_pfa = 1e-3 over the window, 300 draws give 0.3
    # false echoes on average; 3 or more has Poisson probability 0.4 %.
    rows, truth, t0 = scene()
    sigma = 0.45 * float(np.max(np.abs(rows[0])))
    start = plain_echoes(rows, t0)
    rows = rows.copy()
    rows[0] = 0.0
    rng = np.random.default_rng(12)
    false = 0
    for _ in range(300):
        out = cue(noisy(rows, sigma, rng), (None, start[1], start[2]), t0)
        false += out[0] is not None
    assert false <= 2


def test_refine_echoes_cues_then_refines_and_the_switch_turns_it_off() -> None:
    rows, truth, t0 = scene()
    plain = plain_echoes(rows, t0)
    triple = (None, plain[1], plain[2])
    kwargs = dict(sample_rate_hz=FS, t0_s=t0, template=template(), channel_positions_m=POSITIONS, sound_speed_m_s=C,
                  transducers=TRANSDUCERS)
    refined = refine_echoes(rows, triple, config=CONFIG, **kwargs)
    assert all(e is not None for e in refined)
    # Noise-free, the cued and refined right TOF is the true one (the refinement's own accuracy).
    assert abs(refined[0].tof_s - truth[0]) < 0.01e-9
    off = refine_echoes(rows, triple, config=replace(CONFIG, cue_missing_channel=False), **kwargs)
    assert off == triple
    # Two missing channels: nothing to locate from, unchanged.
    assert refine_echoes(rows, (None, None, plain[2]), config=CONFIG, **kwargs) == (None, None, plain[2])


@pytest.mark.parametrize("field,value", [("cue_pfa", 0.0), ("cue_pfa", 1.0), ("cue_pfa", float("nan")),
                                         ("cue_pfa", 1), ("cue_missing_channel", 1)])
def test_bad_cue_settings_are_refused(field: str, value: object) -> None:
    from binsonar.recording import RecordingError

    with pytest.raises(RecordingError, match=field):
        BeamRefinementConfig(**{field: value})
