"""``binsonar detect PING.h5 --method METHOD [--json]``: echoes per ping and channel.

The recording is read range of pings by range of pings (``binsonar.streaming``): memory does
not grow with its length. A WAV, NumPy, MATLAB or CSV file is read directly with
``--array ARRAY.toml`` (its array description, see ``binsonar import``).

Options common to every method are flags (``--average``, ``--bandpass LOW HIGH``,
``--pfa``, ``--noise-window START STOP``, ``--on-clipped``); any other method option is
``--option NAME=VALUE`` (``binsonar detect --list-options METHOD`` shows them). Clipped
channels are reported on stderr (and in the JSON), never silently used. Bad input
(unreadable, empty or truncated file, NaN samples, a template longer than the record, an
unknown method or option) prints one line and exits with 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any


def _value(text: str) -> Any:
    """An option value: int, float, bool, None, a JSON list, or the string itself."""
    lowered = text.strip().lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    if lowered in ("none", "null"):
        return None
    try:
        return json.loads(text)
    except ValueError:
        return text


def _options(args: argparse.Namespace) -> dict[str, Any]:
    from binsonar.recording import RecordingError

    options: dict[str, Any] = {}
    for item in args.option or []:
        name, sep, text = item.partition("=")
        if not sep or not name.strip():
            raise RecordingError(f"--option must be NAME=VALUE, got {item!r}")
        value = _value(text)
        options[name.strip().replace("-", "_")] = tuple(value) if isinstance(value, list) else value
    if args.pfa is not None:
        options["pfa"] = args.pfa
    if args.noise_window is not None:
        options["noise_window_s"] = tuple(args.noise_window)
    return options


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _report(result: Any, recording: Any, path: str) -> dict[str, Any]:
    pings = []
    for p, channels in enumerate(result.echoes):
        pings.append({
            "ping": p,
            "channels": [
                {
                    "channel": c,
                    "name": recording.channel_names[c] if c < len(recording.channel_names) else str(c),
                    "clipped": bool(result.clipped[p][c]),
                    "echoes": [
                        {
                            "tof_s": _finite(e.tof_s),
                            "amplitude": _finite(e.amplitude),
                            "snr_db": _finite(e.snr_db),
                            "score": _finite(e.score),
                            "tof_std_s": _finite(e.tof_std_s),
                        }
                        for e in echoes
                    ],
                }
                for c, echoes in enumerate(channels)
            ],
        })
    return {
        "file": path,
        "method": result.method,
        "sample_rate_hz": recording.sample_rate_hz,
        "n_pings": result.n_pings,
        "elapsed_s": result.elapsed_s,
        "options": {k: (list(v) if isinstance(v, tuple) else v) for k, v in result.options},
        "clipped": [list(row) for row in result.clipped],
        "pings": pings,
    }


def _beam_refinement(args: argparse.Namespace) -> Any:
    """The beam-aware refinement of each range's detections when ``--transducer-diameter-m`` is
    given (``refine_detection`` with its recording), else None."""
    if args.transducer_diameter_m is None:
        if args.beam_target is not None or args.wedge_angle_deg is not None:
            from binsonar.recording import RecordingError

            raise RecordingError("--beam-target and --wedge-angle-deg need --transducer-diameter-m")
        return None
    from binsonar.detection.seed import SEED_COMBINATIONS
    from binsonar.localization.beam_model import BeamModelConfig, PistonTransducers
    from binsonar.localization.beam_refine import BeamRefinementConfig, refine_detection
    from binsonar.recording import RecordingError

    envelope_peak = {"matched", "local-matched"}
    envelope_peak |= {c.name for c in SEED_COMBINATIONS if c.base in envelope_peak}
    if args.method not in envelope_peak:
        raise RecordingError(f"--transducer-diameter-m refines TOFs timed by the template's envelope peak "
                             f"({', '.join(sorted(envelope_peak))}); method {args.method!r} is not one")
    from binsonar.array_description import DIAMETER_RANGE_M

    diameter = args.transducer_diameter_m
    if not (math.isfinite(diameter) and DIAMETER_RANGE_M[0] <= diameter <= DIAMETER_RANGE_M[1]):
        raise RecordingError(f"--transducer-diameter-m must be within {DIAMETER_RANGE_M[0]:g}-{DIAMETER_RANGE_M[1]:g} m, "
                             f"got {diameter!r}")
    model = BeamModelConfig(target=args.beam_target or "vertical-edge", wedge_interior_angle_deg=args.wedge_angle_deg)
    transducers = PistonTransducers.uniform(diameter)
    config = BeamRefinementConfig(model=model)
    return lambda result, recording: refine_detection(result, recording, transducers, config)


def run(args: argparse.Namespace) -> int:
    """Run ``binsonar detect``; returns the exit code."""
    from binsonar.detection import METHODS, method_options
    from binsonar.importers import open_source
    from binsonar.recording import RecordingError, Template
    from binsonar.streaming import detect_source

    if args.list_options:
        if args.list_options not in METHODS:
            raise RecordingError(f"unknown detection method {args.list_options!r}; choose one of: {', '.join(METHODS)}")
        print(json.dumps({"method": args.list_options, "options": method_options(args.list_options)}, default=str))
        return 0
    if args.recording is None:
        raise RecordingError("detect: a recording file (PING.h5) is required")
    if args.method not in METHODS:
        raise RecordingError(f"unknown detection method {args.method!r}; choose one of: {', '.join(METHODS)}")
    refine = _beam_refinement(args)
    options = _options(args)
    with open_source(args.recording, args.array) as source:
        header = source.header
        template = None
        if args.template is not None:
            from binsonar.importers.settings import load_npy_vector

            template = Template(load_npy_vector(args.template, "template"), header.sample_rate_hz,
                                args.template_t0, "calibration-echo")
        bandpass = tuple(args.bandpass) if args.bandpass is not None else (
            "template" if args.bandpass_template else None)
        result = detect_source(
            source,
            args.method,
            template=template,
            average=True if args.average else None,
            bandpass_hz=bandpass,
            on_clipped=args.on_clipped,
            full_scale_v=args.full_scale_v,
            refine=refine,
            **options,
        )
    for p, row in enumerate(result.clipped):
        for c, clipped in enumerate(row):
            if clipped:
                action = "echoes dropped" if args.on_clipped == "drop" else "echoes flagged, unreliable"
                print(f"binsonar: warning: {args.recording}: ping {p}, channel {c} clipped ({action})", file=sys.stderr)
    if args.json:
        print(json.dumps(_report(result, header, str(args.recording))))
        return 0
    print(f"{args.recording}: method {result.method}, {result.n_pings} ping(s), {result.elapsed_s * 1e3:.2f} ms")
    for p, channels in enumerate(result.echoes):
        for c, echoes in enumerate(channels):
            name = header.channel_names[c] if c < len(header.channel_names) else str(c)
            flag = " [clipped]" if result.clipped[p][c] else ""
            if not echoes:
                print(f"  ping {p} {name:>6}: no echo{flag}")
            for e in echoes:
                std = f" +/- {e.tof_std_s * 1e9:.1f} ns" if math.isfinite(e.tof_std_s) else ""
                print(f"  ping {p} {name:>6}: tof {e.tof_s * 1e6:.4f} us{std}, amplitude {e.amplitude:.4g},"
                      f" snr {e.snr_db:.1f} dB, score {e.score:.3g}{flag}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``detect`` verb."""
    from binsonar.detection.api import CLIPPED_POLICIES
    from binsonar.detection.registry import METHODS

    parser = subparsers.add_parser(
        "detect",
        help="detect echoes and their times of flight in a recording",
        description="Detect echoes and estimate their times of flight (per ping and channel).",
    )
    parser.add_argument("recording", nargs="?",
                        help="recording file (HDF5, format 1.x), or a WAV, .npy, .npz, .mat or .csv file with --array")
    parser.add_argument("--array", default=None, metavar="ARRAY.toml",
                        help="array description of a WAV, NumPy, MATLAB or CSV file (see binsonar import)")
    parser.add_argument("--method", default="matched", metavar="METHOD",
                        help=f"detection method (default matched): {', '.join(METHODS)}")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.add_argument("--pfa", type=float, default=None, help="design false-alarm probability")
    parser.add_argument("--noise-window", type=float, nargs=2, metavar=("START_S", "STOP_S"),
                        help="noise-only window (s after the trigger)")
    parser.add_argument("--average", action="store_true", help="average all pings first (seed eq. 4.33)")
    parser.add_argument("--bandpass", type=float, nargs=2, metavar=("LOW_HZ", "HIGH_HZ"),
                        help="zero-phase band-pass first")
    parser.add_argument("--bandpass-template", action="store_true",
                        help="zero-phase band-pass over the template's -20 dB band first")
    parser.add_argument("--template", default=None, metavar="FILE.npy",
                        help="use this template (a calibration echo, at the recording's sample rate)")
    parser.add_argument("--template-t0", type=float, default=0.0, metavar="SECONDS",
                        help=("time of the --template's first sample relative to its reference instant "
                              "(s; write a negative value with '=', e.g. --template-t0=-3.95e-6)"))
    parser.add_argument("--full-scale-v", type=float, default=None, help="ADC full scale (V) for clipping checks")
    parser.add_argument("--on-clipped", choices=CLIPPED_POLICIES, default="flag",
                        help="clipped channels: flag their echoes (default), drop them, or fail (exit 2)")
    parser.add_argument("--transducer-diameter-m", type=float, default=None, metavar="D",
                        help=("refine the matched filter's TOFs for the transducers' beams: baffled pistons of this "
                              "diameter (m; the V318's 19 mm = 0.019), all on the head's boresight"))
    parser.add_argument("--beam-target", choices=("point", "vertical-edge"), default=None,
                        help="target model of the beam refinement (default vertical-edge)")
    parser.add_argument("--wedge-angle-deg", type=float, default=None, metavar="DEG",
                        help="the edge is a rigid wedge of this interior angle facing the sonar (beam refinement)")
    parser.add_argument("--option", action="append", metavar="NAME=VALUE", help="any other method option")
    parser.add_argument("--list-options", metavar="METHOD", default=None,
                        help="print a method's options and defaults as JSON, and exit")
    parser.set_defaults(run=run)
