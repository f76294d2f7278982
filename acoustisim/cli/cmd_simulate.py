"""``acoustisim simulate``: trace a scene, synthesise pings, write a recording with ground truth.

``acoustisim simulate FILE_OR_NAME -o PING.h5 [--seed N] [--snr-db X] [--snr-echo NAME]
[--pings N] [--max-order N] [--keep-all-paths] [--average] [--backend fast|reference] [--json]``

With ``--json`` stdout holds one JSON object: the output file, the number of pings, the
clipped channels and the arrivals table (``Paths.arrivals_table``).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings

from acoustisim.cli.arguments import add_limit_arguments, finite_float, int_at_least, path_argument, seed, with_limits
from acoustisim.ranges import SNR_DB


def _run(args: argparse.Namespace) -> int:
    from acoustisim.propagation.config import SolverConfig
    from acoustisim.simulation import simulate, write_simulation
    from binsonar.files import check_output_file
    from scenes.scene_file import load_scene

    check_output_file(args.output, "-o")  # before the work: a refused path costs nothing
    scene = load_scene(args.scene)
    config = SolverConfig(
        max_order=args.max_order if args.max_order is not None else SolverConfig().max_order,
        amplitude_floor_db=None if args.keep_all_paths else SolverConfig().amplitude_floor_db,
        backend=args.backend,
    )
    from acoustisim.preflight import preflight
    from scenes.file_access import shown_path

    # everything checked before any work, with the options named as the user typed them
    preflight(scene, config=config, n_pings=args.pings, snr_db=args.snr_db, source=shown_path(args.scene),
              pings_key="--pings", order_key="--max-order")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        sim = simulate(
            scene,
            solver_config=config,
            seed=args.seed,
            n_pings=args.pings,
            snr_db=args.snr_db,
            snr_echo=args.snr_echo,
            average=args.average,
        )
    for warning in caught:  # one line each on stderr, never on stdout
        print(f"acoustisim: warning: {warning.message}", file=sys.stderr)
    path = write_simulation(args.output, sim)
    clipped = [
        [name for name, flag in zip(sim.recording.channel_names, row) if flag] for row in sim.recording.clipped
    ]
    if args.json:
        print(
            json.dumps(
                {
                    "scene": scene.name,
                    "output": str(path),
                    "n_pings": int(sim.recording.n_pings),
                    "seed": int(args.seed),
                    "clipped": clipped,
                    "arrivals": sim.paths.arrivals_table(),
                }
            )
        )
    else:
        n_arrivals = len(sim.truth["arrivals"])
        print(
            f"{path}: {sim.recording.n_pings} ping(s) of scene {scene.name!r}, {len(sim.paths)} path rows,"
            f" {n_arrivals} arrivals, {sim.recording.n_samples} samples per channel"
            + (f"; clipped: {clipped}" if any(clipped) else "")
        )
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``simulate`` verb."""
    parser = subparsers.add_parser(
        "simulate",
        help="simulate pings of a scene and write a recording (HDF5) with ground truth",
        description="Trace the scene's paths, synthesise the three digitised channels and write the recording.",
    )
    parser.add_argument("scene", metavar="FILE_OR_NAME", help="scene file (TOML) or built-in scene name")
    parser.add_argument("-o", "--output", required=True, type=path_argument, metavar="PING.h5",
                        help="recording file to write")
    parser.add_argument("--seed", type=seed, default=0, help="noise seed (default 0)")
    parser.add_argument(
        "--snr-db", type=finite_float(SNR_DB), default=None, metavar="X",
        help="set 2E/N0 (dB) of the named echo on each channel with white noise",
    )
    parser.add_argument(
        "--snr-echo", default=None, metavar="NAME",
        help="surface whose echo --snr-db refers to (default: the strongest target echo)",
    )
    parser.add_argument("--pings", type=int_at_least(1), default=1, metavar="N", help="pings (independent noise)")
    parser.add_argument("--max-order", type=int_at_least(1), default=None, metavar="N", help="most reflections per path")
    parser.add_argument("--keep-all-paths", action="store_true", help="turn off the solver's amplitude floor")
    parser.add_argument("--backend", default="fast", choices=("fast", "reference"),
                        help="propagation engine: fast (compiled, default) or reference (plain numpy, "
                             "one module per mechanism; the same paths, slower)")
    parser.add_argument("--average", action="store_true", help="store the mean of the pings as one ping")
    parser.add_argument("--json", action="store_true", help="print one JSON object (arrivals table) on stdout")
    add_limit_arguments(parser)
    parser.set_defaults(run=with_limits(_run))
