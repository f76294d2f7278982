"""Far-field directivity of a baffled circular piston."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def piston_directivity(
    angle_rad: ArrayLike, frequency_hz: ArrayLike, radius_m: float, sound_speed_m_s: float
) -> NDArray[np.float64]:
    """One-way pressure directivity 2 J1(x) / x, x = k a sin(angle), of a baffled circular piston.

    The baffled piston radiates into the half space in front of it: behind it (angle > 90 deg)
    the directivity is 0 (the 2 J1(x)/x formula alone would repeat the front lobe behind).

    Parameters
    ----------
    angle_rad : array_like
        Angle off the acoustic axis (rad); broadcast against ``frequency_hz``.
    frequency_hz : array_like
        Frequency (Hz).
    radius_m : float
        Piston radius a (m).
    sound_speed_m_s : float
        c (m/s).

    Returns
    -------
    ndarray
        Signed directivity (1 on axis, negative in odd side lobes, 0 behind), broadcast shape.
    """
    from scipy.special import j1

    k = 2.0 * np.pi * np.asarray(frequency_hz, dtype=float) / float(sound_speed_m_s)
    x = k * float(radius_m) * np.sin(np.asarray(angle_rad, dtype=float))
    small = np.abs(x) < 1e-8
    safe = np.where(small, 1.0, x)
    # 2 J1(x)/x = 1 - x^2/8 + ... : the series is exact to 1e-17 below |x| = 1e-8
    front = np.cos(np.asarray(angle_rad, dtype=float)) >= 0.0
    return np.where(front, np.where(small, 1.0 - x * x / 8.0, 2.0 * j1(safe) / safe), 0.0)


__all__ = ["piston_directivity"]
