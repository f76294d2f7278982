"""Issue 19's second trap: can the prism's apex be detected channel by channel at the default false-alarm rate?

For the trap of ``benchmarks/localization_table.py`` (the thesis tank's steel prism alone, the
head at (1.2, 1.5, 0.5) m turned by ``--yaws`` degrees, 30 dB of the strongest echo), one
simulated ping gives the noise-free record and its noise. Per channel, the apex's and the near
corner's 2E/N0 at the plain matched filter (``binsonar.estimation.tof.matched_snr``: the clean
record within the echo's stretch against the ping's noise), and the probability that a
square-law cell crosses the ideal threshold of the default CA-CFAR's false-alarm probability
(``PFA`` per cell): 2|z|^2 / E|n|^2 is non-central chi-square with 2 degrees of freedom and
non-centrality 2E/N0, the threshold -2 ln(pfa). ``localize`` needs the echo on two channels
(the cued search then finds the third), so the apex is reported about as often as two of its
three channels cross. The last column is the three channels' summed 2E/N0: what a detector
that adds the channels along a hypothesised position would have.

    python docs/scripts/prism_trap_snr.py [--yaws 4 8]
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path

import numpy as np

PFA = 1e-6
"""The CA-CFAR's default false-alarm probability per cell (``binsonar.detection.cfar``)."""
STRETCHES_S = {"apex": 75e-6, "corner": 75e-6}
"""Half-width of the stretch of the clean record kept around each echo's centre-channel delay (s):
wider than the template and the beam's spread, narrower than the 118 us between the two."""


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    import localization_table as lt
    from scipy.stats import ncx2

    from acoustisim.simulation import simulate
    from binsonar.estimation.tof import matched_snr
    from scenes.builtin import builtin_scene

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--yaws", type=float, nargs="+", default=[4.0, 8.0])
    args = parser.parse_args(argv)
    threshold = -2.0 * math.log(PFA)
    print("| yaw (deg) | echo | 2E/N0 left, centre, right (dB) | P(cross) left, centre, right | P(two or more) "
          "| summed 2E/N0 (dB) |\n|---|---|---|---|---|---|")
    for yaw in args.yaws:
        tank = builtin_scene("thesis-tank")
        prism = tank.objects[0]
        sonar = tank.sonar.with_pose(lt.TRAP_SONAR_M, yaw_deg=yaw)
        scene = lt.empty_tank((prism,), sonar)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # arrivals past the record are left out
            sim = simulate(scene, seed=0, n_pings=1, snr_db=lt.SNR_DB)
        rec = sim.recording
        clean = np.asarray(sim.clean).reshape(3, -1)
        noise = np.asarray(rec.waveforms).reshape(3, -1) - clean
        t = rec.t0_s + np.arange(clean.shape[1]) / rec.sample_rate_hz
        apex = np.asarray(prism.parameter("edge_m"), dtype=float)
        corners = np.unique(np.round(np.asarray(prism.mesh.vertices)[:, :2], 9), axis=0)
        near = min((c for c in corners if np.linalg.norm(c - apex) > 1e-6),
                   key=lambda c: np.linalg.norm(np.asarray(lt.TRAP_SONAR_M[:2]) - c))
        c = float(rec.sound_speed_m_s)
        for name, xy in (("apex", apex), ("corner", near)):
            r, _ = lt.head_range_bearing(sonar, (*xy, lt.TRAP_SONAR_M[2]))
            centre = 2.0 * r / c
            echo = np.where(np.abs(t - centre) < STRETCHES_S[name], clean, 0.0)
            snr = matched_snr(echo, noise, np.asarray(rec.template.samples))
            p = ncx2.sf(threshold, 2, snr)
            two = p[0] * p[1] + p[0] * p[2] + p[1] * p[2] - 2.0 * p[0] * p[1] * p[2]
            print(f"| {yaw:g} | {name} | {', '.join(f'{10 * math.log10(s):.1f}' for s in snr)} "
                  f"| {', '.join(f'{v:.2f}' for v in p)} | {two:.2f} | {10 * math.log10(snr.sum()):.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
