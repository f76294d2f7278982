"""``acoustisim demo``: the main job (simulate the thesis tank, detect, localise, compare with the truth).

``acoustisim demo [--out DIR] [--seed S] [--method M] [--pings N] [--no-elastic] [--json]`` prints a table of
the targets (truth, estimate, error, class, standard deviations; the other detections named from
the ground truth) and writes three figures to ``DIR`` (default ``demo-out``).
"""

from __future__ import annotations

import argparse
import json

from acoustisim.cli.arguments import MAX_SEED, add_limit_arguments, finite_float, path_argument, with_limits
from acoustisim.ranges import RECORD_LENGTH_S


def _run(args: argparse.Namespace) -> int:
    from acoustisim.demo import DemoConfig, format_table, run_demo
    from acoustisim.errors import InputError
    from binsonar.detection import METHODS

    if args.method not in METHODS:
        raise InputError(f"--method {args.method!r}: unknown (known: {', '.join(METHODS)})")
    if args.pings < 1:
        raise InputError(f"--pings must be >= 1, got {args.pings}")
    if not 0 <= args.seed <= MAX_SEED:
        raise InputError(f"--seed must be >= 0 and <= {MAX_SEED}, got {args.seed}")
    from binsonar.files import check_output_folder, note_created_folder

    out = check_output_folder(args.out, "--out")
    existed = out.exists()
    _preflight(args)
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


def _preflight(args: argparse.Namespace) -> None:
    """The simulation the demo will run, checked before any work (as ``simulate`` checks it)."""
    from dataclasses import replace

    from acoustisim.demo import DemoConfig
    from acoustisim.preflight import preflight
    from acoustisim.propagation import SolverConfig
    from scenes.file_access import shown_path
    from scenes.scene_file import load_scene

    scene = load_scene(args.scene)
    sonar = scene.sonar
    if args.record_length is not None:
        from acoustisim.errors import InputError

        try:
            sonar = replace(sonar, record_length_s=args.record_length)
        except InputError as exc:
            raise InputError(f"--record-length {args.record_length!r}: {exc}") from None
    config = SolverConfig(max_order=DemoConfig().max_order, backend=args.backend)
    preflight(scene, sonar, config, n_pings=args.pings, source=shown_path(args.scene), pings_key="--pings")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``demo`` verb."""
    parser = subparsers.add_parser(
        "demo", help="simulate the thesis tank, detect and localise its targets, compare with the truth",
        description="Simulate the thesis tank from the default pose, run binsonar's detection and localisation "
                    "on the recording, print truth vs estimate and write figures.")
    parser.add_argument("--out", default="demo-out", type=path_argument,
                        help="folder for the figures (default demo-out)")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    parser.add_argument("--method", default="ca-cfar", help="binsonar detection method (default ca-cfar)")
    parser.add_argument("--pings", type=int, default=50,
                        help="pings recorded and averaged (default 50, as the seed)")
    parser.add_argument("--scene", default="thesis-tank", help="built-in scene or scene file (default thesis-tank)")
    parser.add_argument("--record-length", type=finite_float(RECORD_LENGTH_S), default=None, metavar="S",
                        help="record length (s; default the sonar's)")
    parser.add_argument("--backend", default="fast", choices=("fast", "reference"),
                        help="propagation engine: fast (default) or reference (the readable one; minutes)")
    parser.add_argument("--no-elastic", action="store_true",
                        help="echoes of the PVC posts and pipe as geometric-optics rows (no elastic echoes)")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    add_limit_arguments(parser)
    parser.set_defaults(run=with_limits(_run))
