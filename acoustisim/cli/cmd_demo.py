"""``acoustisim demo``: the main job (simulate the thesis tank, detect, localise, compare with the truth).

``acoustisim demo [--out DIR] [--seed S] [--method M] [--pings N] [--no-elastic] [--json]`` prints a table of
the targets (truth, estimate, error, class, standard deviations; the other detections named from
the ground truth) and writes three figures to ``DIR`` (default ``demo-out``).
"""

from __future__ import annotations

import argparse
import json



def _run(args: argparse.Namespace) -> int:
    from acoustisim.demo import DemoConfig, format_table, run_demo
    from acoustisim.errors import InputError
    from binsonar.detection import METHODS

    if args.method not in METHODS:
        raise InputError(f"--method {args.method!r}: unknown (known: {', '.join(METHODS)})")
    if args.pings < 1:
        raise InputError(f"--pings must be >= 1, got {args.pings}")
    if args.seed < 0:
        raise InputError(f"--seed must be >= 0, got {args.seed}")
    from binsonar.files import check_output_folder, note_created_folder

    out = check_output_folder(args.out, "--out")
    existed = out.exists()
    demo = run_demo(DemoConfig(scene=args.scene, seed=args.seed, n_pings=args.pings, method=args.method,
                               record_length_s=args.record_length, backend=args.backend,
                               elastic_echoes=not args.no_elastic), out)
    note_created_folder(out, existed, "acoustisim")
    if args.json:
        print(json.dumps(demo.to_dict()))
    else:
        print(format_table(demo))
        print("figures: " + ", ".join(demo.figures))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``demo`` verb."""
    parser = subparsers.add_parser(
        "demo", help="simulate the thesis tank, detect and localise its targets, compare with the truth",
        description="Simulate the thesis tank from the default pose, run binsonar's detection and localisation "
                    "on the recording, print truth vs estimate and write figures.")
    parser.add_argument("--out", default="demo-out", help="folder for the figures (default demo-out)")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    parser.add_argument("--method", default="ca-cfar", help="binsonar detection method (default ca-cfar)")
    parser.add_argument("--pings", type=int, default=50, help="pings recorded and averaged (default 50, as the seed)")
    parser.add_argument("--scene", default="thesis-tank", help="built-in scene or scene file (default thesis-tank)")
    parser.add_argument("--record-length", type=float, default=None,
                        help="record length (s; default the sonar's)")
    parser.add_argument("--backend", default="fast", metavar="{fast,reference}",
                        help="propagation engine: fast (default) or reference (the readable one; minutes)")
    parser.add_argument("--no-elastic", action="store_true",
                        help="echoes of the PVC posts and pipe as geometric-optics rows (no elastic echoes)")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.set_defaults(run=_run)
