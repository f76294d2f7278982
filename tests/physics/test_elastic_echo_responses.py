"""The lazily evaluated transfer functions of one elastic body's rows (``propagation.elastic_responses``).

Against phase 1's direct evaluation (``scattering.echo.echo_transfer``, coefficients at f cos(e)
for every row and frequency): the flat-row decomposition exactly, the synthesis-grid evaluation
(time responses + chirp-z) through the echoes it synthesises, and the span against the echo
computed over a long window.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import hilbert

from acoustisim.materials import get_material
from acoustisim.propagation.elastic_echoes import flat_rows
from acoustisim.propagation.elastic_responses import SPAN_LEVEL_DB, ElasticRows
from acoustisim.scattering.bodies import AIR, Fluid, Shell, body_from_material
from acoustisim.scattering.echo import EchoGeometry, EchoTarget, echo_transfer
from acoustisim.synthesis.transducer import pulse_spectrum, pulse_support_s
from scenes.builders import default_sonar
from support.response_spans import worst_outside_span_db

WATER = Fluid(998.2, 1482.4)
PVC = get_material("pvc")
PULSE = default_sonar().pulse
FS_DEC = 20e6 / 7  # the thesis sonar's decimated synthesis rate
# (image) sources and receivers around a post at the origin: monostatic and bistatic rows in the
# plane normal to the axis, rows via the floor (image 1 m below) and the surface
SOURCES = np.array([[0.0, -1.5, 0.5], [0.0, -1.5, -0.5], [0.3, -2.0, -0.5], [0.0, -1.0, 1.5], [0.1, -2.5, 0.5]])
RECEIVERS = np.array([[0.065, -1.5, 0.5], [0.0, -1.5, 0.5], [0.3, -2.0, 0.5], [0.0, -1.0, 0.5], [-0.1, -2.4, 0.5]])


def body_rows(body, radius: float) -> tuple[ElasticRows, EchoTarget, EchoGeometry]:
    target = EchoTarget("post", radius, body, PVC)
    geometry = EchoGeometry.from_points(SOURCES, RECEIVERS, [0.0, 0.0, 0.5], [0.0, 0.0, 1.0])
    flat, compression, factor = flat_rows(target, geometry, WATER)
    batch = ElasticRows(target, flat, compression, factor, np.zeros(len(SOURCES), dtype=np.int64),
                        WATER.density_kg_m3, WATER.sound_speed_m_s, PULSE)
    return batch, target, geometry


@pytest.fixture(scope="module")
def pvc_post():
    return body_rows(body_from_material(PVC), 0.025)


def test_rows_at_an_elevation_areflat_rows_at_f_cos_e(pvc_post) -> None:
    # H_row(f) = conj(C) T_flat(f cos e) is an identity of phase 1's oblique model (module
    # docstring): exact evaluation both ways agrees to rounding (1e-8 of max |H|: echo_transfer
    # groups the elevations by cos(e) rounded to 1e-12, a frequency shift of 5e-7 Hz at 500 kHz,
    # i.e. 6e-9 rad of the series' propagation phase over its ~2 ms; measured 4e-9)
    batch, target, geometry = pvc_post
    assert np.all(batch.compression[[1, 2, 3]] < 0.98) and np.all(batch.compression[[0, 4]] == 1.0)
    f = np.array([137e3, 499e3, 500e3, 873e3])
    reference = echo_transfer(target, geometry, WATER, f)
    assert np.max(np.abs(batch.exact_transfers(f) - reference)) < 1e-8 * np.max(np.abs(reference))
    # a few frequencies are evaluated exactly by transfers() too
    np.testing.assert_array_equal(batch.transfers(f, WATER.sound_speed_m_s), batch.exact_transfers(f))


def synthesis_grid(batch: ElasticRows) -> tuple[np.ndarray, np.ndarray, int]:
    """The spectral-rows kernel grid for these rows (its length from the span, like synthesis)."""
    start, stop = pulse_support_s(PULSE)
    span = batch.span_s
    length = 1 << int(np.ceil(np.log2((span[1] - span[0] + stop - start) * FS_DEC + 8)))
    f = np.arange(length // 2 + 1) * FS_DEC / length
    return f, f <= batch.window().band_top_hz, length


@pytest.mark.parametrize("case", ["solid post", "pipe"])
def test_synthesis_grid_echoes_match_the_direct_evaluation(case: str, pvc_post) -> None:
    # The echo each row synthesises (pulse x H on the kernel grid, inverse FFT) from the chirp-z
    # evaluation against the one from phase 1's direct evaluation: both hold the echo to the
    # span level (-60 dB), beyond which the ring-down wraps around differently (the body's window
    # and the kernel differ): the difference stays below -50 dB of the echo's peak (measured
    # -55 to -57 dB).
    batch, target, geometry = pvc_post if case == "solid post" else body_rows(
        Shell(body_from_material(PVC), 0.004, AIR), 0.075)
    f, inside, length = synthesis_grid(batch)
    mine = np.zeros((geometry.n_rows, f.size), dtype=complex)
    reference = np.zeros_like(mine)
    mine[:, inside] = batch.transfers(f[inside], WATER.sound_speed_m_s)
    reference[:, 1:][:, inside[1:]] = echo_transfer(target, geometry, WATER, f[1:][inside[1:]])
    pulse = pulse_spectrum(PULSE, f) * np.exp(2j * np.pi * f * (-pulse_support_s(PULSE)[0] + 2.0 / FS_DEC))
    echo, expected = np.fft.irfft(pulse * mine, length), np.fft.irfft(pulse * reference, length)
    error_db = 20 * np.log10(np.abs(echo - expected).max(axis=1) / np.abs(expected).max(axis=1))
    assert np.all(error_db < -50.0), error_db


def test_the_span_holds_the_echo_to_the_span_level(pvc_post) -> None:
    # The monostatic pulse echo over 2 ms (phase 1's direct evaluation; the PVC post has rung down
    # below -100 dB by then): beyond the span (plus the pulse's half-length) it stays below the
    # span level (1 dB allowance for the reference row's distance, 1.5 m, against the rows' median
    # 1.49 m); the named internal arrivals (+42, +76, +94 us) lie inside.
    batch, target, _ = pvc_post
    span = batch.span_s
    assert span[0] <= 0.0 and 0.1e-3 < span[1] < 0.2e-3
    n = 4096
    f = np.fft.rfftfreq(n, 1.0 / FS_DEC)
    band = (f > 0) & (f <= batch.window().band_top_hz)
    geometry = EchoGeometry(np.array([1.5]), np.array([1.5]), np.zeros(1), np.zeros(1))
    spectrum = np.zeros(f.size, dtype=complex)
    spectrum[band] = echo_transfer(target, geometry, WATER, f[band])[0] * pulse_spectrum(PULSE, f[band])
    envelope = np.abs(hilbert(np.roll(np.fft.irfft(spectrum, n), 100)))
    level = 20 * np.log10(envelope / envelope.max())
    t = (np.arange(n) - 100) / FS_DEC
    late = t > span[1] + pulse_support_s(PULSE)[1]
    assert level[late].max() < SPAN_LEVEL_DB + 1.0
    delays = [a.delay_s for a in batch.internal_arrivals() if a.path in ("LL", "LLT", "TT")]
    assert len(delays) == 3 and max(delays) < span[1]


def test_batches_keep_what_they_computed(pvc_post) -> None:
    batch, _, _ = pvc_post
    f = np.arange(300) * 5580.0
    first = batch.transfers(f, WATER.sound_speed_m_s)
    assert batch.transfers(f, WATER.sound_speed_m_s, [3, 1]) is not first
    np.testing.assert_array_equal(batch.transfers(f, WATER.sound_speed_m_s, [3, 1]), first[[3, 1]])
    assert batch.transfers(f, WATER.sound_speed_m_s) is first  # kept, not recomputed


def test_every_echo_of_the_thesis_tank_lies_within_its_span(thesis_tank) -> None:
    # The span promise over a whole scene: each single-body elastic response of the default
    # pose (shadows off: one factor per response), its pulse-filtered echo synthesised through
    # the time responses (a 2 ms grid at 4 MHz, so step 4's interpolation), stays below the span
    # level outside its span plus the pulse's support. The span is measured on a reference row
    # (the body's median distance, monostatic); the rows at other distances and bistatic angles
    # ring up to 2.2 dB higher after it (post-1, -57.8 dB measured): -57 dB. Without the fade of
    # the time responses' ends the pipe's rows showed a -44 dB precursor at the window's start.
    from acoustisim.propagation import SolverConfig, solve

    paths = solve(thesis_tank, config=SolverConfig(mechanisms=("direct", "specular"), shadows=False))
    singles = [r for r in paths.responses if len(r.parts) == 1 and not r.others]
    worst = worst_outside_span_db(singles, thesis_tank.sonar.pulse, paths.sound_speed_m_s,
                                  pulse_support_s(thesis_tank.sonar.pulse))
    assert len(singles) > 100
    assert worst < SPAN_LEVEL_DB + 3.0, worst
