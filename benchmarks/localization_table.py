"""Issue 19's table and its second trap, as a new user meets them: ``binsonar localize PING.h5 --json``.

Table: one thin rigid post (radius 5 mm) at a time in the empty thesis tank (9 m x 3 m x 1 m,
concrete, the default sonar at (1.0, 1.5, 0.5) m looking down +x), at (range to its surface,
bearing) = (0.5 m, 0 deg), (0.8 m, 8 deg), (1.5 m, -6 deg); one ping with white noise setting
2E/N0 = 30 dB of the post's echo on every channel (``acoustisim simulate --snr-db 30``), written
to a recording and localised by the command line. Printed per post: the estimated bearing, its
error and the reported sd, and the same for the range.

Trap: the thesis tank's steel prism alone (its 60-degree apex at (2.5, 1.5) m, size 0.1 m, its
back corners 9 cm behind in range), seen from (1.2, 1.5, 0.5) m with the head turned by
``--yaws`` degrees: the apex 1.3 m away, off boresight, and the corners 18 dB stronger at 8 deg
(their larger diffraction coefficient and the beam). Over ``--pings`` pings at 30 dB (of the
strongest echo), how often ``localize`` reports the apex and the corner (a target within 5 mm
of range and 1 deg of bearing of each), with their classes.

The script uses only what both trees have (the simulator, the recording file and the command
line), so it runs on an older tree too:

    python benchmarks/localization_table.py                                   # this tree
    PYTHONPATH=/work/wt/baseline python benchmarks/localization_table.py      # a baseline tree

``--json`` prints the figures as one JSON object.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

POSTS: tuple[tuple[float, float], ...] = ((0.5, 0.0), (0.8, 8.0), (1.5, -6.0))
"""(range to the surface (m), bearing (deg)) of issue 19's posts."""
POST_RADIUS_M = 0.005
SNR_DB = 30.0
TRAP_SONAR_M = (1.2, 1.5, 0.5)
"""Where the head looks at the prism from: the apex 1.3 m away (the tank's floor-surface
multiples return at 0.5 m steps of range, and 1.5 m would put one on the apex)."""


def empty_tank(objects: tuple[Any, ...], sonar: Any = None) -> Any:
    """The thesis tank with only ``objects`` (and the default sonar, or ``sonar``)."""
    from scenes.builtin import builtin_scene

    tank = builtin_scene("thesis-tank")
    return replace(tank, objects=objects, sonar=tank.sonar if sonar is None else sonar)


def localize_json(scene: Any, seed: int, n_pings: int, extra: tuple[str, ...] = ()) -> dict[str, Any]:
    """Simulate ``n_pings`` pings (``SNR_DB``), write the recording, run ``binsonar localize --json`` on it."""
    from acoustisim.simulation import simulate, write_simulation
    from binsonar.cli import main

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # arrivals past the record are left out
        sim = simulate(scene, seed=seed, n_pings=n_pings, snr_db=SNR_DB)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "ping.h5"
        write_simulation(path, sim)
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            code = main(["localize", str(path), "--json", "--no-fuse", *extra])
    if code != 0:
        raise RuntimeError(f"binsonar localize exited with {code}")
    return json.loads(out.getvalue())


def head_range_bearing(sonar: Any, point_m: Any) -> tuple[float, float]:
    """Range (m, from the transmitter) and bearing (deg) of a tank point in the head frame."""
    head = sonar.tank_to_head(np.atleast_2d(np.asarray(point_m, dtype=float)))[0] - sonar.channel_positions_head[1]
    return float(np.linalg.norm(head)), math.degrees(math.atan2(head[0], head[1]))


def nearest(targets: list[dict[str, Any]], range_m: float, bearing_deg: float, range_gate_m: float = 0.005,
            bearing_gate_deg: float = 1.0) -> dict[str, Any] | None:
    """The target nearest ``range_m`` within the gates, or None."""
    close = [t for t in targets if t["range_m"] is not None and abs(t["range_m"] - range_m) <= range_gate_m
             and t["bearing_deg"] is not None and abs(t["bearing_deg"] - bearing_deg) <= bearing_gate_deg]
    return min(close, key=lambda t: abs(t["range_m"] - range_m), default=None)


