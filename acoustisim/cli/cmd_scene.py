"""``acoustisim scene``: list the built-in scenes, validate a scene, show what it holds.

- ``acoustisim scene list [--json]``
- ``acoustisim scene validate FILE_OR_NAME [--json]``
- ``acoustisim scene show FILE_OR_NAME [--json | --toml]`` (``--toml``: the scene's file, a
  starting point for your own: ``acoustisim scene show thesis-tank --toml > my-tank.toml``)

A bad scene raises ``SceneFileError``: the main wrapper prints one line and exits with 2.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from acoustisim.cli.arguments import add_limit_arguments, with_limits


def _list(args: argparse.Namespace) -> int:
    from scenes.builtin import builtin_scene_names

    names = list(builtin_scene_names())
    if args.json:
        print(json.dumps({"scenes": names}))
    else:
        print("\n".join(names))
    return 0


def _validate(args: argparse.Namespace) -> int:
    from acoustisim.preflight import preflight
    from scenes.file_access import shown_path
    from scenes.scene_file import load_scene

    scene = load_scene(args.scene)  # raises SceneFileError on any problem
    preflight(scene, source=shown_path(args.scene))  # one ping, the default solver, the limits in force
    if args.json:
        print(json.dumps({"scene": args.scene, "name": scene.name, "valid": True, "objects": len(scene.objects)}))
    else:
        print(f"{args.scene}: valid ({len(scene.objects)} objects, {scene.triangle_count} triangles)")
    return 0


def _text(summary: dict[str, Any]) -> str:
    medium, sonar, tank = summary["medium"], summary["sonar"], summary["tank"]
    lines = [f"scene {summary['name']}"]
    lines.append(
        f"  medium   {medium['water']} water, {medium['temperature_c']:g} C, {medium['salinity_ppt']:g} ppt:"
        f" c = {medium['sound_speed_m_s']:.2f} m/s, absorption {medium['absorption_db_per_m_at_centre_frequency']:.4f}"
        f" dB/m at {sonar['centre_frequency_hz'] / 1e3:g} kHz"
    )
    if tank is None:
        lines.append("  tank     none (free field)")
    else:
        lines.append(
            f"  tank     {tank['length_m']:g} x {tank['width_m']:g} m, water {tank['water_depth_m']:g} m deep,"
            f" walls {tank['wall_material']}, floor {tank['floor_material']}, surface {tank['surface_material']}"
        )
    x, y, z = sonar["position_m"]
    lines.append(
        f"  sonar    at ({x:g}, {y:g}, {z:g}) m, yaw {sonar['yaw_deg']:g} deg, pitch {sonar['pitch_deg']:g},"
        f" roll {sonar['roll_deg']:g}; d = {sonar['separation_m'] * 1e3:g} mm,"
        f" {sonar['centre_frequency_hz'] / 1e3:g} kHz, T = {sonar['pulse_duration_s'] * 1e6:g} us,"
        f" {sonar['sample_rate_hz'] / 1e6:g} MS/s, {sonar['adc_bits']} bits"
    )
    lines.append(f"  objects  {len(summary['objects'])}, {summary['triangle_count']} triangles in all")
    header = f"    {'name':<12} {'kind':<9} {'material':<15} {'triangles':>9}  bounds (m)"
    lines.append(header)
    for obj in summary["objects"]:
        lo, hi = obj["bounds_m"]
        bounds = "(" + ", ".join(f"{v:.3f}" for v in lo) + ") .. (" + ", ".join(f"{v:.3f}" for v in hi) + ")"
        lines.append(f"    {obj['name']:<12} {obj['kind']:<9} {obj['material']:<15} {obj['triangles']:>9}  {bounds}")
    return "\n".join(lines)


def _show(args: argparse.Namespace) -> int:
    from scenes.scene_file import load_scene
    from scenes.summary import scene_summary

    scene = load_scene(args.scene)
    if args.toml:
        from scenes.scene_file import scene_to_toml

        print(scene_to_toml(scene), end="")
        return 0
    summary = scene_summary(scene)
    if args.json:
        print(json.dumps(summary))
    else:
        print(_text(summary))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``scene`` verb and its sub-verbs."""
    parser = subparsers.add_parser(
        "scene",
        help="list, validate or show scenes",
        description="List the built-in scenes, validate a scene file, or show what a scene holds.",
    )
    actions = parser.add_subparsers(dest="scene_action", metavar="ACTION")
    actions.required = True

    listing = actions.add_parser("list", help="list the built-in scene names")
    listing.add_argument("--json", action="store_true", help="print one JSON object")
    listing.set_defaults(run=_list)

    validate = actions.add_parser("validate", help="check a scene file or built-in scene (exit 2 if bad)")
    validate.add_argument("scene", metavar="FILE_OR_NAME", help="scene file (TOML) or built-in scene name")
    validate.add_argument("--json", action="store_true", help="print one JSON object")
    add_limit_arguments(validate)
    validate.set_defaults(run=with_limits(_validate))

    show = actions.add_parser(
        "show", help="objects, kinds, materials, bounds, triangle counts, sonar pose, sound speed"
    )
    show.add_argument("scene", metavar="FILE_OR_NAME", help="scene file (TOML) or built-in scene name")
    form = show.add_mutually_exclusive_group()
    form.add_argument("--json", action="store_true", help="print one JSON object on stdout, nothing else")
    form.add_argument("--toml", action="store_true",
                      help="print the scene as a scene file (TOML; mesh paths absolute), e.g. to start your own")
    add_limit_arguments(show)
    show.set_defaults(run=with_limits(_show))
