"""What the joint multi-channel search costs ``localize``: time per ping with and without it, same run.

The scene is issue 19's trap (``localization_table``: the thesis tank's prism alone, the head at
(1.2, 1.5, 0.5) m turned by ``--yaw`` degrees, 30 dB), simulated once; ``localize`` (ca-cfar,
beam-aware, no fusion) then runs on the same recording with the joint search on and off,
alternately, ``--repeats`` times each. Printed: the median time per ping of each, their ratio,
and the median of the joint search's own share (``joint_search`` alone on every ping).

    python benchmarks/bench_joint_search.py [--pings 10] [--repeats 5] [--yaw 8]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np


def main() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import localization_table as lt

    from acoustisim.simulation import simulate
    from binsonar.detection import detect
    from binsonar.localization.array_geometry import ArrayGeometry
    from binsonar.localization.joint_search import JointSearchConfig, JointSetup, joint_search
    from binsonar.localization.pipeline import LocalizationConfig, localize
    from scenes.builtin import builtin_scene

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pings", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--yaw", type=float, default=8.0)
    args = parser.parse_args()
    tank = builtin_scene("thesis-tank")
    sonar = tank.sonar.with_pose(lt.TRAP_SONAR_M, yaw_deg=args.yaw)
    scene = lt.empty_tank((tank.objects[0],), sonar)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # arrivals past the record are left out
        rec = simulate(scene, seed=0, n_pings=args.pings, snr_db=lt.SNR_DB).recording
    on = LocalizationConfig(fuse=False)
    off = replace(on, joint_search=JointSearchConfig(enabled=False))
    times: dict[str, list[float]] = {"on": [], "off": []}
    for _ in range(args.repeats):
        for name, cfg in (("off", off), ("on", on)):
            start = time.perf_counter()
            localize(rec, config=cfg)
            times[name].append((time.perf_counter() - start) / args.pings)
    geometry = ArrayGeometry.from_channel_positions(rec.channel_positions_m)
    setup = JointSetup.create(rec.template, rec.array.transducers(), rec.waveforms.shape[-1], rec.sample_rate_hz,
                              float(rec.sound_speed_m_s), geometry.receivers_m, JointSearchConfig())
    echoes = detect(rec, "ca-cfar").echoes
    own = []
    for k in range(args.pings):
        used = tuple(np.zeros(len(ch), dtype=bool) for ch in echoes[k])
        start = time.perf_counter()
        joint_search(np.asarray(rec.waveforms[k], dtype=float), setup, t0_s=rec.t0_s, transmitter_m=geometry.transmitter_m,
                     receivers_m=geometry.receivers_m, echoes=echoes[k], used=used)
        own.append(time.perf_counter() - start)
    m_on, m_off = statistics.median(times["on"]), statistics.median(times["off"])
    print(f"trap yaw {args.yaw:g} deg, {args.pings} pings x {rec.waveforms.shape[-1]} samples, {args.repeats} repeats")
    print(f"localize per ping, joint search off: {1e3 * m_off:.1f} ms (median)")
    print(f"localize per ping, joint search on:  {1e3 * m_on:.1f} ms (median); ratio on/off {m_on / m_off:.2f}")
    print(f"joint_search alone per ping: {1e3 * statistics.median(own):.1f} ms (median)")


if __name__ == "__main__":
    main()
