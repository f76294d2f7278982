"""``binsonar localize PING.h5 [--method DETECTOR] [--pfa X] [--sound-speed C] [--no-beam] [--no-joint] [--json]``: targets per ping.

Beam-aware by default: when the recording's array description gives its transducers as pistons,
each target's echoes are re-timed with the echo the beam makes and their stds follow that
echo's SNR and bandwidth (``binsonar.localization.beam_targets``); ``--no-beam`` keeps the plain
matched filter's times (with ``--tof-floor-ns``). Beam-aware, a joint search over the three
channels also finds targets whose echo crosses the detector on one channel only, or on none,
when the channels together hold the energy (``binsonar.localization.joint_search``);
``--no-joint`` turns it off.

``--json`` prints one object: ``source``, ``method``, ``sound_speed_m_s``, ``sound_speed_source``
("recording" or "argument"), ``beam_aware`` and ``beam`` (how the echoes were timed), ``pings`` (per ping: ``ping``, ``pose`` or null,
``unassociated_echoes``, ``targets``) and ``fused`` (targets fused over pings with known poses).
Each target has ``class`` (point, cylinder, plane, unknown), ``status`` ("ok" or the problem, e.g.
"radius-not-observable", "no-centre-echo", "invalid-path-lengths"), ``message``, ``range_m``,
``range_std_m``, ``bearing_deg``, ``bearing_std_deg``, ``position_head_m`` and
``position_head_std_m``, ``position_tank_m`` and ``position_tank_std_m`` (null without a pose),
``radius_m`` (null when not fitted, "inf" for a plane), ``radius_std_m``, ``path_lengths_m``,
``path_length_std_m``, ``tof_s`` and ``tof_std_s`` (left, centre, right; null where missing) and
``echo_model`` ("point" or "vertical-edge": the expected echo the times came from; null for plain
times). Non-finite numbers are null.

The recording is detected range of pings by range of pings (``binsonar.streaming``): memory
does not grow with its length. A WAV, NumPy, MATLAB or CSV file is read directly with
``--array ARRAY.toml``.
"""

from __future__ import annotations

import argparse
import json
import math


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``localize`` verb."""
    parser = subparsers.add_parser(
        "localize",
        help="localise and classify reflectors (targets per ping, fused across pings with poses)",
        description="Detect echoes, associate them across channels, fit point, cylinder and plane models "
                    "and classify each target; tank positions when the recording has poses.",
    )
    parser.add_argument("recording",
                        help="recording file (HDF5), or a WAV, .npy, .npz, .mat or .csv file with --array")
    parser.add_argument("--array", default=None, metavar="ARRAY.toml",
                        help="array description of a WAV, NumPy, MATLAB or CSV file (see binsonar import)")
    parser.add_argument("--method", default="ca-cfar",
                        help="detection method (default: ca-cfar, which reports every echo; see binsonar detect)")
    parser.add_argument("--sound-speed", type=float, default=None, dest="sound_speed",
                        help="sound speed (m/s), used when the recording has none")
    parser.add_argument("--no-fuse", action="store_true", help="do not fuse targets across pings")
    parser.add_argument("--tof-floor-ns", type=float, default=50.0, dest="tof_floor_ns",
                        help="systematic TOF uncertainty added in quadrature to each plain-timed echo's std "
                             "(ns, default 50)")
    parser.add_argument("--pfa", type=float, default=None,
                        help="the detector's false-alarm probability (default the method's, 1e-6 for ca-cfar); "
                             "lower values find weak echoes next to strong ones, and the association's geometric "
                             "gates and the model tests reject most of the false alarms")
    parser.add_argument("--no-beam", action="store_true", dest="no_beam",
                        help="keep the plain matched filter's times (default: re-time each target's echoes "
                             "with the beams the array description gives)")
    parser.add_argument("--no-joint", action="store_true", dest="no_joint",
                        help="no joint search over the three channels (default: beam-aware, also find targets "
                             "whose echo crosses the detector on one channel only, at 1e-3 false alarms per ping)")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.set_defaults(run=run)


def _fmt(v: float | None, spec: str) -> str:
    return "-" if v is None or not math.isfinite(v) else format(v, spec)


def run(args: argparse.Namespace) -> int:
    """Run ``localize``; returns the exit code."""
    from binsonar.importers import open_source
    from binsonar.localization.pipeline import LocalizationConfig
    from binsonar.recording import RecordingError
    from binsonar.streaming import localize_source

    if args.sound_speed is not None and not (math.isfinite(args.sound_speed) and 1000 < args.sound_speed < 2000):
        raise RecordingError(f"--sound-speed: out of range (1000-2000 m/s): {args.sound_speed!r}")
    if not (math.isfinite(args.tof_floor_ns) and args.tof_floor_ns >= 0):
        raise RecordingError(f"--tof-floor-ns: must be >= 0, got {args.tof_floor_ns!r}")
    from binsonar.detection import METHODS

    if args.method not in METHODS:
        raise RecordingError(f"unknown detection method {args.method!r}; choose one of: {', '.join(METHODS)}")
    if args.tof_floor_ns > 1e6:
        raise RecordingError(f"--tof-floor-ns: must be at most 1e6 ns, got {args.tof_floor_ns!r}")
    from binsonar.localization.joint_search import JointSearchConfig

    config = LocalizationConfig(fuse=not args.no_fuse, tof_floor_s=args.tof_floor_ns * 1e-9, beam=not args.no_beam,
                                joint_search=JointSearchConfig(enabled=not args.no_joint))
    options = {}
    if args.pfa is not None:
        if not (math.isfinite(args.pfa) and 0.0 < args.pfa < 0.5):
            raise RecordingError(f"--pfa: must be within (0, 0.5), got {args.pfa!r}")
        options["pfa"] = args.pfa
    with open_source(args.recording, args.array) as source:
        result = localize_source(source, method=args.method, sound_speed_m_s=args.sound_speed, config=config,
                                 **options)
    if args.json:
        print(json.dumps(result.to_dict()))
        return 0
    print(f"{args.recording}: method {result.method}, c = {result.sound_speed_m_s:.2f} m/s "
          f"({result.sound_speed_source}), beam-aware timing: {result.beam}")
    for k, targets in enumerate(result.targets):
        print(f"ping {k}: {len(targets)} target(s)")
        for t in targets:
            tank = "" if t.position_tank_m is None else (
                " tank (" + ", ".join(_fmt(float(v), ".4f") for v in t.position_tank_m) + ") m")
            print(f"  {t.cls:8s} range {_fmt(t.range_m, '.4f')} +- {_fmt(t.range_std_m, '.2g')} m, "
                  f"bearing {_fmt(t.bearing_deg, '.2f')} +- {_fmt(t.bearing_std_deg, '.2g')} deg, "
                  f"radius {_fmt(t.radius_m, '.4f')} +- {_fmt(t.radius_std_m, '.2g')} m{tank} [{t.status}]"
                  + (f" ({t.echo_model} echo)" if t.echo_model else ""))
    for f in result.fused:
        print(f"fused over {len(f.pings)} pings: {f.cls} at ("
              + ", ".join(_fmt(float(v), ".4f") for v in f.position_tank_m)
              + f") m, radius {_fmt(f.radius_m, '.4f')} +- {_fmt(f.radius_std_m, '.2g')} m [{f.status}]")
    return 0
