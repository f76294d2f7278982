"""Batched solution of the small boundary-condition systems of every order and frequency bin.

Method: the columns of a system mix Bessel functions of very different sizes (J_n of the
solid's argument may be 1e-50 where Y_n of the water's is 1e+50), so each system is
equilibrated first: every column is divided by its largest modulus, then every row by its
largest modulus (the solution of the scaled system, multiplied back by the column scales, is
the solution). ``numpy.linalg.solve`` then solves all (..., m, m) systems in one call (LU with
partial pivoting); its relative error is then about m times the condition number of the
equilibrated system times 1e-16. The loop over systems is compiled
(:func:`acoustisim.scattering.kernels.solve_small_systems`: the same equilibration and LU with
partial pivoting per system, without the batched temporaries).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.scattering.kernels import solve_small_systems

__all__ = ("solve_equilibrated",)


def solve_equilibrated(matrix: NDArray[np.complex128], rhs: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """Solve ``matrix @ x = rhs`` for every leading index.

    Parameters
    ----------
    matrix : ndarray, shape (..., m, m)
    rhs : ndarray, shape (..., m)

    Returns
    -------
    ndarray, shape (..., m)

    Raises
    ------
    InputError
        A singular system (a zero pivot after equilibration).
    """
    m = matrix.shape[-1]
    flat = np.ascontiguousarray(np.broadcast_to(matrix, rhs.shape[:-1] + (m, m)), dtype=complex).reshape(-1, m, m)
    solution = solve_small_systems(flat, np.ascontiguousarray(rhs, dtype=complex).reshape(-1, m))
    if np.isnan(solution).any():
        raise InputError("modal series: a boundary system is singular (its Bessel functions underflow: the body "
                         "is beyond the series' reach at these frequencies)")
    return solution.reshape(rhs.shape)
