"""Point, cylinder, plane or unknown: which model the path lengths support, given their noise.

Each model's weighted residual chi2 is tested against the chi-square distribution with its
degrees of freedom (goodness of fit at significance ``alpha``). The circle contains the point
(rc = 0) and the plane (rc -> infinity) as limits, so it always fits at least as well; it is
preferred to a simpler accepted model only when the drop in chi2 is significant (likelihood
ratio with one degree of freedom). From one ping (three path lengths) the circle has zero
degrees of freedom and this reduces to Peremans' use of the curvature: "point" while the data
are consistent with rc = 0, "plane" while consistent with rc = infinity, "cylinder" otherwise.
"""

from __future__ import annotations

from binsonar.localization.fit import ModelFit

POINT, CYLINDER, PLANE, UNKNOWN = "point", "cylinder", "plane", "unknown"


def chi2_threshold(dof: int, alpha: float) -> float:
    """Upper (1 - alpha) quantile of chi-square with ``dof`` degrees of freedom (dof >= 1)."""
    from scipy.special import chdtri

    return float(chdtri(max(int(dof), 1), alpha))


def fits_within_noise(fit: ModelFit | None, alpha: float) -> bool:
    """Goodness of fit: the fit succeeded and its chi2 is below the (1 - alpha) quantile.

    A fit with zero degrees of freedom is accepted when its chi2 is below the one-degree
    threshold (it is non-zero only when a bound, such as rc >= 0, is active).
    """
    if fit is None or not fit.ok:
        return False
    return fit.chi2 <= chi2_threshold(fit.dof, alpha)


def classify(point: ModelFit | None, circle: ModelFit | None, plane: ModelFit | None,
             alpha: float = 0.01, prefer: str | None = None) -> tuple[str, str]:
    """Class of a target from its model fits.

    Parameters
    ----------
    point, circle, plane : ModelFit or None
        The fits (None when not attempted).
    alpha : float
        Significance of the tests (probability of rejecting a true model).
    prefer : {"point", "plane"}, optional
        The class other evidence supports (the echo's shape: a sharp edge's diffraction is a
        point, ``beam_targets``), taken when point and plane both fit; otherwise the smaller
        chi2 decides.

    Returns
    -------
    cls : str
        "point", "cylinder", "plane" or "unknown".
    reason : str
        One line explaining the decision ("ambiguous: ..." when point and plane both fit).
    """
    simple = {name: fit for name, fit in ((POINT, point), (PLANE, plane)) if fits_within_noise(fit, alpha)}
    dof_ok = any(f is not None and f.ok and f.dof >= 1 for f in (point, plane))
    if not dof_ok and not (circle is not None and circle.ok and circle.dof >= 1):
        return UNKNOWN, "too few path lengths to test any model (need three per ping)"
    circle_ok = fits_within_noise(circle, alpha)
    if circle_ok and circle is not None:
        threshold = chi2_threshold(1, alpha)
        if all(fit.chi2 - circle.chi2 > threshold for fit in simple.values()):
            if circle.value("rc_m") <= 0.0:
                return UNKNOWN, "the circle fit wants a negative radius (concave reflector?)"
            return CYLINDER, f"point and plane rejected against the circle (chi2 {_chi2s(point, circle, plane)})"
    if simple:
        best = min(simple, key=lambda k: simple[k].chi2)
        if len(simple) > 1:
            if prefer in simple:
                return str(prefer), (f"ambiguous: point and plane both fit (chi2 {_chi2s(point, circle, plane)}); "
                                     f"{prefer} by the echo's shape")
            return best, f"ambiguous: point and plane both fit (chi2 {_chi2s(point, circle, plane)})"
        return best, f"{best} fits within noise (chi2 {_chi2s(point, circle, plane)})"
    return UNKNOWN, f"no model fits within noise (chi2 {_chi2s(point, circle, plane)})"


def _chi2s(point: ModelFit | None, circle: ModelFit | None, plane: ModelFit | None) -> str:
    parts = []
    for name, fit in (("point", point), ("circle", circle), ("plane", plane)):
        if fit is not None and fit.ok:
            parts.append(f"{name} {fit.chi2:.3g}/{fit.dof}")
    return ", ".join(parts) or "none"
