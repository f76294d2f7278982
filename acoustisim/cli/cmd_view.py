"""``acoustisim view``: look at a scene, its echo paths and localisation results in 3-D.

``acoustisim view FILE_OR_NAME [--ping PING.h5 [--ping-index I]] [--results RESULTS.json]
[--png OUT.png] [--html OUT.html] [--camera top|side|sonar|perspective|targets] [--echo N|NAME]
[--no-paths] [--max-order N] [--channels LIST] [--max-paths N] [--max-diffuse N] [--edge-elements] [--no-beam]
[--no-labels] [--size WxH] [--title TEXT]``

Paths: the ping's true arrivals with ``--ping``, else traced now (``acoustisim.propagation``),
unless ``--no-paths``. Rendering is off-screen when ``--png`` or ``--html`` is given; without
them a window opens, which needs a display (else exit code 2 with a one-line message).
"""

from __future__ import annotations

import argparse

from acoustisim.cli.arguments import int_at_least
from acoustisim.errors import InputError


def _echo(text: str) -> int | str:
    return int_at_least(0)(text) if text.strip().lstrip("-").isdigit() else text


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels, e.g. 1200x800, got {text!r}") from None
    if not (16 <= width <= 8192 and 16 <= height <= 8192):
        raise argparse.ArgumentTypeError(f"window size must be 16..8192 pixels per side, got {text!r}")
    return width, height


def _channels(text: str) -> tuple[int, ...]:
    names = {"left": 0, "centre": 1, "center": 1, "right": 2, "0": 0, "1": 1, "2": 2}
    parts = [p.strip().lower() for p in text.split(",") if p.strip()]
    if not parts or any(p not in names for p in parts):
        raise argparse.ArgumentTypeError(f"expected channels among left,centre,right, got {text!r}")
    return tuple(sorted({names[p] for p in parts}))


def _run(args: argparse.Namespace) -> int:
    from acoustisim.viz.cameras import CAMERA_NAMES
    from acoustisim.viz.render import ViewOptions, export_html, has_display, show_scene
    from acoustisim.viz.snapshot import render_png
    from binsonar.files import atomic_output, check_output_file
    from scenes.scene_file import load_scene

    if args.camera not in CAMERA_NAMES:  # argparse already restricts it; kept for API callers
        raise InputError(f"--camera: unknown preset {args.camera!r}")
    if args.png is None and args.html is None and not has_display():
        raise InputError("view: no display here; write an image with --png OUT.png or a page with --html OUT.html")
    outputs = [(option, path) for option, path in (("--png", args.png), ("--html", args.html)) if path is not None]
    for option, path in outputs:  # before the work: a refused path costs nothing
        check_output_file(path, option)
    scene = load_scene(args.scene)
    sonar = scene.sonar
    paths = None
    truths = None
    if args.ping is not None:
        from acoustisim.viz.ping_file import load_ping

        ping = load_ping(args.ping, sonar, args.ping_index)
        sonar, paths = ping.sonar, ping.paths
        truths = list(ping.truths) or None
    if args.no_paths:
        paths = None
    elif paths is None:
        from acoustisim.propagation import SolverConfig, solve

        config = SolverConfig() if args.max_order is None else SolverConfig(max_order=args.max_order)
        paths = solve(scene, sonar, config)
    options = ViewOptions(channels=args.channels, max_paths=args.max_paths or None,
                          max_diffuse=args.max_diffuse or None, edge_elements=args.edge_elements,
                          echo=args.echo, show_beam=not args.no_beam, labels=not args.no_labels)
    common = dict(sonar=sonar, truths=truths, options=options, camera=args.camera, title=args.title,
                  window_size=args.size)
    written = []
    for option, path in outputs:
        with atomic_output(path, option) as temporary:  # the umask's mode; links and devices refused
            if option == "--png":
                render_png(scene, temporary, paths, args.results, **common)
            else:
                export_html(scene, temporary, paths, args.results, **{**common, "window_size": args.size or (1200, 800)})
        written.append(path)
    if written:
        for path in written:
            print(path)
        return 0
    plotter = show_scene(scene, paths, args.results, off_screen=False, **common)
    plotter.show()
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``view`` verb."""
    parser = subparsers.add_parser(
        "view",
        help="3-D view of a scene, its echo paths and localisation results (window, PNG or HTML)",
        description=__doc__.split("\n\n")[-1] if __doc__ else None,
    )
    parser.add_argument("scene", metavar="FILE_OR_NAME", help="scene file (.toml) or built-in scene name")
    parser.add_argument("--ping", metavar="PING.h5", help="recording file: pose and, if simulated, true paths")
    parser.add_argument("--ping-index", type=int_at_least(0), default=0, metavar="I",
                        help="which ping of the file (default 0)")
    parser.add_argument("--results", metavar="RESULTS.json", help="localisation results (binsonar localize --json)")
    parser.add_argument("--png", metavar="OUT.png", help="render off-screen to this PNG file")
    parser.add_argument("--html", metavar="OUT.html", help="write a self-contained interactive HTML page")
    parser.add_argument("--camera", choices=("top", "side", "sonar", "perspective", "targets"),
                        default="perspective",
                        help="camera preset (default perspective; targets: top view of the sonar and targets)")
    parser.add_argument("--echo", type=_echo, metavar="N|NAME",
                        help="draw the time-of-flight ellipsoids of echo N (rank by delay among the centre "
                             "channel's specular and edge echoes) or of the first echo off surface NAME")
    parser.add_argument("--no-paths", action="store_true", help="draw no paths (neither traced nor the ping's)")
    parser.add_argument("--max-order", type=int_at_least(1), metavar="N", help="reflection order when tracing")
    parser.add_argument("--channels", type=_channels, default=(0, 1, 2), metavar="LIST",
                        help="receiver channels whose paths are drawn, e.g. centre or left,right (default all)")
    parser.add_argument("--max-paths", type=int_at_least(0), default=10_000, metavar="N",
                        help="draw only the N strongest paths (0: all; default 10000)")
    parser.add_argument("--max-diffuse", type=int_at_least(0), default=400, metavar="N",
                        help="of those, draw only the N strongest diffuse paths (0: all; default 400)")
    parser.add_argument("--edge-elements", action="store_true",
                        help="draw every edge-diffraction element instead of one line per edge arrival")
    parser.add_argument("--no-beam", action="store_true", help="hide the transmit beam cones")
    parser.add_argument("--no-labels", action="store_true", help="do not write the objects' names")
    parser.add_argument("--size", type=_size, default=None, metavar="WxH",
                        help="image or window size in pixels (default: a 1400 pixel wide PNG as tall as the view "
                             "needs; a 1200x800 window or page)")
    parser.add_argument("--title", metavar="TEXT", help="title text (default: the scene's name)")
    parser.set_defaults(run=_run)
