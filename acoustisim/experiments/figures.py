"""Figures shared by the experiments (matplotlib, Agg backend, no display)."""

from __future__ import annotations

from types import MappingProxyType
from typing import Any, Sequence

import numpy as np

COLOURS = MappingProxyType({"threshold": "tab:orange", "matched": "tab:blue", "beam-matched": "tab:red", "bound": "0.3"})


def new_figure(n_rows: int, n_cols: int = 1, *, width: float = 7.5, row_height: float = 2.6) -> tuple[Any, Any]:
    """A figure and its axes array (squeezed), drawn with the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(n_rows, n_cols, figsize=(width, row_height * n_rows), squeeze=False,
                             constrained_layout=True)
    return fig, axes


def sweep_figure(x: Sequence[float], positions: list[dict[str, Any]], detectors: Sequence[str], *, xlabel: str,
                 title: str) -> Any:
    """Range and bearing RMS error against the swept variable, with the CRLB-derived bound, and times.

    Parameters
    ----------
    x : sequence of float
        The swept variable at each position.
    positions : list of dict
        ``sweep_summary.summarise(...)["positions"]``.
    detectors : sequence of str
    xlabel, title : str
    """
    fig, axes = new_figure(3, 1, row_height=2.4)
    ax_r, ax_b, ax_t = axes[:, 0]
    xs = np.asarray(x, dtype=float)
    for m in detectors:
        r = np.array([p[m]["range_rms_m"] for p in positions], dtype=float) * 1e3
        b = np.array([p[m]["bearing_rms_deg"] for p in positions], dtype=float)
        t = np.array([p[m].get("cpu_s", p[m]["elapsed_s"]) for p in positions], dtype=float) * 1e3
        ax_r.semilogy(xs, r, "o-", ms=3, color=COLOURS.get(m), label=f"{m} (RMS)")
        ax_b.semilogy(xs, b, "o-", ms=3, color=COLOURS.get(m), label=f"{m} (RMS)")
        ax_t.plot(xs, t, "o-", ms=3, color=COLOURS.get(m), label=m)
        missed = np.array([p[m]["detection_rate"] < 1.0 for p in positions])
        if missed.any():
            ax_r.plot(xs[missed], np.full(missed.sum(), ax_r.get_ylim()[1] if np.isfinite(r).any() else 1.0), "x",
                      color=COLOURS.get(m), label=f"{m} missed")
    bound_r = np.array([p["bound_range_m"] for p in positions], dtype=float) * 1e3
    bound_b = np.array([p["bound_bearing_deg"] for p in positions], dtype=float)
    ax_r.semilogy(xs, bound_r, "--", color=COLOURS["bound"], label="CRLB-derived bound, noise only (1 sigma)")
    ax_r.semilogy(xs, 1.5 * bound_r, ":", color=COLOURS["bound"], label="1.5 x bound, noise only")
    reverb_r = np.array([p.get("reverb_bound_range_m", np.nan) for p in positions], dtype=float) * 1e3
    if np.isfinite(reverb_r).any():
        # The same CRLB with the reverberation's level at the echo as Gaussian interference.
        ax_r.semilogy(xs, 1.5 * reverb_r, "-.", color="tab:brown", lw=1,
                      label="1.5 x bound with reverberation")
    ax_b.semilogy(xs, bound_b, "--", color=COLOURS["bound"], label="CRLB-derived bound (1 sigma)")
    ax_b.semilogy(xs, 1.5 * bound_b, ":", color=COLOURS["bound"], label="1.5 x bound")
    ax_r.set_ylabel("range error (mm)")
    ax_b.set_ylabel("bearing error (deg)")
    ax_t.set_ylabel("detection CPU time\nper position (ms)")
    ax_t.set_xlabel(xlabel)
    ax_r.set_title(title, fontsize=10)
    for ax in (ax_r, ax_b, ax_t):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    return fig
