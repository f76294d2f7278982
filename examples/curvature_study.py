"""The seed's curvature study (thesis section 4.3.2, cases 1-3): approximate vs exact circle fit.

A cylinder (circle in the horizontal plane) in front of the tri-aural head (d = 4 cm); the three
bistatic path lengths get Gaussian noise of 0.002 mm; each method estimates the radius, the range
(transmitter to the nearest point of the cylinder) and the angle (bearing of the centre):

- "approximate": the seed's tri-aural formulas, eqs. 4.37-4.44 as written (Peremans);
- "exact": the bistatic circle (Fermat) fitted by nonlinear least squares from the clipped
  tri-aural start (``binsonar.localization.circle.fit_circle``), replacing the seed's
  eleven-equation fsolve.

Case 1 varies the radius 0.3-1.5 m (step 0.1), case 2 the range 1.5-3 m (step 0.1), case 3 the
angle 1-12 deg (step 1); 10 noisy trials per value. The other two parameters of each case were
"randomly selected" in the seed, which lists the values it drew in its figure captions: case 1
range 3.05 m, angle 20.1 deg; case 2 radius 0.303 m, angle 7.23 deg; case 3 radius 0.66 m, range
3.91 m. Those are the default (``--fixed captions``); ``--fixed random`` draws them from the stated
ranges instead (range 1.5-3 m, angle 1-12 deg, radius 0.3-1.5 m).

Run:  python examples/curvature_study.py [--fixed captions|random] [--seed 0] [--json]
                                         [--figure docs/images/curvature_study.png]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from binsonar.localization.array_geometry import ArrayGeometry
from binsonar.localization.circle import circle_path_lengths, fit_circle, tri_aural_approximation

SEPARATION_M = 0.04
NOISE_M = 0.002e-3
TRIALS = 10
RADII = np.round(np.arange(0.3, 1.5001, 0.1), 10)
RANGES = np.round(np.arange(1.5, 3.0001, 0.1), 10)
ANGLES_DEG = np.arange(1.0, 12.001, 1.0)


def _truth(radius: float, range_m: float, angle_deg: float) -> tuple[np.ndarray, float]:
    th = np.radians(angle_deg)
    dist = range_m + radius
    return dist * np.array([np.sin(th), np.cos(th)]), radius


def _estimates(lengths: np.ndarray, geometry: ArrayGeometry) -> dict[str, tuple[float, float, float]]:
    """(radius, range, angle_deg) of both methods for one set of noisy path lengths."""
    xc, yc, rc = (float(v) for v in tri_aural_approximation(*lengths, SEPARATION_M))
    approx = (rc, float(np.hypot(xc, yc) - rc), float(np.degrees(np.arctan2(xc, yc))))
    fit = fit_circle(lengths, np.full(3, NOISE_M), geometry)
    if fit.ok:
        xe, ye, re = fit.parameters
        exact = (float(re), float(np.hypot(xe, ye) - re), float(np.degrees(np.arctan2(xe, ye))))
    else:
        exact = (np.nan, np.nan, np.nan)
    return {"approximate": approx, "exact": exact}


def run_case(name: str, varied: np.ndarray, make: callable, rng: np.random.Generator, geometry: ArrayGeometry) -> dict:
    """Absolute errors (values x trials) of radius, range and angle for both methods."""
    errors = {m: np.full((3, varied.size, TRIALS), np.nan) for m in ("approximate", "exact")}
    for i, v in enumerate(varied):
        radius, range_m, angle = make(v)
        centre, rc = _truth(radius, range_m, angle)
        clean, _ = circle_path_lengths(centre, rc, np.zeros((3, 3)), geometry.receivers_m)
        for k in range(TRIALS):
            est = _estimates(clean + NOISE_M * rng.standard_normal(3), geometry)
            for m, (r_est, d_est, a_est) in est.items():
                errors[m][:, i, k] = [abs(r_est - radius), abs(d_est - range_m), abs(a_est - angle)]
    return {"name": name, "varied": varied, "errors": errors}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fixed", choices=("captions", "random"), default="captions",
                        help="the parameters held fixed in each case: the seed's captions or random draws")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument("--figure", default=str(Path(__file__).resolve().parents[1] / "docs/images/curvature_study.png"))
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    geometry = ArrayGeometry.seed(SEPARATION_M)

    if args.fixed == "captions":
        r1, a1, rad2, a2, rad3, r3 = 3.05, 20.1, 0.303, 7.23, 0.66, 3.91
    else:
        r1, a1 = rng.uniform(1.5, 3.0), rng.uniform(1.0, 12.0)
        rad2, a2 = rng.uniform(0.3, 1.5), rng.uniform(1.0, 12.0)
        rad3, r3 = rng.uniform(0.3, 1.5), rng.uniform(1.5, 3.0)
    cases = [
        run_case(f"case 1: radius varied (range {r1:.2f} m, angle {a1:.1f} deg)", RADII, lambda v: (v, r1, a1), rng, geometry),
        run_case(f"case 2: range varied (radius {rad2:.2f} m, angle {a2:.1f} deg)", RANGES, lambda v: (rad2, v, a2), rng, geometry),
        run_case(f"case 3: angle varied (radius {rad3:.2f} m, range {r3:.2f} m)", ANGLES_DEG, lambda v: (rad3, r3, v), rng, geometry),
    ]
    summary = []
    for case in cases:
        row = {"case": case["name"]}
        for m, err in case["errors"].items():
            row[m] = {q: {"mean_abs": float(np.nanmean(err[j])), "max_abs": float(np.nanmax(err[j])),
                          "failures": int(np.isnan(err[j]).sum())}
                      for j, q in enumerate(("radius_m", "range_m", "angle_deg"))}
        summary.append(row)

    _figure(cases, args.figure)
    if args.json:
        print(json.dumps({"separation_m": SEPARATION_M, "noise_m": NOISE_M, "trials": TRIALS, "seed": args.seed,
                          "fixed": args.fixed,
                          "cases": summary, "figure": args.figure}))
    else:
        print(f"d = {SEPARATION_M} m, path noise {NOISE_M * 1e3} mm, {TRIALS} trials per value, "
              f"fixed parameters: {args.fixed}, seed {args.seed}")
        for row in summary:
            print(row["case"])
            for q, unit in (("radius_m", "m"), ("range_m", "m"), ("angle_deg", "deg")):
                a, e = row["approximate"][q], row["exact"][q]
                print(f"  {q:10s} mean |error|: approximate {a['mean_abs']:.3g} {unit}, exact {e['mean_abs']:.3g} {unit}"
                      f"  (failures {a['failures']} / {e['failures']})")
        print(f"figure: {args.figure}")
    return 0


def _figure(cases: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = ("radius error (m)", "range error (m)", "angle error (deg)")
    xlabels = ("radius (m)", "range (m)", "angle (deg)")
    fig, axes = plt.subplots(3, 3, figsize=(13, 10), constrained_layout=True)
    for i, case in enumerate(cases):
        for j in range(3):
            ax = axes[i, j]
            for m, style in (("approximate", dict(color="tab:red", marker="o", linestyle="--", mfc="none")),
                             ("exact", dict(color="tab:blue", marker="s", linestyle="-"))):
                err = case["errors"][m][j]
                ax.semilogy(case["varied"], np.nanmean(err, axis=1), label=f"{m} (mean |error|)", **style)
                ax.semilogy(np.repeat(case["varied"], err.shape[1]), err.ravel(), linestyle="none", marker=".",
                            color=style["color"], alpha=0.25)
            if j == 1:
                ax.text(0.02, 0.02, "range: both methods coincide (set by Mc)", transform=ax.transAxes, fontsize=8)
            ax.set_xlabel(xlabels[i])
            ax.set_ylabel(labels[j])
            ax.grid(True, which="both", alpha=0.3)
            if j == 0:
                ax.set_title(case["name"], loc="left", fontsize=10)
            if i == 0 and j == 0:
                ax.legend(fontsize=8)
    fig.suptitle(f"Curvature estimation, d = {SEPARATION_M * 100:.0f} cm, path noise {NOISE_M * 1e3} mm "
                 f"(seed's section 4.3.2): approximate (eqs. 4.37-4.44) vs exact bistatic circle fit")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
