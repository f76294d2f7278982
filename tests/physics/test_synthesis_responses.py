"""Rows with a transfer function or a rough reflection (``synthesis.spectral_rows``).

Checked against what the table-driven kernels give for the same row (the identity response),
against exact delay shifts (a pure-delay response), and against the coherent-roughness factor
exp(-S k^2) read off the records' spectra.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from acoustisim.errors import InputError
from acoustisim.medium import Medium
from acoustisim.propagation.paths import PathKind, empty_paths_array
from acoustisim.sonar import SonarHead
from acoustisim.synthesis.synthesiser import PathSynthesiser


@dataclass(frozen=True)
class Delay:
    """H(f) = exp(-j 2 pi f d): the echo d seconds later."""

    delay_s: float
    label: str = "delay"

    @property
    def span_s(self) -> tuple[float, float]:
        return (min(0.0, self.delay_s), max(0.0, self.delay_s))

    def transfer(self, frequency_hz, sound_speed_m_s):
        return np.exp(-2j * np.pi * np.asarray(frequency_hz) * self.delay_s)


def row(delay_s: float, *, angle_rad: float = 0.1, roughness_m2: float = 0.0, response_id: int = -1,
        path_length_m: float = 1.482):
    rows = empty_paths_array(1)
    rows["path_id"] = 0
    rows["channel"] = 1
    rows["kind"] = PathKind.SPECULAR
    rows["order"] = 1
    rows["delay_s"] = delay_s
    rows["path_length_m"] = path_length_m
    rows["geometric_gain"] = 0.5
    rows["phase_rad"] = 0.0  # a constant phase adds a Hilbert-transform tail (1/t) longer than any kernel
    rows["angle_tx_rad"] = angle_rad
    rows["angle_rx_rad"] = 0.5 * angle_rad
    rows["roughness_m2"] = roughness_m2
    rows["response_id"] = response_id
    return rows


@pytest.fixture(scope="module")
def synth() -> PathSynthesiser:
    return PathSynthesiser.create(SonarHead(record_length_s=2e-3), Medium())


def test_the_identity_response_gives_the_table_kernels_echo(synth) -> None:
    # The tables hold the directivity to 7e-4 absolute and the delay to 0.05 ns (the
    # synthesiser's stated resolution); the spectral path evaluates both exactly: the echoes
    # agree within 2e-3 of their peak.
    table = synth.decimated_record(row(1.0e-3))
    spectral = synth.decimated_record(row(1.0e-3, response_id=0), responses=(Delay(0.0),))
    peak = np.abs(table).max()
    assert peak > 0
    assert np.abs(spectral - table).max() <= 2e-3 * peak


def test_a_pure_delay_response_moves_the_echo_exactly(synth) -> None:
    # Both through the spectral path, evaluated exactly; the kernels start at different samples
    # and so cut the pulse's tails (its support holds the envelope to 1e-6) differently: equal
    # within 1e-6 of the peak.
    later = synth.decimated_record(row(1.0e-3, response_id=0), responses=(Delay(3.7e-6),))
    moved = synth.decimated_record(row(1.0e-3 + 3.7e-6, response_id=0), responses=(Delay(0.0),))
    assert np.abs(later - moved).max() <= 1e-6 * np.abs(moved).max()


def test_roughness_multiplies_the_spectrum_by_exp_minus_s_k_squared(synth) -> None:
    s = 2 * (0.5e-3 * np.sin(np.radians(30.0))) ** 2  # h = 0.5 mm at 30 deg grazing: -4.9 dB at 500 kHz
    smooth = synth.decimated_record(row(1.0e-3, response_id=0), responses=(Delay(0.0),))[1]
    rough = synth.decimated_record(row(1.0e-3, roughness_m2=s))[1]
    fs_dec = synth.grid.sample_rate_hz / synth.grid.decimation
    f = np.fft.rfftfreq(smooth.size, 1.0 / fs_dec)
    band = (f > 300e3) & (f < 700e3)
    ratio = np.fft.rfft(rough)[band] / np.fft.rfft(smooth)[band]
    k = 2 * np.pi * f[band] / synth.sound_speed_m_s
    # the ratio of two exactly evaluated spectra whose kernels cut the pulse's tails (1e-6 of
    # its envelope) at different places: the factor to 1e-6
    np.testing.assert_allclose(ratio, np.exp(-s * k**2), rtol=1e-6)
    level_500 = -10 * np.log10(np.exp(-s * (2 * np.pi * 500e3 / synth.sound_speed_m_s) ** 2) ** 2)
    assert level_500 == pytest.approx(4.9, abs=0.1)  # physics.md section 8: ~5 dB


def test_a_row_naming_a_missing_response_is_refused(synth) -> None:
    with pytest.raises(InputError, match="response_id"):
        synth.decimated_record(row(1.0e-3, response_id=2), responses=(Delay(0.0),))
