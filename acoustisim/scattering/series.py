"""The common shape of a modal series: its coefficients, truncation and input checks.

A bin keeps the orders n <= ceil(Re(k a)) + ``extra_orders``; beyond n = k a the coefficients
of every body fall faster than exponentially (as J_n(x) / H_n(x)), so the default 30 extra orders
leave terms far below rounding (physics.md section 8; the convergence is shown in
``tests/physics/test_elastic_series.py``).
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acoustisim.errors import InputError

__all__ = ("DEFAULT_EXTRA_ORDERS", "ModalCoefficients", "Shape", "check_band", "order_keep_mask",
           "truncation_orders")

Shape = Literal["cylinder", "sphere"]

DEFAULT_EXTRA_ORDERS = 30
"""Orders kept beyond Re(k a) in each bin (physics.md section 8: "n up to about ka + 30")."""


class ModalCoefficients(NamedTuple):
    """The scattered-wave coefficients of a body at a set of frequencies.

    Attributes
    ----------
    shape : {"cylinder", "sphere"}
    orders : ndarray of int, shape (n_orders,)
        0, 1, ..., N.
    coefficients : ndarray of complex, shape (n_bins, n_orders)
        A_n (0 beyond each bin's truncation).
    wavenumber : ndarray, shape (n_bins,)
        The water's k (1/m).
    radius_m : float
        Outer radius a (m).
    """

    shape: Shape
    orders: NDArray[np.int64]
    coefficients: NDArray[np.complex128]
    wavenumber: NDArray[np.complex128]
    radius_m: float


def truncation_orders(ka: ArrayLike, extra_orders: int = DEFAULT_EXTRA_ORDERS) -> NDArray[np.int64]:
    """Highest order kept per bin: ceil(Re(k a)) + ``extra_orders``, shape of ``ka``."""
    return np.ceil(np.real(np.asarray(ka))).astype(np.int64) + int(extra_orders)


def order_keep_mask(ka: NDArray[np.complex128], extra_orders: int) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """The orders 0..N of the largest truncation and the (bins, orders) mask of kept ones."""
    highest = truncation_orders(ka, extra_orders)
    orders = np.arange(int(highest.max()) + 1)
    return orders, orders[None, :] <= highest[:, None]


def check_band(radius_m: float, frequencies_hz: ArrayLike) -> NDArray[np.float64]:
    """The frequencies (n_bins,) as floats, after checking them and the radius.

    Raises
    ------
    InputError
        A radius that is not finite and positive, or frequencies that are not a non-empty 1-D
        array of finite positive values.
    """
    if not (math.isfinite(radius_m) and radius_m > 0.0):
        raise InputError(f"radius_m = {radius_m!r}: must be finite and > 0")
    f = np.atleast_1d(np.asarray(frequencies_hz, dtype=float))
    if f.ndim != 1 or f.size == 0 or not np.all(np.isfinite(f) & (f > 0.0)):
        raise InputError(f"frequencies_hz: expected a non-empty 1-D array of finite frequencies > 0, got {f!r}")
    return f
