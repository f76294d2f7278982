"""Synthetic beam-filtered echoes for the beam-aware refinement tests, built in the frequency
domain from the Gaussian pulse's analytic spectrum, the piston directivity evaluated with
scipy's J1 directly, and the exact geometric delays: an independent construction of what
``beam_model`` models with its own table and quadrature."""


from __future__ import annotations

import math

import numpy as np
from scipy.special import j1

from binsonar.detection import detect
from binsonar.localization.beam_model import BeamModelConfig, PistonTransducers
from binsonar.localization.beam_refine import BeamRefinementConfig, refine_tofs
from binsonar.recording import Template

FS = 20e6
C = 1482.0
F0 = 500e3
T_PULSE = 5e-6
RADIUS = 0.0095
N = 8192
SEP = 0.065
POSITIONS = np.array([[-SEP, 0.0, 0.0], [0.0, 0.0, 0.0], [SEP, 0.0, 0.0]])


ALPHA = 13.8 / T_PULSE ** 2
DC_CORRECTION = math.exp(-(math.pi * F0) ** 2 / ALPHA)


def pulse_spectrum(f: np.ndarray) -> np.ndarray:
    """Continuous FT of s(t) = exp(-13.8 t^2 / T^2) (cos(2 pi f0 t) - k), the seed's pulse
    (physics.md section 2) with its 1 % mean removed (k = exp(-pi^2 f0^2 / alpha), S(0) = 0):
    transducers and the receiver's high-pass pass no DC, and a pulse with a mean would give a
    phase-shifted echo (an edge's -45 deg, a carrier phase) Hilbert tails longer than any window."""
    g = lambda x: math.sqrt(math.pi / ALPHA) * np.exp(-(math.pi * x) ** 2 / ALPHA)  # noqa: E731
    return 0.5 * (g(f - F0) + g(f + F0)) - DC_CORRECTION * g(f)


def template() -> Template:
    t = np.arange(-200, 201) / FS  # +/-10 us: the Gaussian is exp(-55) there
    return Template(np.exp(-ALPHA * t ** 2) * (np.cos(2 * np.pi * F0 * t) - DC_CORRECTION), FS, float(t[0]))


def jinc(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return np.where(np.abs(x) < 1e-12, 1.0, 2.0 * j1(np.where(x == 0, 1.0, x)) / np.where(x == 0, 1.0, x))


def angle(v: np.ndarray, axis: np.ndarray) -> np.ndarray:
    return np.arccos(np.clip((v @ axis) / np.linalg.norm(v, axis=-1), -1.0, 1.0))


def record_from_spectra(spectra: np.ndarray) -> np.ndarray:
    """(3, N) record of the echoes whose continuous spectra (3, N/2+1), referred to t = 0, are given."""
    return np.fft.irfft(FS * spectra, N, axis=-1)


def record_start(tof: np.ndarray) -> float:
    """Time of the record's first sample (s): 150 us before the earliest echo, on the sample grid."""
    return math.floor((float(np.min(tof)) - 150e-6) * FS) / FS


def point_echoes(target: np.ndarray, axes: np.ndarray, radius: float = RADIUS,
                 phase: float = 0.7) -> tuple[np.ndarray, np.ndarray, float]:
    """Record (3, N) of a point target with the pistons' directivity, the true TOFs (3,) and the record's t0 (s)."""
    f = np.fft.rfftfreq(N, 1.0 / FS)
    tof = (np.linalg.norm(target) + np.linalg.norm(target - POSITIONS, axis=1)) / C
    T0 = record_start(tof)
    k = 2 * np.pi * f / C
    d_tx = jinc(k * radius * np.sin(angle(target, axes[1])))
    spectra = np.empty((3, f.size), dtype=complex)
    for ch in range(3):
        d_rx = jinc(k * radius * np.sin(angle(target - POSITIONS[ch], axes[ch])))
        spectra[ch] = pulse_spectrum(f) * d_tx * d_rx * np.exp(-2j * np.pi * f * (tof[ch] - T0) + 1j * phase)
    return record_from_spectra(spectra), tof, T0


def plain_tofs(rows: np.ndarray, t0: float) -> np.ndarray:
    result = detect(rows, "matched", sample_rate_hz=FS, t0_s=t0, template=template())
    return np.array([e.tof_s for e in result.first(0)])


def refine(rows: np.ndarray, tof: np.ndarray, t0: float, transducers: PistonTransducers, **model) -> np.ndarray:
    config = BeamRefinementConfig(model=BeamModelConfig(**model))
    return refine_tofs(rows, tof, sample_rate_hz=FS, t0_s=t0, template=template(), channel_positions_m=POSITIONS,
                       sound_speed_m_s=C, transducers=transducers, config=config).tof_s
