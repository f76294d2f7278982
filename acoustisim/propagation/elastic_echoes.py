"""Elastic echoes: the solve's step that gives echoes off elastic posts, spheres and pipes their
transfer functions (issue 17).

Which rows
----------
A specular row's interaction is *curved* when it lies on a sphere, on the side of a cylinder
(not on its flat caps) or on a smooth user mesh; it is *elastic* when, besides, the object is a
sphere, post or cylinder whose body (:func:`acoustisim.scattering.echo.object_body`) is an
elastic solid (shear speed > 0) or a pipe (a cylinder with a wall thickness and a fill), and
whose k a at the band's top is at most :data:`MAX_KA`. Rigid,
pressure-release and fluid bodies keep today's echo: their exact echoes are today's up to the
creeping waves and 1/(ka) corrections (phase 1's tests), and a fluid body's internal echoes are
not modelled. Every row with at least one elastic interaction whose bistatic angle is at most
:data:`MAX_BISTATIC_RAD` (90 deg) gets an
:class:`~acoustisim.propagation.elastic_responses.ElasticEchoResponse`, one factor per such
interaction.

Geometry (physics)
------------------
Each elastic interaction at P is the echo of a point source and a receiver: the transmitter and
receiver unfolded through the plane mirrors of the row (walls, floor, surface, polyhedral
faces, cylinder caps) on each side of P. Through plane mirrors the image lies on the straight
extension of the leg that reaches P, at the path length travelled since the transmitter (so
S' = P - u_in L_in, R' = P + u_out L_out), which is exact; another curved interaction on the way
stops the unfolding there and its point is taken as the source (or receiver), which is the
point-source approximation of a reflected wavefront (its curvature is left out; such chains
are rare and weak). Rows via the floor or the surface thus see a post at an elevation (phase 1:
normal-incidence coefficients at f cos(e)).

Amplitude
---------
The ``amplitude`` column (the echo's pressure factor at the centre frequency f0) is multiplied
by |H(f0)| (the product over the row's factors), so that the arrivals table states the elastic
echo's level at f0; the amplitude floor was judged before, on today's rows.

Method
------
Plain numpy, per solve: the rows' unfolding and geometry, their :class:`ElasticRows` (one per
body: shape, radius, body, material), and H(f0) from one coefficient table per body at the
distinct f0 cos(e). The transfer functions over the band are computed when synthesis asks
(:mod:`acoustisim.propagation.elastic_responses`). Both engines give the same rows, hence the
same responses.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.errors import InputError
from acoustisim.geometry import CylinderPrimitive, SpherePrimitive
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.elastic_responses import BAND_LEVEL_DB, SPAN_LEVEL_DB, ElasticEchoResponse, ElasticRows
from acoustisim.propagation.paths import MAX_INTERACTIONS, PathKind, Paths
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.scattering.bodies import Body, Elastic, Fluid, Shell
from acoustisim.scattering.echo import EchoGeometry, EchoTarget, echo_target_for
from acoustisim.scattering.echo_series import todays_echo

__all__ = ("INTERNAL_ARRIVAL_DTYPE", "MAX_BISTATIC_RAD", "MAX_KA", "SIDE_TOLERANCE_M", "attach_elastic_echoes",
           "curved_interactions", "elastic_targets", "flat_rows", "internal_arrival_table", "is_elastic_body",
           "unfolded_ends")

MAX_BISTATIC_RAD = 0.5 * np.pi
"""Largest bistatic angle (rad) at the object whose echo gets the elastic transfer function: 90
deg, a reflection at 45 deg or less from the normal. The transfer function is the exact echo over
geometric optics; for a rigid post (25-75 mm, 150-500 kHz) it stays within 0.2 dB of 1 up to 90
deg, is off by 0.6-2 dB at 120 deg, and near forward (grazing reflections, the far-wall chains
of the tank) the exact scattered field is the wave that forms the shadow, +5 to +35 dB over the
grazing reflection: it belongs with the occluded incident field, not with this row. Rows beyond
keep today's reflection."""

