"""A fitted model: parameters, covariance, residuals and a status, never an exception.

``weighted_least_squares`` wraps ``scipy.optimize.least_squares`` so that any numerical failure
(non-finite residuals, a singular Jacobian, no convergence) becomes a status on the result.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

# Status values of a fit.
OK = "ok"
FIT_FAILED = "fit-failed"
NOT_CONVERGED = "not-converged"
INVALID_INPUT = "invalid-input"
SINGULAR = "singular"


@dataclass(frozen=True, eq=False)
class ModelFit:
    """One model fitted to path lengths.

    Attributes
    ----------
    model : str
        "point", "circle", "plane", "tri-aural" (the seed's approximation) ...
    parameter_names : tuple of str
        Names (with units) of the parameters.
    parameters : ndarray, shape (k,)
        Estimates (NaN when the fit failed).
    covariance : ndarray, shape (k, k)
        Linearised covariance (J^T W J)^-1 with W = diag(1 / sigma^2); inf on the diagonal where
        not observable, NaN when the fit failed.
    residuals_m : ndarray, shape (m,)
        Measured minus modelled path lengths (m).
    chi2 : float
        Sum of squared normalised residuals.
    dof : int
        Measurements minus parameters.
    status : str
        "ok" or the reason it is not (see module constants).
    message : str
        Human-readable detail.
    n_evaluations : int
        Model evaluations the solver used.
    """

    model: str
    parameter_names: tuple[str, ...]
    parameters: NDArray[np.float64] = field(repr=False)
    covariance: NDArray[np.float64] = field(repr=False)
    residuals_m: NDArray[np.float64] = field(repr=False)
    chi2: float = float("nan")
    dof: int = 0
    status: str = OK
    message: str = ""
    n_evaluations: int = 0

    @property
    def ok(self) -> bool:
        """True when the fit produced usable estimates."""
        return self.status == OK

    @property
    def std(self) -> NDArray[np.float64]:
        """Standard deviations (k,) of the parameters."""
        return np.sqrt(np.abs(np.diag(self.covariance)))

    def value(self, name: str) -> float:
        """One parameter by name."""
        return float(self.parameters[self.parameter_names.index(name)])

    def std_of(self, name: str) -> float:
        """One parameter's standard deviation by name."""
        return float(self.std[self.parameter_names.index(name)])

    @classmethod
    def failed(cls, model: str, names: tuple[str, ...], n_measurements: int, status: str, message: str) -> "ModelFit":
        """A fit that produced nothing usable."""
        k = len(names)
        return cls(model, names, np.full(k, np.nan), np.full((k, k), np.nan), np.full(n_measurements, np.nan),
                   float("nan"), n_measurements - k, status, message)


def covariance_from_jacobian(jacobian: ArrayLike, sigma: ArrayLike) -> tuple[NDArray[np.float64], bool]:
    """(J^T W J)^-1 for residual Jacobian J (m, k) and measurement std sigma (m,).

    Returns the covariance (k, k) and whether it is well conditioned. Directions the data do not
    constrain (relative singular value below 1e-12) get infinite variance.
    """
    j = np.asarray(jacobian, dtype=float) / np.asarray(sigma, dtype=float)[:, None]
    k = j.shape[1]
    if not np.all(np.isfinite(j)):
        return np.full((k, k), np.nan), False
    _, s, vt = np.linalg.svd(j, full_matrices=False)
    if s.size < k:
        s = np.concatenate([s, np.zeros(k - s.size)])
        vt = np.vstack([vt, np.zeros((k - vt.shape[0], k))])
    good = s > 1e-12 * s.max() if s.max() > 0 else np.zeros(k, dtype=bool)
    inv_s2 = np.where(good, 1.0 / np.where(good, s, 1.0) ** 2, 0.0)
    cov = (vt.T * inv_s2) @ vt
    if not np.all(good):
        # Unconstrained directions: infinite variance along the parameters they involve.
        bad_params = np.any(np.abs(vt[~good]) > 1e-6, axis=0)
        cov = cov.copy()
        cov[bad_params, :] = np.nan
        cov[:, bad_params] = np.nan
        cov[bad_params, bad_params] = np.inf
    return cov, bool(np.all(good))


def weighted_least_squares(
    model: str,
    names: tuple[str, ...],
    predict: Callable[[NDArray[np.float64]], tuple[NDArray[np.float64], NDArray[np.float64]]],
    measured_m: ArrayLike,
    sigma_m: ArrayLike,
    x0: ArrayLike,
    *,
    lower: ArrayLike | None = None,
    upper: ArrayLike | None = None,
    x_scale: ArrayLike | str = "jac",
    max_nfev: int = 200,
) -> ModelFit:
    """Fit parameters x so that ``predict(x)`` matches the measured path lengths.

    Parameters
    ----------
    model, names : str, tuple of str
        Labels of the result.
    predict : callable
        x (k,) -> (modelled path lengths (m,), Jacobian d modelled / d x (m, k)).
    measured_m, sigma_m : array_like, shape (m,)
        Measured path lengths and their standard deviations (m).
    x0 : array_like, shape (k,)
        Start.
    lower, upper : array_like, shape (k,), optional
        Bounds (default unbounded).
    x_scale : array_like or "jac"
        Passed to ``scipy.optimize.least_squares``.
    max_nfev : int
        Evaluation budget; exceeding it gives status "not-converged".
    """
    from scipy.optimize import least_squares

    y = np.asarray(measured_m, dtype=float)
    s = np.asarray(sigma_m, dtype=float)
    x0 = np.asarray(x0, dtype=float)
    k, m = x0.size, y.size
    if not (np.all(np.isfinite(y)) and np.all(np.isfinite(s)) and np.all(s > 0)):
        return ModelFit.failed(model, names, m, INVALID_INPUT, "path lengths or their std are not finite and positive")
    if not np.all(np.isfinite(x0)):
        return ModelFit.failed(model, names, m, INVALID_INPUT, "no valid starting point")
    lo = np.full(k, -np.inf) if lower is None else np.asarray(lower, dtype=float)
    hi = np.full(k, np.inf) if upper is None else np.asarray(upper, dtype=float)
    x0 = np.clip(x0, lo, hi)
    # least_squares needs a strictly feasible start for the trf method.
    span = np.where(np.isfinite(hi - lo), hi - lo, 1.0)
    x0 = np.where(x0 <= lo, lo + 1e-9 * np.maximum(span, 1e-3), x0)
    x0 = np.where(x0 >= hi, hi - 1e-9 * np.maximum(span, 1e-3), x0)

    cache: dict[bytes, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}

    def evaluate(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        # least_squares asks for the residuals and the Jacobian at the same x: model once.
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = predict(x)
        return cache[key]

    def fun(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return (evaluate(x)[0] - y) / s

    def jac(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return evaluate(x)[1] / s[:, None]

    try:
        with np.errstate(all="ignore"):
            res = None
            if m >= k:
                # Levenberg-Marquardt (MINPACK) first: fast; kept when it lands inside the bounds.
                res = least_squares(fun, x0, jac=jac, method="lm", x_scale=x_scale,
                                    xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=max_nfev)
                if not (np.all(np.isfinite(res.x)) and np.all(res.x >= lo) and np.all(res.x <= hi)
                        and np.all(np.isfinite(res.fun)) and res.status > 0):
                    res = None
            if res is None:
                res = least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale=x_scale,
                                    xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=max_nfev)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError) as exc:
        return ModelFit.failed(model, names, m, FIT_FAILED, f"{model} fit failed: {exc}")
    x = res.x
    pred, j = predict(x)
    if not (np.all(np.isfinite(pred)) and np.all(np.isfinite(j)) and np.all(np.isfinite(x))):
        return ModelFit.failed(model, names, m, FIT_FAILED, f"{model} fit failed: model not finite at the solution")
    resid = y - pred
    chi2 = float(np.sum((resid / s) ** 2))
    cov, well = covariance_from_jacobian(j, s)
    status, message = OK, ""
    if res.status == 0:
        # Budget exhausted: accept only if the gradient is negligible (converged to rounding).
        g = np.abs(j.T @ (resid / s**2))
        scale = np.abs(j).T @ (np.abs(y) / s**2) + 1e-300
        if not np.all(g <= 1e-8 * scale):
            status, message = NOT_CONVERGED, f"{model} fit did not converge in {max_nfev} evaluations"
    elif res.status < 0:
        status, message = FIT_FAILED, f"{model} fit failed: {res.message}"
    if status == OK and not well:
        message = f"{model} fit: some parameters are not observable (infinite variance)"
    return ModelFit(model, names, x.copy(), cov, resid, chi2, m - k, status, message, int(res.nfev))
