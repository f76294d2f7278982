"""The demo's figures: channels with labelled echoes, matched-filter outputs, top view with ellipses."""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray

from acoustisim.experiments.figures import new_figure

CHANNELS = ("left", "centre", "right")
KIND_COLOURS = MappingProxyType({"target": "tab:red", "multipath": "tab:purple", "tank": "tab:gray"})


def _colour(label: str) -> str:
    if " via " in label or "+" in label.split(" via ")[0]:
        return KIND_COLOURS["multipath"]
    if label.startswith(("wall", "floor", "surface")) or label in ("unexplained",):
        return KIND_COLOURS["tank"]
    return KIND_COLOURS["target"]


def channels_figure(waveforms: NDArray[np.float64], sample_rate_hz: float, blanking_s: float,
                    echoes: Sequence[tuple[int, float, str]], arrivals: Any, labels: Sequence[str]) -> Any:
    """The three channels of the averaged ping, with the main bang, the blanking and the echoes labelled.

    Parameters
    ----------
    waveforms : ndarray, shape (3, n_samples)
        Averaged volts from t = 0 (the trigger).
    sample_rate_hz : float
    blanking_s : float
    echoes : sequence of (channel, tof_s, label)
        The localised targets' echoes.
    arrivals, labels
        Ground truth (``Paths.arrivals()``) and its labels, for the direct path (cross-talk).
    """
    fig, axes = new_figure(3, 1, width=11.0, row_height=2.5)
    t_ms = np.arange(waveforms.shape[1]) / sample_rate_hz * 1e3
    i0 = int(blanking_s * sample_rate_hz)
    for ch in range(3):
        ax = axes[ch, 0]
        ax.plot(t_ms, waveforms[ch], lw=0.4, color="k")
        after = np.abs(waveforms[ch, i0:]).max() if waveforms.shape[1] > i0 else 1.0
        ax.set_ylim(-1.3 * after, 1.6 * after)
        ax.axvspan(0, blanking_s * 1e3, color="0.85", zorder=0)
        direct = arrivals[(arrivals["channel"] == ch) & (arrivals["kind"] == 0)]
        bang = "main bang" + (f" + cross-talk ({direct['delay_s'][0] * 1e6:.0f} us)" if direct.size and ch != 1 else "")
        ax.text(blanking_s * 1e3, 1.45 * after, f" {bang}: blanked (off scale)", fontsize=7, va="top", color="0.3")
        span_ms = float(t_ms[-1] - t_ms[0]) if t_ms.size > 1 else 1.0
        char_ms = span_ms / 180.0  # rough width of one 6.5 pt character on this 11-inch axis
        mine = [(tof, lab) for c, tof, lab in echoes if c == ch]
        for tof, lab in mine:
            ax.axvline(tof * 1e3, color=_colour(lab), lw=0.8, alpha=0.7)
        # Labels: objects' own echoes first, then multipaths, then the tank; each on the first of
        # five rows where it does not overlap a label already written; dropped when none is free.
        rank = {KIND_COLOURS["target"]: 0, KIND_COLOURS["multipath"]: 1, KIND_COLOURS["tank"]: 2}
        rows: list[list[tuple[float, float]]] = [[] for _ in range(5)]
        written: set[tuple[str, int]] = set()
        for tof, lab in sorted(mine, key=lambda e: (rank[_colour(e[1])], e[0])):
            x0 = tof * 1e3
            x1 = x0 + (len(lab) + 1) * char_ms
            key = (lab, int(x0 / (0.5 * span_ms / 10)))
            if key in written:
                continue  # the same name just written nearby
            for level, row in enumerate(rows):
                if all(x1 < a or x0 > b for a, b in row):
                    row.append((x0, x1))
                    written.add(key)
                    ax.text(x0, (1.2 - 0.17 * level) * after, " " + lab, fontsize=6.5, color=_colour(lab),
                            va="bottom")
                    break
        ax.set_ylabel(f"{CHANNELS[ch]} (V)")
        ax.grid(True, alpha=0.3)
    axes[0, 0].set_title("Averaged ping, three channels; echoes of the localised targets named from the "
                         "ground-truth arrivals (red: targets, purple: multipaths, grey: tank)", fontsize=9)
    axes[2, 0].set_xlabel("time after the transmit trigger (ms)")
    return fig


