"""Plot one simulated ping of the thesis tank: three channels, main bang, echoes and multipaths.

Usage
-----
    python examples/plot_thesis_ping.py [-o docs/images/thesis_tank_ping.png] [--seed 0]

Left: the whole record (20 ms) of each channel (left, centre, right receivers); right: a zoom
on the target echoes. The labels come from the simulation's ground truth (its arrivals
table): the strongest arrival of each target and the strongest multipaths (paths that also
touch the tank's walls, floor or surface), at their traced delays.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def broadband_gain(arrivals, sonar, sound_speed_m_s):
    """Each arrival's echo level averaged over the pulse's spectrum, directivities included.

    The arrivals table's ``amplitude`` is at the centre frequency only: 10 deg off axis it sits
    near the piston's first null although the echo's lower frequencies come through strongly.
    """
    from acoustisim.propagation.directivity import piston_directivity

    f = np.linspace(100e3, 1.2e6, 45)
    q = np.abs(sonar.pulse.spectrum(f))

    def directivity(angle):
        front = (np.abs(angle) < 0.5 * np.pi)[:, None]
        return piston_directivity(angle[:, None], f, sonar.piston_radius_m, sound_speed_m_s) * front

    product = directivity(arrivals["angle_tx_rad"]) * directivity(arrivals["angle_rx_rad"]) * q
    return np.abs(arrivals["geometric_gain"]) * np.abs(product.sum(axis=1)) / q.sum()


def labelled_arrivals(sim, scene, n_targets_max=6, n_multipaths=5, early_s=3.2e-3, n_early_multipaths=3):
    """(delay_s, label, is_target) of the arrivals worth naming, strongest first, one per delay:
    the targets, the strongest multipaths, and the strongest multipaths before ``early_s``."""
    from acoustisim.propagation.paths import Paths, PathKind

    arrivals = sim.paths.arrivals()
    labels = Paths(arrivals, sim.paths.surface_names).object_labels()
    level = broadband_gain(arrivals, scene.sonar, scene.medium.sound_speed)
    ids = arrivals["object_ids"].astype(int)
    touched = ids >= 0
    target = touched.any(axis=1) & np.all(~touched | (ids >= len(scene.boundaries)), axis=1)
    target &= arrivals["kind"] != PathKind.DIFFUSE
    multi = ~target & touched.any(axis=1) & (arrivals["kind"] == PathKind.SPECULAR)
    chosen: list[tuple[float, str, bool]] = []
    early = arrivals["delay_s"] < early_s
    groups = ((target, n_targets_max, True), (multi & early, n_early_multipaths, False), (multi, n_multipaths, False))
    for mask, limit, is_target in groups:
        names: set[str] = set()
        for i in np.flatnonzero(mask)[np.argsort(-level[mask])]:
            delay = float(arrivals["delay_s"][i])
            if labels[i] in names or any(abs(delay - d) < 30e-6 for d, _, _ in chosen) or (
                not is_target and any(label == labels[i].replace(">", " > ") for _, label, _ in chosen)
            ):
                continue  # one label per delay (the same path walked backwards, other channels)
            names.add(labels[i])
            chosen.append((delay, labels[i].replace(">", " > "), is_target))
            if len(names) == limit:
                break
    return sorted(chosen)


def main() -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from acoustisim.simulation import simulate
    from scenes.builtin import builtin_scene

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", default=str(ROOT / "docs" / "images" / "thesis_tank_ping.png"))
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    scene = builtin_scene("thesis-tank")
    sim = simulate(scene, seed=args.seed)  # the thesis tank's record holds every arrival: no warning
    recording = sim.recording
    t_ms = recording.times_s * 1e3
    marks = labelled_arrivals(sim, scene)
    zoom = (1.95, 3.2)

    fig, axes = plt.subplots(3, 2, figsize=(15, 9), sharey=True, gridspec_kw={"width_ratios": [1.5, 1]})
    names = ("left", "centre", "right")
    limit = 0.15
    for channel in range(3):
        for column, (lo, hi) in enumerate(((-0.2, t_ms[-1]), zoom)):
            ax = axes[channel, column]
            window = (t_ms >= lo) & (t_ms <= hi)
            ax.plot(t_ms[window], recording.waveforms[0, channel, window], lw=0.5, color="0.15")
            ax.set_xlim(lo, hi)
            ax.set_ylim(-limit, limit)
            for delay, label, is_target in marks:
                if lo <= delay * 1e3 <= hi:
                    ax.axvline(delay * 1e3, color="tab:red" if is_target else "tab:blue", lw=0.6, alpha=0.5)
            if column == 0:
                ax.set_ylabel(f"{names[channel]} (V)")
        bang = np.abs(recording.waveforms[0, channel, : int(20e-6 * recording.sample_rate_hz)]).max()
        axes[channel, 0].annotate(
            ("main bang" if channel == 1 else "cross-talk") + f" (peak {bang:.2f} V)",
            xy=(0.0, 0.95 * limit), xytext=(0.4, 0.8 * limit), fontsize=8,
            arrowprops=dict(arrowstyle="->", lw=0.6),
        )
        if channel != 1:  # the direct path from the transmitter, 65 mm along the baffle plane
            direct = sim.paths.arrivals()
            direct = direct[(direct["channel"] == channel) & (direct["kind"] == 0)]
            if direct.size:
                axes[channel, 0].annotate(
                    f"direct path ({direct['delay_s'][0] * 1e6:.0f} us)", xy=(direct["delay_s"][0] * 1e3, -0.9 * limit),
                    xytext=(0.4, -0.8 * limit), fontsize=8, arrowprops=dict(arrowstyle="->", lw=0.6),
                )
    for k, (delay, label, is_target) in enumerate(marks):
        for column, (lo, hi) in enumerate(((0.0, t_ms[-1]), zoom)):
            if not lo <= delay * 1e3 <= hi or (column == 0 and lo <= delay * 1e3 <= zoom[1]):
                continue  # the crowded early echoes are named in the zoom only
            y = limit * (0.92 - 0.12 * (k % 7))
            right = delay * 1e3 > lo + 0.7 * (hi - lo)
            axes[1, column].text(
                delay * 1e3, y, (label + " ") if right else (" " + label), fontsize=7,
                color="tab:red" if is_target else "tab:blue", ha="right" if right else "left", va="top",
            )
    axes[2, 0].set_xlabel("time after trigger (ms)")
    axes[2, 1].set_xlabel("time after trigger (ms), zoom on the targets")
    axes[0, 0].set_title(
        f"thesis tank, one simulated ping (seed {args.seed}): red = target echoes, blue = tank multipaths"
    )
    axes[0, 1].set_title("zoom: the nearest targets and their floor/surface multipaths")
    fig.tight_layout()
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
