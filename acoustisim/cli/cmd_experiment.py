"""``acoustisim experiment NAME``: run one of the seed's experiments in the simulated tank.

``acoustisim experiment NAME [--trials N] [--seed S] [--out DIR] [--workers N] [--json]
[--no-progress] [experiment options]`` writes ``results.json``, ``report.md`` and PNG figures to
``DIR`` (default ``out/NAME``), with a progress bar on stderr. The experiments are the modules
found by ``acoustisim.experiments.registry``; each may add its own options. With ``--json``,
one JSON object (the experiment, the files written and the summary) is printed on stdout.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

COMMON = ("trials", "seed", "out", "workers", "json", "no_progress", "experiment", "verb", "run")


def _run(args: argparse.Namespace) -> int:
    from acoustisim.errors import InputError
    from acoustisim.experiments.config import ExperimentConfig
    from acoustisim.experiments.registry import experiment_module
    from acoustisim.experiments.report import to_jsonable

    module = experiment_module(args.experiment)
    if args.trials is not None and args.trials < 1:
        raise InputError(f"--trials must be >= 1, got {args.trials}")
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be >= 1, got {args.workers}")
    if args.seed < 0:
        raise InputError(f"--seed must be >= 0, got {args.seed}")
    options = {k: v for k, v in vars(args).items() if k not in COMMON}
    from binsonar.files import check_output_folder, note_created_folder

    out_dir = check_output_folder(args.out if args.out else Path("out") / args.experiment, "--out")
    existed = out_dir.exists()
    config = ExperimentConfig(name=args.experiment, out_dir=out_dir, seed=args.seed, trials=args.trials,
                              workers=args.workers, progress=not args.no_progress, options=options)
    report = module.run(config)
    files = report.write()
    note_created_folder(out_dir, existed, "acoustisim")
    summary: dict[str, Any] = {
        "experiment": args.experiment,
        "out_dir": str(out_dir),
        **files,
        "figures": [str(out_dir / name) for name, _ in report.figures],
        "summary": report.results.get("summary"),
    }
    if args.json:
        print(json.dumps(to_jsonable(summary)))
    else:
        print(f"{args.experiment}: wrote {files['results']}, {files['report']} and {len(report.figures)} figure(s)")
        for name, _ in report.figures:
            print(f"  {out_dir / name}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``experiment`` verb with one sub-command per registered experiment."""
    from acoustisim.experiments.registry import discover

    modules, broken = discover()
    parser = subparsers.add_parser(
        "experiment", help="run an experiment (range-sweep, angle-sweep, nine-methods, ...)",
        description="Run one of the seed's experiments in the simulated tank; writes results.json, "
                    "report.md and PNG figures.",
        epilog=("modules of acoustisim.experiments that failed to import: "
                + "; ".join(f"{k}: {v}" for k, v in broken.items())) if broken else None)
    names = parser.add_subparsers(dest="experiment", metavar="NAME")
    names.required = True
    for name, module in modules.items():
        sub = names.add_parser(name, help=getattr(module, "SUMMARY", ""), description=getattr(module, "SUMMARY", ""))
        sub.add_argument("--trials", type=int, default=None, metavar="N",
                         help="the experiment's size (see its report; default: the experiment's own)")
        sub.add_argument("--seed", type=int, default=0, metavar="S", help="master seed (default 0)")
        sub.add_argument("--out", default=None, metavar="DIR", help=f"output folder (default out/{name})")
        sub.add_argument("--workers", type=int, default=None, metavar="N", help="worker processes (default: the usable cores)")
        sub.add_argument("--json", action="store_true", help="print one JSON object on stdout")
        sub.add_argument("--no-progress", action="store_true", help="no progress bar")
        add_arguments = getattr(module, "add_arguments", None)
        if callable(add_arguments):
            add_arguments(sub)
        sub.set_defaults(run=_run)
