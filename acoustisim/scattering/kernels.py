"""Compiled loops of the modal series (numba, cached on disk): small linear systems and modal sums.

Each loop does per element what the numpy formulation in its caller's docstring states, without
the (bins, orders, m, m) and (rows, bins, orders) temporaries numpy needs.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ("downward_recurrence", "modal_sums", "solve_small_systems", "upward_recurrence")


@njit(cache=True, nogil=True)
def upward_recurrence(first: NDArray[np.complex128], second: NDArray[np.complex128], x: NDArray[np.complex128],
                      top: int, nu0: float) -> NDArray[np.complex128]:
    """Z_{nu0 + m}(x), m = 0..top, (n, top + 1), from Z_{nu0} = ``first`` and Z_{nu0 + 1} = ``second``
    by Z_{m+1} = 2 (m + nu0) / x Z_m - Z_{m-1} (:mod:`acoustisim.scattering.special`)."""
    n = x.size
    table = np.empty((n, top + 1), dtype=np.complex128)
    for i in range(n):
        inverse = 1.0 / x[i]
        previous = first[i]
        table[i, 0] = previous
        if top >= 1:
            current = second[i]
            table[i, 1] = current
            for m in range(1, top):
                following = 2.0 * (m + nu0) * inverse * current - previous
                table[i, m + 1] = following
                previous, current = current, following
    return table


@njit(cache=True, nogil=True)
def downward_recurrence(x: NDArray[np.complex128], top: int, start: int, nu0: float,
                        rescale: float) -> NDArray[np.complex128]:
    """Unnormalised J_{nu0 + m}(x), m = 0..top, (n, top + 1), by Miller's downward recurrence from
    order ``start`` (> top) with the values (0, 1e-30), rescaled by 1 / ``rescale`` whenever they
    pass ``rescale``; entries stored before a rescaling are rescaled with it (the caller
    normalises each row against two known orders; :func:`acoustisim.scattering.special`)."""
    n = x.size
    table = np.zeros((n, top + 1), dtype=np.complex128)
    for i in range(n):
        inverse = 1.0 / x[i]
        upper = 0.0 + 0.0j
        current = 1e-30 + 0.0j
        for m in range(start, 0, -1):
            if m <= top:
                table[i, m] = current
            lower = 2.0 * (m + nu0) * inverse * current - upper
            if abs(lower) > rescale:
                lower /= rescale
                current /= rescale
                for j in range(m, top + 1):
                    table[i, j] /= rescale
            upper, current = current, lower
        table[i, 0] = current
    return table


@njit(cache=True, nogil=True)
def _size(z: complex) -> float:
    """max(|Re z|, |Im z|): the modulus to within sqrt(2), without a square root."""
    return max(abs(z.real), abs(z.imag))


@njit(cache=True, nogil=True)
def solve_small_systems(matrix: NDArray[np.complex128], rhs: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """x with ``matrix[b] @ x[b] = rhs[b]`` for every b: (B, m) from (B, m, m) and (B, m).

    Each system is equilibrated (columns by their largest entry, then rows by theirs; an entry's
    size is max(|Re|, |Im|), the modulus to within sqrt 2) and solved by LU with partial pivoting
    on that size; the solution is scaled back by the column scales. A singular system (a zero
    pivot) gives NaN.
    """
    count, m = rhs.shape
    out = np.empty((count, m), dtype=np.complex128)
    a = np.empty((m, m), dtype=np.complex128)
    y = np.empty(m, dtype=np.complex128)
    column = np.empty(m)
    for b in range(count):
        for j in range(m):
            largest = 0.0
            for i in range(m):
                largest = max(largest, _size(matrix[b, i, j]))
            column[j] = 1.0 / largest if largest > 0.0 else 1.0
        for i in range(m):
            largest = 0.0
            for j in range(m):
                a[i, j] = matrix[b, i, j] * column[j]
                largest = max(largest, _size(a[i, j]))
            scale = 1.0 / largest if largest > 0.0 else 1.0
            for j in range(m):
                a[i, j] *= scale
            y[i] = rhs[b, i] * scale
        for k in range(m):
            pivot = k
            largest = _size(a[k, k])
            for i in range(k + 1, m):
                if _size(a[i, k]) > largest:
                    largest = _size(a[i, k])
                    pivot = i
            if pivot != k:
                for j in range(m):
                    a[k, j], a[pivot, j] = a[pivot, j], a[k, j]
                y[k], y[pivot] = y[pivot], y[k]
            if a[k, k] == 0.0:  # singular (a whole column underflowed): no solution
                break
            inverse = 1.0 / a[k, k]
            for i in range(k + 1, m):
                factor = a[i, k] * inverse
                for j in range(k + 1, m):
                    a[i, j] -= factor * a[k, j]
                y[i] -= factor * y[k]
        singular = False
        for k in range(m):
            singular = singular or a[k, k] == 0.0
        if singular:
            out[b, :] = np.nan
            continue
        for i in range(m - 1, -1, -1):
            total = y[i]
            for j in range(i + 1, m):
                total -= a[i, j] * out[b, j]
            out[b, i] = total / a[i, i]
        for j in range(m):
            out[b, j] *= column[j]
    return out


@njit(cache=True, nogil=True)
def modal_sums(spherical: bool, coefficients: NDArray[np.complex128], tops: NDArray[np.int64],
               which: NDArray[np.int64], start_s: NDArray[np.complex128], start_r: NDArray[np.complex128],
               x_s: NDArray[np.float64], x_r: NDArray[np.float64], cos_beta: NDArray[np.float64]
               ) -> NDArray[np.complex128]:
    """sum_{n <= top} w_n A_n Z_n(x_s) Z_n(x_r) X_n(beta) for every row r and column k: (R, K).

    ``coefficients`` (P, N) holds A_n of P frequencies, ``tops`` (P,) each one's highest order;
    element (r, k) uses frequency ``which[r, k]``. ``start_s``, ``start_r`` (2, R, K) are Z_0 and
    Z_1 at ``x_s``, ``x_r``; higher orders by Z_{n+1} = 2 (n + nu0) / x Z_n - Z_{n-1}
    (nu0 = 1/2 for spherical functions). w_n X_n: eps_n cos(n beta) (cylinder: eps_0 = 1, else
    2) or (2n + 1) P_n(cos beta) (sphere).
    """
    rows, columns = x_s.shape
    nu0 = 0.5 if spherical else 0.0
    out = np.zeros((rows, columns), dtype=np.complex128)
    for r in range(rows):
        c = cos_beta[r]
        beta = np.arccos(min(1.0, max(-1.0, c)))
        rotation = complex(np.cos(beta), np.sin(beta))
        for k in range(columns):
            p = which[r, k]
            top = tops[p]
            zs0, zs1 = start_s[0, r, k], start_s[1, r, k]
            zr0, zr1 = start_r[0, r, k], start_r[1, r, k]
            inverse_s, inverse_r = 1.0 / x_s[r, k], 1.0 / x_r[r, k]
            total = coefficients[p, 0] * zs0 * zr0
            # angular factors: P_n by Legendre's recurrence (stable for |c| <= 1), cos(n beta) as the
            # real part of e^{i n beta} by repeated rotation (rounding grows as n eps: 5e-14 at n = 500)
            x0, x1 = 1.0, c
            power = rotation
            for n in range(1, top + 1):
                if n >= 2:
                    zs0, zs1 = zs1, 2.0 * (n - 1 + nu0) * inverse_s * zs1 - zs0
                    zr0, zr1 = zr1, 2.0 * (n - 1 + nu0) * inverse_r * zr1 - zr0
                    if spherical:
                        x0, x1 = x1, ((2 * n - 1) * c * x1 - (n - 1) * x0) / n
                    else:
                        power = power * rotation
                weight = (2.0 * n + 1.0) * x1 if spherical else 2.0 * power.real
                a_n = coefficients[p, n]
                if a_n != 0.0:
                    total += a_n * zs1 * zr1 * weight
            out[r, k] = total
    return out
