"""``binsonar import FILE --array ARRAY.toml -o PING.h5 [--json]``: a recording from another format.

Reads a multi-channel WAV (16/24/32-bit integer or float), a NumPy ``.npy``/``.npz``, a MATLAB
``.mat`` (v5 or v7.3) or a CSV file, described by an array description (TOML, with an
``[import]`` table: README, "Array description"), and writes a recording file (HDF5), ping range
by ping range. ``-o`` is checked before anything is read. With ``--json`` stdout holds one
object: ``input``, ``output``, ``n_pings``, ``n_samples``, ``sample_rate_hz``, ``stored_as``
("codes" or "volts").
"""

from __future__ import annotations

import argparse
import json


def run(args: argparse.Namespace) -> int:
    """Run ``binsonar import``; returns the exit code."""
    from binsonar.importers import import_recording

    path, source = import_recording(args.input, args.array, args.output, option="-o")
    summary = {
        "input": str(args.input),
        "output": str(path),
        "n_pings": int(source.n_pings),
        "n_samples": int(source.n_samples),
        "sample_rate_hz": float(source.header.sample_rate_hz),
        "stored_as": "codes" if source.header.stores_codes else "volts",
    }
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"{path}: {summary['n_pings']} ping(s) of {summary['n_samples']} samples at "
              f"{summary['sample_rate_hz']:g} Hz from {args.input} (stored as {summary['stored_as']})")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``import`` verb."""
    parser = subparsers.add_parser(
        "import",
        help="convert a WAV, NumPy, MATLAB or CSV file to a recording file",
        description="Convert a DAQ or lab file (WAV 16/24/32-bit integer or float, .npy, .npz, .mat v5/v7.3, CSV) "
                    "and its array description (TOML) to a recording file (HDF5).",
    )
    parser.add_argument("input", metavar="FILE", help="the file to import (.wav, .npy, .npz, .mat, .csv)")
    parser.add_argument("--array", required=True, metavar="ARRAY.toml",
                        help="array description of the file, with its [import] table (README: Array description)")
    parser.add_argument("-o", "--output", required=True, metavar="PING.h5", help="recording file to write")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.set_defaults(run=run)
