"""Upper tail of a weighted sum of independent unit exponentials, X = sum_i lambda_i E_i.

This is the law of any Hermitian quadratic form z^H A z of circular complex Gaussian noise
(lambda: the eigenvalues of A C). Its far tail is governed by the largest lambda, which a
moment-matched Gamma law underestimates; the Lugannani-Rice saddle-point formula is accurate
to a few per cent there:

    K(s) = -sum ln(1 - s lambda_i)        (cumulant generating function, s < 1 / max lambda)
    K'(s_hat) = x,  w = sign(s_hat) sqrt(2 (s_hat x - K(s_hat))),  u = s_hat sqrt(K''(s_hat))
    P(X > x) ~ Q(w) + phi(w) (1/u - 1/w)
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray


def _saddle(x: float, lam: NDArray[np.float64]) -> float:
    """s with K'(s) = x (K' increases from 0 at s -> -inf to inf at s -> 1/max lambda)."""
    high = 1.0 / lam.max()
    low = -1.0
    while np.sum(lam / (1.0 - low * lam)) > x:  # widen the bracket to the left
        low *= 2.0
    hi = high * (1.0 - 1e-15)
    for _ in range(200):  # bisection on a scalar
        mid = 0.5 * (low + hi)
        if np.sum(lam / (1.0 - mid * lam)) < x:
            low = mid
        else:
            hi = mid
        if hi - low <= 1e-14 * max(1.0, abs(mid)):
            break
    return 0.5 * (low + hi)


def exceedance(x: float, lam: NDArray[np.float64]) -> float:
    """P(X > x) for X = sum lambda_i E_i, lambda_i > 0 (saddle-point approximation)."""
    from scipy.special import ndtr

    lam = np.asarray(lam, dtype=float)
    mean = float(lam.sum())
    if x <= 0:
        return 1.0
    s = _saddle(x, lam)
    k = float(-np.sum(np.log1p(-s * lam)))
    k2 = float(np.sum(lam ** 2 / (1.0 - s * lam) ** 2))
    if abs(x - mean) < 1e-9 * mean:
        return 0.5  # the formula's removable singularity at the mean; tails are what matter
    w = math.copysign(math.sqrt(max(2.0 * (s * x - k), 0.0)), s)
    u = s * math.sqrt(k2)
    density = math.exp(-0.5 * w * w) / math.sqrt(2.0 * math.pi)
    return float(min(max(ndtr(-w) + density * (1.0 / u - 1.0 / w), 0.0), 1.0))


def quantile(p: float, lam: NDArray[np.float64]) -> float:
    """x with P(X > x) = p (for p below 0.5), by bisection on ``exceedance``."""
    lam = np.asarray(lam, dtype=float)
    low = float(lam.sum())
    high = 2.0 * low
    while exceedance(high, lam) > p:  # doubling until bracketed
        high *= 2.0
    for _ in range(100):  # bisection on a scalar
        mid = 0.5 * (low + high)
        if exceedance(mid, lam) > p:
            low = mid
        else:
            high = mid
        if high - low <= 1e-10 * high:
            break
    return 0.5 * (low + high)