MAX_KA = 600.0
"""Largest k a (at the top of the synthesised band) of an object whose echo gets its transfer
function: the series takes about k a + 30 orders at every bin, and beyond a few hundred the
boundary systems' Bessel functions underflow (a fast-shear solid's, e.g. steel from ka ~ 1000).
At the thesis pulse (band top 1.3 MHz) this is a radius of 11 cm: the tank's posts and pipe,
the clutter experiment's objects are well inside; the curvature study's 0.3-1.5 m steel
cylinders keep today's echo."""

SIDE_TOLERANCE_M = 1e-6
"""A point within this distance (m) of a cylinder's side radius, and this far inside its caps,
is on its curved side (the solver's specular points lie on it to ~1e-12 m)."""

INTERNAL_ARRIVAL_DTYPE = np.dtype([
    ("path_id", np.int64),        # the echo's path (Paths.rows / the arrivals table)
    ("channel", np.int8),         # 0 left, 1 centre, 2 right
    ("object_id", np.int16),      # the elastic object (index into surface_names)
    ("arrival", "S64"),           # its name, e.g. b"compressional through the diameter"
    ("delay_s", np.float64),      # when it arrives (s): the echo's delay plus after_echo_s
    ("after_echo_s", np.float64),  # after the echo's specular delay (s)
    ("level_db", np.float64),     # its level in the sonar's echo, dB re the echo's peak (monostatic)
])
"""One row per internal arrival of each elastic echo (``/truth/internal_arrivals``)."""


def _band_top_hz(context: SolveContext) -> float:
    """The top of the band synthesis fills (the pulse 100 dB below its peak)."""
    from acoustisim.synthesis.transducer import pulse_band_top_hz

    return pulse_band_top_hz(context.sonar.pulse, BAND_LEVEL_DB)


def is_elastic_body(body: Body) -> bool:
    """An elastic solid (c_S > 0) or a pipe: a body whose echo rings."""
    return isinstance(body, Shell) or (isinstance(body, Elastic) and not body.is_fluid)


def curved_interactions(rows: NDArray[Any], prepared: PreparedScene, n_boundaries: int) -> NDArray[np.bool_]:
    """(n, MAX_INTERACTIONS): interaction on a sphere, a cylinder's side or a smooth mesh."""
    ids = rows["object_ids"].astype(np.int64)
    points = rows["points_m"]
    curved = np.zeros(ids.shape, dtype=bool)
    for j, obj in enumerate(prepared.scene.objects):
        here = ids == n_boundaries + j
        if not here.any():
            continue
        primitive = obj.primitive
        if isinstance(primitive, SpherePrimitive):
            curved |= here
        elif isinstance(primitive, CylinderPrimitive):
            local = points[here] - np.asarray(primitive.center_m)
            axis = np.asarray(primitive.axis)
            along = local @ axis
            radial = np.linalg.norm(local - np.outer(along, axis), axis=1)
            side = (np.abs(radial - primitive.radius_m) <= SIDE_TOLERANCE_M) & (
                np.abs(along) < 0.5 * primitive.length_m - SIDE_TOLERANCE_M)
            curved[here] = side
    for reflector in prepared.smooth:
        curved |= ids == reflector.surface
    return curved


