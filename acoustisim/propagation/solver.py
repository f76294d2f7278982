"""``solve(scene, sonar, config) -> Paths``: every path from the transmitter to each receiver.

The solve checks the pose (:func:`check_sonar`), builds the pose's :class:`SolveContext`, and
asks the engine ``config.backend`` names (:func:`~acoustisim.propagation.engine.engine_for`)
for each mechanism named in ``config.mechanisms``, in the order of
:data:`~acoustisim.propagation.config.MECHANISMS` (direct, specular, edge, diffuse), each
starting its path ids at the next free one. With ``config.shadows`` the specular legs are tested
against the scene without its smooth obstacles, whose diffracted shadows then weigh the direct
and specular rows (:func:`~acoustisim.propagation.shadows.shadow_rows`, engine-independent:
rows and transfer functions into ``Paths.responses``). The engine then assembles the rows
(derived columns, order by channel and delay, amplitude floor judged across the pulse band).
Last, the engine-independent steps on the assembled rows: the coherent roughness of specular
rows on rough surfaces (:func:`~acoustisim.propagation.roughness.apply_coherent_roughness`:
their ``roughness_m2`` and their loss at f0), and elastic echoes
(:mod:`~acoustisim.propagation.elastic_echoes`, ``config.elastic_echoes``; a shadowed echo's
transfer function multiplies its shadow's).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from acoustisim.preflight import check_solve
from acoustisim.propagation.apex_response import apex_response
from acoustisim.propagation.config import MECHANISMS, SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.engine import engine_for
from acoustisim.propagation.paths import PATH_DTYPE, Paths
from acoustisim.propagation.prepared import PreparedScene, prepare
from acoustisim.propagation.roughness import apply_coherent_roughness
from acoustisim.propagation.shadows import shadow_rows
from acoustisim.scene import Scene
from acoustisim.sonar import CHANNEL_NAMES, SonarHead

def check_sonar(prepared: PreparedScene, sonar: SonarHead) -> None:
    """Raise :class:`InputError` if a transducer touches or is inside a surface, or a receive-only
    transducer sits on the transmitter.

    "Touching" is closer than the piston radius a to a tank boundary or an object surface: the
    face of the piston would cut the surface.
    """
    scene = prepared.scene
    a = float(sonar.piston_radius_m)
    tx = np.asarray(sonar.transmitter_position, dtype=float)
    positions = np.asarray(sonar.receiver_positions, dtype=float)
    for i, name in enumerate(CHANNEL_NAMES):
        if i != 1 and np.linalg.norm(positions[i] - tx) < a:
            raise InputError(
                f"sonar: the {name} receiver at {positions[i].round(4).tolist()} m coincides with the transmitter "
                f"at {tx.round(4).tolist()} m (closer than the piston radius {a} m)"
            )
    if scene.tank is not None:
        inside = scene.tank.contains(positions, margin_m=a)
        if not np.all(inside):
            i = int(np.argmin(inside))
            raise InputError(
                f"sonar.position_m: the {CHANNEL_NAMES[i]} transducer at {positions[i].round(4).tolist()} m is "
                f"outside the water or within {a} m of a tank boundary"
            )
    bounds = prepared.object_bounds
    # (object, transducer) pairs within the piston radius of the object's box, all at once
    close = np.all((positions[None, :, :] >= bounds[:, None, 0, :] - a)
                   & (positions[None, :, :] <= bounds[:, None, 1, :] + a), axis=2)
    for j in np.flatnonzero(np.any(close, axis=1)):
        obj, near = scene.objects[j], close[j]
        candidates = positions[near]
        primitive = obj.primitive
        if isinstance(primitive, SpherePrimitive):
            distance = np.linalg.norm(candidates - np.asarray(primitive.center_m), axis=1) - primitive.radius_m
        elif isinstance(primitive, CylinderPrimitive):
            local = candidates - np.asarray(primitive.center_m)
            along = local @ np.asarray(primitive.axis)
            radial = np.linalg.norm(local - np.outer(along, primitive.axis), axis=1) - primitive.radius_m
            axial = np.abs(along) - 0.5 * primitive.length_m
            outside = np.hypot(np.maximum(radial, 0.0), np.maximum(axial, 0.0))
            distance = np.where((radial < 0) & (axial < 0), np.maximum(radial, axial), outside)
        else:
            import trimesh

            # trimesh's sign convention: positive inside
            distance = -trimesh.proximity.signed_distance(obj.mesh, candidates)
        if np.any(distance < a):
            i = int(np.flatnonzero(near)[int(np.argmin(distance))])
            raise InputError(
                f"sonar.position_m: the {CHANNEL_NAMES[i]} transducer at {positions[i].round(4).tolist()} m touches "
                f"or is inside object {obj.name!r} (closer than the piston radius {a} m)"
            )


def solve(scene: Scene | PreparedScene, sonar: SonarHead | None = None,
          config: SolverConfig | None = None) -> Paths:
    """Every transmitter-to-receiver path of ``scene`` for one sonar pose.

    Parameters
    ----------
    scene : Scene or PreparedScene
        A prepared scene (:func:`acoustisim.propagation.prepared.prepare`) skips the per-scene
        work (mesh checks, Embree build), for many poses of one scene.
    sonar : SonarHead, optional
        The pose; defaults to ``scene.sonar``.
    config : SolverConfig, optional
        Defaults to ``SolverConfig()``.

    Returns
    -------
    Paths
        Rows sorted by channel then delay.

    Raises
    ------
    InputError
        Degenerate meshes, a transducer touching a surface or coincident with the transmitter.
    """
    check_solve(scene, sonar, config)  # types and resource limits before any work (acoustisim.preflight)
    config = SolverConfig() if config is None else config
    if not isinstance(config, SolverConfig):
        raise InputError(f"solver config must be a SolverConfig, got {type(config).__name__}")
    prepared = prepare(scene)
    sonar = prepared.scene.sonar if sonar is None else sonar
    check_sonar(prepared, sonar)
    context = SolveContext.build(prepared.scene, sonar, prepared.raycaster)
    engine = engine_for(config)
    obstacles = prepared.smooth_obstacles if config.shadows else None
    parts: list[NDArray[Any]] = []
    responses: list[Any] = []
    next_id = 0
    for mechanism in MECHANISMS:  # in this order: it fixes the order of rows with equal delays
        if mechanism not in config.mechanisms:
            continue
        mechanism_context = context.with_first_path_id(next_id)
        if mechanism == "direct":
            rows = engine.direct_rows(mechanism_context)
        elif mechanism == "specular":
            legs_scene = prepared if obstacles is None else prepared.without_smooth_obstacles()
            rows = engine.specular_rows(mechanism_context, legs_scene, config.max_order, config.max_curved_per_path)
        elif mechanism == "edge":
            rows = engine.edge_rows(mechanism_context, config, prepared)
            if np.any(rows["response_id"] >= 0):  # Keller's apex rows name the first response
                responses.append(apex_response(context))
        else:
            rows = engine.diffuse_rows(mechanism_context, config, prepared)
        rows = np.asarray(rows, dtype=PATH_DTYPE)
        parts.append(rows)
        if rows.size:
            next_id = max(next_id, int(rows["path_id"].max()) + 1)
    if obstacles is not None:
        for i, part in enumerate(parts):
            parts[i], shadows = shadow_rows(part, context, obstacles, len(responses))
            responses.extend(shadows)
    rows = engine.assemble_rows(parts, context, config)
    # coherent roughness: every specular reflection on a rough surface, exp(-S k^2) (both engines)
    apply_coherent_roughness(rows, prepared, context)
    if config.elastic_echoes:  # echoes off elastic posts, spheres and pipes get their transfer functions
        from acoustisim.propagation.elastic_echoes import attach_elastic_echoes

        rows, responses = attach_elastic_echoes(rows, tuple(responses), prepared, context)
    return Paths.adopt(rows, prepared.scene.surface_names, context.centre_frequency_hz, context.sound_speed_m_s,
                       tuple(responses))


__all__ = ["check_sonar", "solve"]
