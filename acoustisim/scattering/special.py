"""Cylinder and spherical Bessel functions of all orders at once, with their derivatives.

Method: recurrences over the order, vectorised over the arguments (scipy.special gives only
the two starting orders; one scipy call per order and argument costs about 1 us, 100 times the
recurrence step). With nu0 = 0 (cylinder) or 1/2 (spherical; z_n(x) = sqrt(pi / (2 x))
Z_{n+1/2}(x), the factor cancels in the linear recurrence)
Z_{m+1} = (2 (m + nu0) / x) Z_m - Z_{m-1} for J, Y and H alike:

- Y and H upward from scipy's orders nu0 and nu0 + 1: stable (Y grows with the order beyond
  x, and no solution dominates below it);
- J upward too where every order lies below |x| (no solution dominates there), elsewhere
  downward (Miller's algorithm): from an order well above max(N, |x|) with arbitrary
  start values, rescaled against overflow, normalised by scipy's two lowest orders (least
  squares over both, so that a zero of one does not spoil it); the minimal solution, so the
  error decays going down.

Derivatives from Z_n' = (n / x) Z_n - Z_{n+1} (cylinder) and z_n' = (n / x) z_n - z_{n+1}
(spherical), valid for n >= 0 and free of cancellation where n > x. Arguments may be complex
(lossy media). Entries whose order is masked out (beyond a bin's truncation) are replaced by 1,
so that huge Y_n of small arguments never reach the arithmetic.

Accuracy: relative errors of about 1e-14 against ``scipy.special`` (``jv``, ``yv``,
``hankel1``, ``spherical_jn``, ``spherical_yn``) over the orders and arguments used here
(``tests/physics/test_elastic_series.py``).
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy import special

from acoustisim.scattering.kernels import downward_recurrence, upward_recurrence

__all__ = ("BesselPair", "bessel_pair", "bessel_table")

Kind = Literal["J", "Y", "H"]


class BesselPair(NamedTuple):
    """Z_n(x) and Z_n'(x), each (n_bins, n_orders)."""

    value: NDArray[np.complex128]
    derivative: NDArray[np.complex128]


def _start(kind: Kind, order: float, x: NDArray[np.complex128]) -> NDArray[np.complex128]:
    if kind == "J":
        return special.jv(order, x)
    if kind == "Y":
        return special.yv(order, x)
    return special.hankel1(order, x)


_MILLER_MARGIN = 40
"""Orders above max(N + 1, |x|) where Miller's downward recurrence starts (the start's error
falls by more than 1e-15 over that margin)."""

_RESCALE = 1e100
"""Downward-recurrence values above this are rescaled (the higher orders then underflow to 0,
which they are relative to the lower ones)."""


def _upward(kind: Kind, top: int, x: NDArray[np.complex128], nu0: float) -> NDArray[np.complex128]:
    """Z_{nu0 + m}(x), m = 0..top, (n_bins, top + 1), by upward recurrence (compiled loop)."""
    return upward_recurrence(np.ascontiguousarray(_start(kind, nu0, x), dtype=complex),
                             np.ascontiguousarray(_start(kind, nu0 + 1.0, x), dtype=complex),
                             np.ascontiguousarray(x, dtype=complex), int(top), float(nu0))


def _miller(top: int, x: NDArray[np.complex128], nu0: float) -> NDArray[np.complex128]:
    """J_{nu0 + m}(x), m = 0..top, (n_bins, top + 1), by Miller's downward recurrence (compiled
    loop, rescaled against overflow: values past _RESCALE are divided by it, with every order
    already stored), normalised by scipy's two lowest orders."""
    start = max(top, int(np.ceil(np.max(np.abs(x))))) + _MILLER_MARGIN
    table = downward_recurrence(np.ascontiguousarray(x, dtype=complex), int(top), int(start), float(nu0), _RESCALE)
    size = np.maximum(np.abs(table[:, 0]), np.abs(table[:, 1]))
    r0, r1 = table[:, 0] / size, table[:, 1] / size
    reference0, reference1 = special.jv(nu0, x), special.jv(nu0 + 1.0, x)
    norm = (reference0 * np.conj(r0) + reference1 * np.conj(r1)) / (np.abs(r0) ** 2 + np.abs(r1) ** 2)
    return table * (norm / size)[:, None]


def bessel_table(kind: Kind, top: int, x: NDArray[np.complex128], *, spherical: bool = False) -> NDArray[np.complex128]:
    """Z_n(x) (or z_n(x)) for n = 0..top, shape (n_bins, top + 1)."""
    x = np.asarray(x, dtype=complex).ravel()
    nu0 = 0.5 if spherical else 0.0
    with np.errstate(all="ignore"):
        if kind == "J":
            # upward is stable where every order lies below the argument (oscillatory region)
            table = np.empty((x.size, top + 1), dtype=complex)
            above = np.abs(x) > top + 1
            if np.any(above):
                table[above] = _upward("J", top, x[above], nu0)
            if not np.all(above):
                table[~above] = _miller(top, x[~above], nu0)
        else:
            table = _upward(kind, top, x, nu0)
        if spherical:
            table = table * np.sqrt(0.5 * np.pi / x)[:, None]
    return table


def bessel_pair(kind: Kind, orders: NDArray[np.int64], x: NDArray[np.complex128], *, spherical: bool = False,
                keep: NDArray[np.bool_] | None = None) -> BesselPair:
    """Z_n(x) and Z_n'(x) for n in ``orders`` (0, 1, ..., N: consecutive from 0).

    Parameters
    ----------
    kind : {"J", "Y", "H"}
        Bessel, Neumann or Hankel (first kind, outgoing for exp(-i w t)).
    orders : ndarray of int, shape (n_orders,)
        0, 1, ..., N.
    x : ndarray, shape (n_bins,)
        Arguments (real or complex, non-zero).
    spherical : bool
        Spherical functions j, y, h instead.
    keep : ndarray of bool, shape (n_bins, n_orders), optional
        Entries to keep; the others are set to 1.

    Returns
    -------
    BesselPair
    """
    x = np.asarray(x, dtype=complex).ravel()
    table = bessel_table(kind, int(orders[-1]) + 1, x, spherical=spherical)
    with np.errstate(all="ignore"):
        value = table[:, :-1]
        derivative = orders[None, :] / x[:, None] * value - table[:, 1:]
    if keep is not None:
        value = np.where(keep, value, 1.0)
        derivative = np.where(keep, derivative, 1.0)
    return BesselPair(value, derivative)