def matched_figure(averaged: NDArray[np.float64], recording: Any, echoes: Sequence[tuple[int, float, str]]) -> Any:
    """binsonar's matched-filter output |z|^2 over its noise mean (dB) on each channel, detections marked.

    Parameters
    ----------
    averaged : ndarray, shape (3, n)
        The gated, averaged ping (V).
    recording : Recording
        The gated recording (sample rate, t0_s, template).
    echoes : sequence of (channel, tof_s, label)
    """
    from binsonar.detection.inputs import as_signals, resolve_template
    from binsonar.detection.matched import envelope, filtered_spectrum, noise_mean_power, plan_matched

    signals = as_signals(recording)
    template = resolve_template(None, signals, "matched")
    fs = recording.sample_rate_hz
    plan = plan_matched(template, averaged.shape[1], fs)
    z = envelope(plan, filtered_spectrum(plan, averaged))
    power = z.real ** 2 + z.imag ** 2
    level_db = 10 * np.log10(power / noise_mean_power(power)[:, None])
    lags = np.arange(power.shape[1]) * plan.decimation
    t_ms = plan.lag_to_tof(lags, recording.t0_s) * 1e3
    fig, axes = new_figure(3, 1, width=11.0, row_height=2.3)
    for ch in range(3):
        ax = axes[ch, 0]
        ax.plot(t_ms, level_db[ch], lw=0.5, color="tab:blue")
        for c, tof, lab in echoes:
            if c == ch:
                ax.plot(tof * 1e3, np.interp(tof * 1e3, t_ms, level_db[ch]), "v", ms=4, color=_colour(lab))
        ax.set_ylim(-10, max(10.0, float(level_db[ch].max()) + 5))
        ax.set_ylabel(f"{CHANNELS[ch]}\n|z|^2 / noise (dB)")
        ax.grid(True, alpha=0.3)
    axes[0, 0].set_title("Matched-filter output (binsonar.detection.matched) of the averaged ping; "
                         "triangles: echoes used by the localised targets", fontsize=9)
    axes[2, 0].set_xlabel("time of flight (ms)")
    return fig


def _ellipse(ax: Any, centre: Sequence[float], cov: NDArray[np.float64], n_sigma: float, scale: float, **kw: Any) -> None:
    from matplotlib.patches import Ellipse

    c2 = np.asarray(cov, dtype=float)[:2, :2]
    if not np.all(np.isfinite(c2)):
        return
    values, vectors = np.linalg.eigh(c2)
    values = np.maximum(values, 0.0)
    angle = math.degrees(math.atan2(vectors[1, 1], vectors[0, 1]))
    ax.add_patch(Ellipse((centre[0], centre[1]), 2 * n_sigma * math.sqrt(values[1]) * scale,
                         2 * n_sigma * math.sqrt(values[0]) * scale, angle=angle, fill=False, **kw))


def _outline(obj: Any, z: float) -> NDArray[np.float64] | None:
    """The object's cross-section at height z as a closed polygon (convex hull of the slice)."""
    try:
        section = obj.mesh.section(plane_origin=(0.0, 0.0, z), plane_normal=(0.0, 0.0, 1.0))
    except Exception:  # noqa: BLE001 - an object that does not reach z has no outline
        return None
    if section is None:
        return None
    pts = np.asarray(section.vertices)[:, :2]
    if len(pts) < 3:
        return None
    from scipy.spatial import ConvexHull

    hull = ConvexHull(pts)
    ring = pts[hull.vertices]
    return np.vstack([ring, ring[:1]])