def unfolded_ends(rows: NDArray[Any], curved: NDArray[np.bool_], hits: NDArray[np.int64], slots: NDArray[np.int64],
                   transmitter: NDArray[np.float64], receivers: NDArray[np.float64]
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The unfolded source and receiver (h, 3) of interactions ``slots`` of rows ``hits``."""
    sub = rows[hits]
    order = sub["order"].astype(np.int64)
    n = hits.size
    # chain[i] = transmitter, points..., receiver (padded with the receiver after the last point)
    chain = np.empty((n, MAX_INTERACTIONS + 2, 3))
    chain[:, 0] = transmitter
    receiver = receivers[sub["channel"].astype(np.int64)]
    for i in range(MAX_INTERACTIONS):
        chain[:, i + 1] = np.where((i < order)[:, None], sub["points_m"][:, i], receiver)
    chain[:, MAX_INTERACTIONS + 1] = receiver
    legs = np.linalg.norm(np.diff(chain, axis=1), axis=2)  # (n, MAX + 1): leg i ends at chain[i + 1]
    walked = np.concatenate([np.zeros((n, 1)), np.cumsum(legs, axis=1)], axis=1)  # length to chain[i]
    curved_sub = curved[hits]
    index = np.arange(n)
    here = slots + 1  # position of the interaction in the chain
    # the nearest curved interaction before (or the transmitter, 0) and after (or the receiver)
    before = np.zeros(n, dtype=np.int64)
    after = order + 1
    for i in range(MAX_INTERACTIONS):
        is_curved = curved_sub[:, i] & (i < order)
        before = np.where(is_curved & (i + 1 < here), i + 1, before)
        after = np.where(is_curved & (i + 1 > here) & (i + 1 < after), i + 1, after)
    point = chain[index, here]
    incoming = point - chain[index, here - 1]
    outgoing = chain[index, here + 1] - point
    length_in = walked[index, here] - walked[index, before]
    length_out = walked[index, after] - walked[index, here]
    source = point - incoming / np.linalg.norm(incoming, axis=1)[:, None] * length_in[:, None]
    image_receiver = point + outgoing / np.linalg.norm(outgoing, axis=1)[:, None] * length_out[:, None]
    return source, image_receiver


def flat_rows(target: EchoTarget, geometry: EchoGeometry, water: Fluid
               ) -> tuple[EchoGeometry, NDArray[np.float64], NDArray[np.complex128]]:
    """The flat geometry, cos(e) and conj(C) of rows (elastic_responses' module docstring)."""
    if target.shape == "sphere":
        ones = np.ones(geometry.n_rows)
        return geometry, ones, ones.astype(complex)
    flat = EchoGeometry(geometry.source_distance_m, geometry.receiver_distance_m, geometry.bistatic_angle_rad,
                        np.zeros(geometry.n_rows))
    g_row, length = todays_echo(target, geometry, water)
    g_flat, planar = todays_echo(target, flat, water)
    compression = planar / length
    return flat, compression, np.conj(compression * g_flat / g_row)


def elastic_targets(prepared: PreparedScene, context: SolveContext, bodies: Mapping[str, Body] | None = None
                    ) -> dict[int, tuple[EchoTarget, NDArray[np.float64], NDArray[np.float64] | None]]:
    """The objects whose echoes get transfer functions, by surface index (into
    ``scene.surface_names``): their :class:`~acoustisim.scattering.echo.EchoTarget`, centre and
    axis (:func:`~acoustisim.scattering.echo.echo_target_for`).

    An object qualifies when its body is elastic (:func:`is_elastic_body`) or it is named in
    ``bodies`` (whose bodies replace the objects' own), and its k a at the band's top is at most
    :data:`MAX_KA`. Without ``bodies`` the result depends on the scene, the water and the pulse
    only: it is kept in ``prepared.memo`` for every later pose (do not modify it).
    """
    water = Fluid(context.density_kg_m3, context.sound_speed_m_s)
    pulse = context.sonar.pulse
    key: Any = None
    if bodies is None:
        key = ("elastic targets", water.density_kg_m3, water.sound_speed_m_s, pulse)
        try:
            found = prepared.memo.get(key)
        except TypeError:  # a pulse that cannot be a key (sampled): computed every time
            key = None
        else:
            if found is not None:
                return found
    overrides = dict(bodies or {})
    n_boundaries = len(prepared.scene.boundaries)
    largest_radius = MAX_KA / (2.0 * np.pi * _band_top_hz(context) / water.sound_speed_m_s)
    targets: dict[int, tuple[EchoTarget, NDArray[np.float64], NDArray[np.float64] | None]] = {}
    for j, obj in enumerate(prepared.scene.objects):
        found = echo_target_for(obj, overrides.get(obj.name), water)
        if found is None or found[0].radius_m > largest_radius:
            continue
        if obj.name in overrides or is_elastic_body(found[0].body):
            targets[n_boundaries + j] = found
    if key is not None:
        prepared.memo[key] = targets
    return targets


def attach_elastic_echoes(rows: NDArray[Any], responses: Sequence[Any], prepared: PreparedScene,
                          context: SolveContext, *, bodies: Mapping[str, Body] | None = None
                          ) -> tuple[NDArray[Any], tuple[Any, ...]]:
    """Give the echo rows of elastic objects their transfer functions (module docstring).

    Parameters
    ----------
    rows : structured ndarray of PATH_DTYPE, shape (n,)
        The assembled rows of one solve (derived columns filled); modified in place
        (``response_id``, ``amplitude``) and returned.
    responses : sequence of EchoResponse
        The responses the rows already name (kept; a row that had one gets a response that
        multiplies it in).
    prepared : PreparedScene
    context : SolveContext
        The pose (transmitter, receivers, water, centre frequency, the sonar's pulse).
    bodies : mapping of object name -> Body, optional
        Bodies to use instead of the objects' own (e.g. a rigid body, to check a limit); an
        object named here gets responses whatever its body.

    Returns
    -------
    (rows, responses)
    """
    scene = prepared.scene
    responses = tuple(responses)
    water = Fluid(context.density_kg_m3, context.sound_speed_m_s)
    n_boundaries = len(scene.boundaries)
    targets = elastic_targets(prepared, context, bodies)
    if not targets or rows.size == 0:
        return rows, responses
    # the specular rows touching a target (a few hundred of the solve's rows): every later
    # array is over these candidates only
    target_ids = np.fromiter(targets, dtype=np.int64, count=len(targets))
    specular = np.flatnonzero(rows["kind"] == PathKind.SPECULAR)
    specular_ids = rows["object_ids"][specular].astype(np.int64)
    on_target = np.isin(specular_ids, target_ids)
    touching = on_target.any(axis=1)
    candidates = specular[touching]
    if candidates.size == 0:
        return rows, responses
    chosen = rows[candidates]
    ids, on_target = specular_ids[touching], on_target[touching]
    curved = curved_interactions(chosen, prepared, n_boundaries)
    slot_valid = np.arange(MAX_INTERACTIONS)[None, :] < chosen["order"][:, None]
    hit_rows, hit_slots = np.nonzero(curved & on_target & slot_valid)  # hit_rows: indices into candidates
    if hit_rows.size == 0:
        return rows, responses
    source, receiver = unfolded_ends(chosen, curved, hit_rows, hit_slots, context.transmitter_m, context.receivers_m)
    hit_objects = ids[hit_rows, hit_slots]
    # every hit's geometry at its object; hits beyond MAX_BISTATIC_RAD keep today's row
    geometry_of = np.empty((hit_rows.size, 4))
    for surface in np.unique(hit_objects):
        _, centre, axis = targets[int(surface)]
        mine = hit_objects == surface
        geometry = EchoGeometry.from_points(source[mine], receiver[mine], centre, axis)
        geometry_of[mine] = np.column_stack([geometry.source_distance_m, geometry.receiver_distance_m,
                                             geometry.bistatic_angle_rad, geometry.axial_offset_m])
    keep = geometry_of[:, 2] <= MAX_BISTATIC_RAD
    hit_rows, hit_slots, hit_objects, geometry_of = hit_rows[keep], hit_slots[keep], hit_objects[keep], geometry_of[keep]
    if hit_rows.size == 0:
        return rows, responses

    # one ElasticRows per body (shape, radius, body, material): objects alike share coefficients
    groups: dict[Any, list[int]] = {}
    for surface in np.unique(hit_objects):
        target = targets[int(surface)][0]
        groups.setdefault((target.shape, target.radius_m, target.body, target.material), []).append(int(surface))
    part_of = np.empty((hit_rows.size, 2), dtype=np.int64)  # (batch number, index in batch)
    batches: list[ElasticRows] = []
    h0 = np.ones(candidates.size, dtype=complex)
    for surfaces in groups.values():
        order = np.flatnonzero(np.isin(hit_objects, surfaces))
        target = targets[surfaces[0]][0]
        flat, compression, factor = flat_rows(target, EchoGeometry(*geometry_of[order].T), water)
        batch = ElasticRows(target, flat, compression, factor, hit_objects[order], water.density_kg_m3,
                            water.sound_speed_m_s, context.sonar.pulse)
        try:
            at_f0 = batch.exact_transfers([context.centre_frequency_hz])[:, 0]
        except InputError as exc:  # a body the series cannot describe (singular boundary systems)
            warnings.warn(f"elastic echoes of {', '.join(scene.surface_names[i] for i in surfaces)} left out: {exc}",
                          UserWarning, stacklevel=3)
            part_of[order, 0] = -1
            continue
        part_of[order, 0] = len(batches)
        part_of[order, 1] = np.arange(order.size)
        np.multiply.at(h0, hit_rows[order], at_f0)
        batches.append(batch)
    described = part_of[:, 0] >= 0
    hit_rows, hit_objects, part_of = hit_rows[described], hit_objects[described], part_of[described]

    amplitude = rows["amplitude"]
    amplitude[candidates] = amplitude[candidates] * np.abs(h0)
    return rows, responses + _echo_responses(rows, responses, candidates[hit_rows], hit_objects, part_of, batches,
                                             scene.surface_names)


def _echo_responses(rows: NDArray[Any], responses: tuple[Any, ...], hit_rows: NDArray[np.int64],
                    hit_objects: NDArray[np.int64], part_of: NDArray[np.int64], batches: Sequence[ElasticRows],
                    names: Sequence[str]) -> tuple[Any, ...]:
    """One :class:`ElasticEchoResponse` per row of ``hit_rows`` (h,) (sorted, a row once per
    elastic interaction), numbered after ``responses``; sets those rows' ``response_id``."""
    if hit_rows.size == 0:
        return ()
    first = np.flatnonzero(np.r_[True, hit_rows[1:] != hit_rows[:-1]])  # each row's run of interactions
    stops = np.r_[first[1:], hit_rows.size].tolist()
    echo_rows = hit_rows[first]
    previous = rows["response_id"][echo_rows].tolist()
    objects, batch_of, index_of = hit_objects.tolist(), part_of[:, 0].tolist(), part_of[:, 1].tolist()
    labels: dict[tuple[tuple[int, int], ...], str] = {}  # one label per combination of (object, body)
    new: list[Any] = []
    for start, stop, before in zip(first.tolist(), stops, previous):
        parts = tuple((batches[batch_of[k]], index_of[k]) for k in range(start, stop))
        key = tuple((objects[k], batch_of[k]) for k in range(start, stop))
        label = labels.get(key)
        if label is None:
            label = labels[key] = "elastic echo of " + ", ".join(
                f"{names[surface]} ({batches[batch].target.material.name}"
                f"{', pipe' if isinstance(batches[batch].target.body, Shell) else ''})" for surface, batch in key)
        new.append(ElasticEchoResponse(label, parts, (responses[before],) if before >= 0 else ()))
    rows["response_id"][echo_rows] = len(responses) + np.arange(echo_rows.size)
    return tuple(new)


def internal_arrival_table(paths: Paths) -> NDArray[Any]:
    """The named internal arrivals of every elastic echo of ``paths`` (``/truth/internal_arrivals``).

    One row per (echo row, elastic interaction, internal arrival of that body: the diameter
    paths, glory rays, creeping and Rayleigh waves of a solid, the wall reverberations and
    back-wall echo of a pipe; :mod:`acoustisim.scattering.arrivals`), its delay the echo's plus
    the arrival's monostatic delay scaled by cos(e) (the oblique model's time compression), its
    level that of the sonar's monostatic echo at that delay (dB re the echo's peak; computed on
    first use with the echo's transfer functions). Arrivals whose level is below
    :data:`~acoustisim.propagation.elastic_responses.SPAN_LEVEL_DB` (what the synthesised echo
    holds) are left out.

    Returns
    -------
    structured ndarray of INTERNAL_ARRIVAL_DTYPE, sorted by channel then delay
    """
    table = []
    rows = paths.rows
    for r in np.flatnonzero(rows["response_id"] >= 0):
        response = paths.responses[int(rows["response_id"][r])]
        for batch, index in getattr(response, "parts", ()):
            if not isinstance(batch, ElasticRows):
                continue
            arrivals = batch.internal_arrivals()
            if not arrivals:
                continue
            after = np.array([a.delay_s for a in arrivals]) * batch.compression[index]
            levels = batch.level_db(after / batch.compression[index])
            for arrival, delay, level in zip(arrivals, after, levels):
                if level < SPAN_LEVEL_DB:  # below what the synthesised echo holds
                    continue
                table.append((rows["path_id"][r], rows["channel"][r], batch.object_ids[index],
                              arrival.name.encode("ascii", "replace")[:64], rows["delay_s"][r] + delay, delay, level))
    out = np.array(table, dtype=INTERNAL_ARRIVAL_DTYPE)
    return out[np.lexsort((out["delay_s"], out["channel"]))] if out.size else out
