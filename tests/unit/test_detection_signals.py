"""The synthetic echoes of ``support.detection_signals`` are what the detection tests assume."""

from __future__ import annotations

import numpy as np

from binsonar.bounds import rms_bandwidth_hz, tof_crlb_s
from support.detection_signals import FS, echo_rows, pulse_energy, pulse_template


def test_envelope_bandwidth_and_bound_match_physics_notes():
    # physics.md section 6: envelope beta = 118.2 kHz, i.e. 135 ns at 2E/N0 = 20 dB. The
    # sampled, truncated template must reproduce it to 0.5 % (the printed precision).
    beta = rms_bandwidth_hz(pulse_template().samples, FS)
    assert abs(beta - 118.2e3) < 0.005 * 118.2e3
    assert abs(float(tof_crlb_s(100.0, beta)) - 135e-9) < 1.5e-9


def test_echo_energy_does_not_depend_on_the_fractional_delay():
    # The SNR definition uses the template's energy for every echo: check it holds for echoes
    # at fractional delays (a band-limited pulse sampled 40 times per cycle: Parseval).
    rows = echo_rows(np.array([100e-6, 100e-6 + 13e-9, 100e-6 + 31e-9]), 4096)
    energies = (rows ** 2).sum(axis=1)
    assert np.allclose(energies, pulse_energy(), rtol=1e-9)
