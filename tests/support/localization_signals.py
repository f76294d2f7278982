"""Three-channel recordings with Gaussian-pulse echoes at the exact path delays of point targets
(binsonar only: no simulator)."""

import numpy as np

from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.point import point_path_lengths
from binsonar.recording import Recording, Template

C = 1482.0
G = ArrayGeometry.seed(0.065)
POSITIONS = G.receivers_m


def gaussian_pulse(t, f0=500e3, tau=0.95e-6):
    return np.exp(-0.5 * (t / tau) ** 2) * np.cos(2 * np.pi * f0 * t)


def synthetic_recording(truth_head, sound_speed=C, pose=None, noise_v=1e-3, seed=0, fs=20e6, n=70000, store_c=True):
    """Three channels with Gaussian-pulse echoes at the exact path delays of point targets.

    ``store_c`` False leaves the sound speed out of the recording.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    w = np.zeros((1, 3, n))
    for p in truth_head:
        L, _ = point_path_lengths(p, G)
        for c in range(3):
            w[0, c] += 0.2 * gaussian_pulse(t - L[c] / sound_speed)
    w += noise_v * rng.standard_normal(w.shape)
    tt = np.arange(-120, 121) / fs
    template = Template(gaussian_pulse(tt), fs, t0_s=float(tt[0]))
    return Recording(w, fs, 0.0, POSITIONS, template=template, sound_speed_m_s=sound_speed if store_c else None,
                     pose=pose), template