def top_view_figure(scene: Any, sonar: Any, objects: list[dict[str, Any]], extra: list[dict[str, Any]]) -> Any:
    """The tank seen from above: objects, sonar and beam, estimates with 2-sigma ellipses, and zooms.

    The top panel is the whole tank; below, one panel per found object, centred on its truth,
    in millimetres, showing the estimate and its 2-sigma ellipse (``covariance_tank``).
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    found = [r for r in objects if r["estimate"] is not None]
    n_zoom = max(1, len(found))
    fig = plt.figure(figsize=(11, 7.5), constrained_layout=True)
    grid = fig.add_gridspec(2, n_zoom, height_ratios=[1.6, 1.0])
    ax = fig.add_subplot(grid[0, :])
    z = sonar.transmitter_position[2]
    if scene.tank is not None:
        L, W = scene.tank.length_m, scene.tank.width_m
        ax.plot([0, L, L, 0, 0], [0, 0, W, W, 0], color="k", lw=1)
    for obj in scene.objects:
        ring = _outline(obj, z)
        if ring is not None:
            ax.fill(ring[:, 0], ring[:, 1], color="0.6", zorder=2)
            ax.text(ring[:, 0].max() + 0.05, ring[:, 1].mean(), obj.name, fontsize=7)
    tx = sonar.transmitter_position
    rx = sonar.receiver_positions
    ax.plot(rx[:, 0], rx[:, 1], "s", color="tab:green", ms=3, zorder=4)
    bore = sonar.boresight
    null = math.asin(min(1.0, 3.8317 / (2 * math.pi * sonar.centre_frequency_hz * sonar.piston_radius_m
                                     / scene.medium.sound_speed)))
    reach = scene.tank.length_m if scene.tank is not None else 5.0
    for sign in (-1, 1):
        c, s = math.cos(sign * null), math.sin(sign * null)
        d = np.array([c * bore[0] - s * bore[1], s * bore[0] + c * bore[1]])
        ax.plot([tx[0], tx[0] + reach * d[0]], [tx[1], tx[1] + reach * d[1]], "--", color="tab:green", lw=0.7)
    ax.text(tx[0], tx[1] + 0.12, f"sonar (beam: first null +/-{math.degrees(null):.1f} deg)", fontsize=7,
            color="tab:green")
    for r in found:
        p = r["estimate"]["position_tank_m"]
        if p is not None:
            ax.plot(p[0], p[1], "+", color="tab:red", ms=8, mew=1.2, zorder=5)
    for e in extra:
        p = e["position_tank_m"]
        if p is not None and np.all(np.isfinite(p)):
            ax.plot(p[0], p[1], ".", color="tab:purple", ms=3, zorder=3)
    ax.plot([], [], "+", color="tab:red", label="estimate of an object")
    ax.plot([], [], ".", color="tab:purple", label="other detection (multipath, wall)")
    ax.legend(fontsize=7, loc="upper right")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("Top view of the tank at the sonar's height", fontsize=9)
    for k, r in enumerate(found):
        zax = fig.add_subplot(grid[1, k])
        e = r["estimate"]
        surface = e["class"] == "point" and r["class_truth"] != "point"
        truth = np.asarray(r["truth_surface_tank_m"] if surface else r["truth_position_tank_m"])
        p = np.asarray(e["position_tank_m"], dtype=float)
        d = (p - truth) * 1e3
        zax.plot(0, 0, "o", color="k", ms=4, label="truth")
        zax.plot(d[0], d[1], "+", color="tab:red", ms=8, mew=1.2, label="estimate")
        if e["covariance_tank"] is not None:
            _ellipse(zax, d, np.asarray(e["covariance_tank"]), 2.0, 1e3, color="tab:red", lw=0.8)
        span = max(1.0, 1.3 * float(np.max(np.abs(d[:2]))) if np.all(np.isfinite(d[:2])) else 1.0)
        if e["covariance_tank"] is not None and np.all(np.isfinite(e["covariance_tank"])):
            span = max(span, 2.6 * 1e3 * math.sqrt(max(np.linalg.eigvalsh(np.asarray(e["covariance_tank"])[:2, :2]))))
        zax.set_xlim(-span, span)
        zax.set_ylim(-span, span)
        zax.set_aspect("equal")
        zax.grid(True, alpha=0.3)
        zax.set_title(f"{r['object']}: {e['class']}" + (" (vs nearest surface)" if surface else ""), fontsize=8)
        zax.set_xlabel("dx (mm)", fontsize=7)
        if k == 0:
            zax.set_ylabel("dy (mm)", fontsize=7)
            zax.legend(fontsize=6, loc="lower left")
        zax.tick_params(labelsize=6)
    fig.suptitle("Estimates with 2-sigma error ellipses (zooms: mm around the truth: the edge, a cylinder's axis, or its nearest surface point when localised as a point)", fontsize=9)
    return fig