def post_table(seed: int) -> list[dict[str, Any]]:
    """Issue 19's three posts, one ping each."""
    from scenes.builders import default_sonar, post

    rows = []
    sonar = default_sonar()
    tx = np.asarray(sonar.transmitter_position, dtype=float)
    for range_m, bearing_deg in POSTS:
        theta = math.radians(bearing_deg)
        centre = (tx[0] + (range_m + POST_RADIUS_M) * math.cos(theta), tx[1] - (range_m + POST_RADIUS_M) * math.sin(theta))
        scene = empty_tank((post("post", centre, POST_RADIUS_M, 1.0, "rigid"),))
        result = localize_json(scene, seed, 1)
        target = nearest(result["pings"][0]["targets"], range_m, bearing_deg, 0.01, 3.0)
        row: dict[str, Any] = {"range_m": range_m, "bearing_deg": bearing_deg, "found": target is not None}
        if target is not None:
            row.update({"class": target["class"], "status": target["status"],
                        "estimated_bearing_deg": target["bearing_deg"], "bearing_error_deg": target["bearing_deg"] - bearing_deg,
                        "bearing_sd_deg": target["bearing_std_deg"], "estimated_range_m": target["range_m"],
                        "range_error_m": target["range_m"] - range_m, "range_sd_m": target["range_std_m"],
                        "echo_model": target.get("echo_model")})
        rows.append(row)
    return rows


def trap(yaws_deg: tuple[float, ...], n_pings: int, seed: int, extra: tuple[str, ...] = ()) -> list[dict[str, Any]]:
    """The prism's apex and corners seen off boresight (module docstring)."""
    from scenes.builtin import builtin_scene

    prism = builtin_scene("thesis-tank").objects[0]
    corners = np.unique(np.round(np.asarray(prism.mesh.vertices)[:, :2], 9), axis=0)
    apex = np.asarray(prism.parameter("edge_m"), dtype=float)
    out = []
    for yaw in yaws_deg:
        sonar = builtin_scene("thesis-tank").sonar.with_pose(TRAP_SONAR_M, yaw_deg=yaw)
        scene = empty_tank((prism,), sonar)
        result = localize_json(scene, seed, n_pings, extra)
        points = [("apex", apex)] + [("corner", c) for c in corners if np.linalg.norm(c - apex) > 1e-6]
        truths = [(name, *head_range_bearing(sonar, (*xy, TRAP_SONAR_M[2]))) for name, xy in points]
        found: dict[str, Any] = {}
        for name, r, b in truths:
            key = f"{name} {r:.3f} m {b:+.2f} deg"
            hits = [nearest(ping["targets"], r, b) for ping in result["pings"]]
            classes = [h["class"] for h in hits if h is not None]
            found[key] = {"reported": len(classes), "classes": {c: classes.count(c) for c in sorted(set(classes))}}
        out.append({"yaw_deg": yaw, "pings": n_pings, "targets": found,
                    "targets_per_ping": float(np.mean([len(p["targets"]) for p in result["pings"]]))})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--pings", type=int, default=20, help="pings of the trap scene (default 20)")
    parser.add_argument("--yaws", type=float, nargs="+", default=[4.0, 8.0], help="head yaws of the trap (deg)")
    parser.add_argument("--trap-option", action="append", default=[], dest="trap_options",
                        help="extra binsonar localize argument for the trap (repeatable), e.g. --trap-option=--pfa=1e-4")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    table = post_table(args.seed)
    traps = trap(tuple(args.yaws), args.pings, args.seed, tuple(args.trap_options))
    if args.json:
        print(json.dumps({"posts": table, "trap": traps}))
        return
    print("| post (range, bearing) | estimated bearing | error | reported sd | range error | reported sd |")
    print("|---|---|---|---|---|---|")
    for r in table:
        if not r["found"]:
            print(f"| {r['range_m']:g} m, {r['bearing_deg']:g} deg | not found | | | | |")
            continue
        print(f"| {r['range_m']:g} m, {r['bearing_deg']:g} deg | {r['estimated_bearing_deg']:.3f} deg | "
              f"{r['bearing_error_deg']:+.3f} deg | {r['bearing_sd_deg']:.3f} deg | {1e3 * r['range_error_m']:+.3f} mm | "
              f"{1e3 * r['range_sd_m']:.3f} mm |")
    for t in traps:
        print(f"trap, yaw {t['yaw_deg']:g} deg, {t['pings']} pings ({t['targets_per_ping']:.1f} targets per ping):")
        for key, v in t["targets"].items():
            print(f"  {key}: reported in {v['reported']}/{t['pings']} pings, classes {v['classes']}")


if __name__ == "__main__":
    main()
