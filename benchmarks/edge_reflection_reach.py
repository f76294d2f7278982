"""What the reach of the integrated edge-and-reflection paths buys and costs, on one thesis-tank pose.

Solves the default pose's edge rows twice, with the default reach
(``SolverConfig.edge_reflection_fresnel_v = 3``: pairs near a geometric boundary integrated,
the others one Keller row each) and with every pair integrated (``None``), and prints:

* CPU-time medians of the default deterministic solve (direct + specular + edges, every other
  knob at its default) for both, interleaved, and their rows;
* the edge-and-reflection arrivals of each (integrated, Keller);
* the arrivals the default leaves out (no row of the same channel, surfaces and delay within
  1 us), the strongest relative to the strongest non-direct arrival (the amplitude floor's
  reference, :func:`acoustisim.propagation.reference.floor.band_levels`);
* for each Keller row, its band-limited echo (the seed pulse through both pistons,
  sqrt(f0 / f), -45 deg) against the integrated arrival's over the 50 us after the onset: the
  peak ratio in dB, as quantiles, and for the strongest ten.

    python benchmarks/edge_reflection_reach.py [--repeats 9]
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

FS_HZ = 20e6
N_SAMPLES = 1 << 14
BAND_TOP_HZ = 1.5e6
MATCH_S = 1e-6


def cpu_median_ms(solve: Any, repeats: int) -> float:
    """Median CPU time (ms) of ``solve()`` over ``repeats`` calls."""
    times = []
    for _ in range(repeats):
        start = time.process_time()
        solve()
        times.append(time.process_time() - start)
    return 1e3 * float(np.median(times))


def main(argv: list[str] | None = None) -> int:
    from acoustisim.propagation import SolverConfig, prepare, solve
    from acoustisim.propagation.apex_response import APEX_RESPONSE_ID
    from acoustisim.propagation.context import SolveContext
    from acoustisim.propagation.directivity import piston_directivity
    from acoustisim.propagation.paths import PathKind
    from acoustisim.propagation.reference.floor import arrival_groups, band_levels, floor_frequencies
    from acoustisim.synthesis.transducer import pulse_spectrum
    from scenes.builtin import builtin_scene

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9)
    args = parser.parse_args(argv)
    prepared = prepare(builtin_scene("thesis-tank"))
    context = SolveContext.build(prepared.scene, prepared.scene.sonar, prepared.raycaster)
    c, f0, a = context.sound_speed_m_s, context.centre_frequency_hz, context.piston_radius_m
    reaches = {"default reach (v <= 3)": 3.0, "every pair integrated": None}
    configs = {name: SolverConfig(mechanisms=("direct", "specular", "edge"), edge_reflection_fresnel_v=reach)
               for name, reach in reaches.items()}
    for config in configs.values():
        solve(prepared, config=config)  # warm (compilation, caches)
    timings: dict[str, list[float]] = {name: [] for name in configs}
    for _ in range(3):  # interleaved rounds
        for name, config in configs.items():
            timings[name].append(cpu_median_ms(lambda: solve(prepared, config=config), args.repeats))
    print(f"thesis tank, default pose, deterministic solve (direct + specular + edges, defaults), CPU medians of "
          f"{args.repeats} x 3 interleaved rounds:")
    for name, config in configs.items():
        rows = solve(prepared, config=config).rows
        reflected = rows[(rows["kind"] == PathKind.EDGE) & (rows["order"] > 1)]
        keller = reflected["response_id"] == APEX_RESPONSE_ID
        arrivals = np.unique(np.stack([reflected["path_id"][~keller], reflected["channel"][~keller]]), axis=1).shape[1]
        print(f"  {name}: {np.median(timings[name]):.1f} ms, {rows.size} rows; edge + reflection arrivals: "
              f"{arrivals} integrated, {int(keller.sum())} Keller")

    edge_only = {name: solve(prepared, config=SolverConfig(mechanisms=("direct", "specular", "edge"),
                                                           edge_reflection_fresnel_v=reach, amplitude_floor_db=None)).rows
                 for name, reach in reaches.items()}
    default, full = edge_only["default reach (v <= 3)"], edge_only["every pair integrated"]
    frequencies, weights = floor_frequencies(context, None)
    group, n_groups = arrival_groups(full)
    levels = band_levels(full, group, n_groups, context, frequencies, weights)
    direct = np.zeros(n_groups, dtype=bool)
    direct[group[full["kind"] == PathKind.DIRECT]] = True
    strongest = float(levels[~direct].max())
    reflected = (full["kind"] == PathKind.EDGE) & (full["order"] > 1)
    ours = default[(default["kind"] == PathKind.EDGE) & (default["order"] > 1)]
    left_out = []
    members: dict[int, np.ndarray] = {}
    for g in np.unique(group[reflected]):  # a few hundred arrivals
        mine = full[group == g]
        members[int(g)] = mine
        same = ours[(ours["channel"] == mine["channel"][0]) & np.all(ours["object_ids"] == mine["object_ids"][0], axis=1)]
        if not np.any(np.abs(same["delay_s"] - mine["delay_s"].min()) < MATCH_S):
            left_out.append(20 * np.log10(levels[g] / strongest))
    left_out.sort(reverse=True)
    print(f"  left out by the default reach: {len(left_out)} of {len(members)} arrivals, the strongest "
          f"{left_out[0] if left_out else float('nan'):.1f} dB re the strongest echo")

    f = np.fft.rfftfreq(N_SAMPLES, 1 / FS_HZ)
    band = f <= BAND_TOP_HZ
    q = pulse_spectrum(prepared.scene.sonar.pulse, f[band])

    def echo(rows: np.ndarray) -> np.ndarray:
        """The rows' band-limited echo from 20 us before their earliest delay."""
        fb = f[band]
        delay = rows["delay_s"] - rows["delay_s"].min() + 20e-6
        factor = (rows["geometric_gain"] * np.exp(1j * rows["phase_rad"]))[:, None] * piston_directivity(
            rows["angle_tx_rad"][:, None], fb, a, c) * piston_directivity(rows["angle_rx_rad"][:, None], fb, a, c)
        keller_rows = rows["response_id"] == APEX_RESPONSE_ID
        factor[keller_rows] *= np.sqrt(f0 / np.maximum(fb, 0.1 * f0))
        spectrum = np.zeros(f.size, dtype=complex)
        spectrum[band] = q * np.sum(factor * np.exp(-2j * np.pi * np.outer(delay, fb)), axis=0)
        return np.fft.irfft(spectrum, N_SAMPLES)

    window = slice(int(10e-6 * FS_HZ), int(70e-6 * FS_HZ))
    compared = []
    for row in ours[ours["response_id"] == APEX_RESPONSE_ID]:  # a few hundred rows
        for mine in members.values():
            if (mine["channel"][0] == row["channel"] and np.all(mine["object_ids"][0] == row["object_ids"])
                    and abs(mine["delay_s"].min() - row["delay_s"]) < MATCH_S):
                reference = np.abs(echo(mine)[window]).max()
                if reference > 0:
                    compared.append((20 * np.log10(np.abs(echo(row[None])[window]).max() / reference),
                                     20 * np.log10(reference), int(row["channel"]),
                                     "+".join(np.asarray(prepared.scene.surface_names)[row["object_ids"][:2]])))
                break
    ratios = np.array([item[0] for item in compared])
    print(f"  Keller rows against the integrated arrivals (peak of the band-limited echo over 50 us, dB), "
          f"{ratios.size} rows: quantiles 0/10/50/90/100 % "
          + " / ".join(f"{value:+.2f}" for value in np.quantile(ratios, [0, 0.1, 0.5, 0.9, 1.0])))
    top = max(item[1] for item in compared)
    print("  the ten strongest (dB re the strongest integrated edge + reflection echo, channel, path):")
    for ratio, level, channel, name in sorted(compared, key=lambda item: -item[1])[:10]:
        print(f"    {ratio:+.2f} dB at {level - top:6.1f} dB, channel {channel}, {name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
