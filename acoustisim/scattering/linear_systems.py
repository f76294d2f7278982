"""Batched solution of the small boundary-condition systems of every order and frequency bin.

Method: the columns of a system mix Bessel functions of very different sizes (J_n of the
solid's argument may be 1e-50 where Y_n of the water's is 1e+50), so each system is
equilibrated first: every column is divided by its largest modulus, then every row by its
largest modulus (the solution of the scaled system, multiplied back by the column scales, is
the solution). ``numpy.linalg.solve`` then solves all (..., m, m) systems in one call (LU with
partial pivoting); its relative error is then about m times the condition number of the
equilibrated system times 1e-16.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

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
    """
    column_scale = np.max(np.abs(matrix), axis=-2, keepdims=True)
    column_scale = np.where(column_scale > 0.0, column_scale, 1.0)
    scaled = matrix / column_scale
    row_scale = np.max(np.abs(scaled), axis=-1, keepdims=True)
    row_scale = np.where(row_scale > 0.0, row_scale, 1.0)
    solution = np.linalg.solve(scaled / row_scale, (rhs[..., None] / row_scale))[..., 0]
    return solution / column_scale[..., 0, :]
