"""``acoustisim dataset``: generate, verify and describe synthetic datasets.

- ``acoustisim dataset generate SPEC.toml --out DATA.zarr [--workers N] [--scheduler ADDRESS] [--repair] [--json]``
  (running it again on the same ``--out`` resumes: only the unfinished chunks of samples are
  made, see ``samples_per_chunk``; ``--repair`` first verifies the store and makes again the
  samples that fail)
- ``acoustisim dataset verify DATA.zarr [--json]``: exit 0 when complete and every checksum
  matches, 1 otherwise
- ``acoustisim dataset info DATA.zarr [--json]``

A bad spec raises ``SpecError`` (naming the key and the value): the main wrapper prints one line
and exits with 2, before any work starts. The spec's pre-flight (its worst sample and chunk
against the resource limits) uses the limits of the environment (``ACOUSTISIM_MAX_MEMORY_GB``
and the like), which the workers inherit.
"""

from __future__ import annotations

import argparse
import json

from acoustisim.cli.arguments import int_at_least, path_argument


def _generate(args: argparse.Namespace) -> int:
    from acoustisim.datasets.generate import generate
    from acoustisim.datasets.spec import load_spec
    from binsonar.files import check_output_folder

    check_output_folder(args.out, "--out")  # before the work: the store's folder takes new files
    spec = load_spec(args.spec)
    report = generate(spec, args.out, workers=args.workers, scheduler=args.scheduler,
                      progress=not args.no_progress, repair=args.repair)
    if args.json:
        print(json.dumps(report.as_dict()))
    else:
        repaired = f", {report.n_repaired} of them repaired" if args.repair else ""
        print(
            f"{report.path}: {report.n_complete} / {report.n_samples} samples complete ({report.n_generated} made now"
            f"{repaired}, {report.n_skipped} already there) in {report.elapsed_s:.1f} s, "
            f"{report.samples_per_s:.2f} samples/s {report.workers_text()}"
            + ("" if report.scheduler == "in-process" else f" ({report.scheduler})")
        )
    return 0 if report.n_complete == report.n_samples else 1


def _verify(args: argparse.Namespace) -> int:
    from acoustisim.datasets.verify import verify

    report = verify(args.data)
    if args.json:
        print(json.dumps(report.as_dict()))
    else:
        status = "OK" if report.ok else "FAILED"
        print(f"{report.path}: {status}: {report.n_complete} / {report.n_samples} samples complete, "
              f"{len(report.corrupt)} corrupt")
        if report.missing:
            shown = ", ".join(str(i) for i in report.missing[:20])
            more = " ..." if len(report.missing) > 20 else ""
            print(f"  missing: {shown}{more} (run the same generate command again to complete them)")
        for index, problem in report.corrupt[:20]:
            print(f"  sample {index}: {problem}")
        if len(report.corrupt) > 20:
            print(f"  ... and {len(report.corrupt) - 20} more corrupt samples")
        if report.corrupt:
            print(f"  to make them again: acoustisim dataset generate SPEC.toml --out {report.path} --repair")
        if report.damaged_records:
            print(f"  {len(report.damaged_records)} sample(s) with an unreadable completion or checksum record "
                  "(made again by the same generate command)")
        if report.stray_files:
            print(f"  {len(report.stray_files)} stray *.partial file(s) from interrupted writes (harmless)")
    return 0 if report.ok else 1


def _info(args: argparse.Namespace) -> int:
    from acoustisim.datasets.info import dataset_info, format_info

    info = dataset_info(args.data)
    if args.json:
        print(json.dumps(info))
    else:
        print(format_info(info))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``dataset`` and its sub-commands."""
    parser = subparsers.add_parser("dataset", help="generate, verify and describe synthetic datasets (Zarr)",
                                   description="Synthetic datasets: generate (resumable, Dask), verify, info.")
    sub = parser.add_subparsers(dest="dataset_verb", metavar="ACTION")
    sub.required = True

    gen = sub.add_parser("generate", help="generate or resume a dataset from a spec file")
    gen.add_argument("spec", metavar="SPEC.toml", type=path_argument,
                     help="dataset specification (see examples/dataset_spec.toml)")
    gen.add_argument("--out", required=True, type=path_argument, metavar="DATA.zarr",
                     help="Zarr store to create or resume")
    gen.add_argument("--workers", type=int_at_least(0), default=None, metavar="N",
                     help="worker processes of the local Dask cluster (default: CPU count; 0: no Dask, this process)")
    gen.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="use a running dask.distributed scheduler (its workers must see --out at the same "
                          "absolute path; each is checked before any work)")
    gen.add_argument("--repair", action="store_true",
                     help="first verify the store and make again exactly the samples that fail (damaged chunks, "
                          "checksum mismatches)")
    gen.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    gen.add_argument("--json", action="store_true", help="print the run's report as one JSON object")
    gen.set_defaults(run=_generate)

    ver = sub.add_parser("verify", help="check completeness and per-sample checksums (exit 1 if not OK)")
    ver.add_argument("data", metavar="DATA.zarr", type=path_argument)
    ver.add_argument("--json", action="store_true")
    ver.set_defaults(run=_verify)

    inf = sub.add_parser("info", help="describe a dataset (card, counts, SNR histogram)")
    inf.add_argument("data", metavar="DATA.zarr", type=path_argument)
    inf.add_argument("--json", action="store_true")
    inf.set_defaults(run=_info)


