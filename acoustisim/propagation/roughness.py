"""Coherent roughness of specular reflections: each row's exp(-S k^2) term and its level at f0.

Physics
-------
A reflection at grazing angle theta_g on a surface of Gaussian heights with rms h keeps the
coherent part

    chi = exp(-2 (k h sin theta_g)^2),        k = 2 pi f / c,

of its pressure (Kirchhoff approximation; Eckart, JASA 25, 566, 1953; ``physics.md`` section 8;
:func:`acoustisim.scattering.roughness.coherent_factor`). Over a chain of reflections the
factors multiply,

    prod_i exp(-2 (k h_i sin theta_g,i)^2) = exp(-S k^2),   S = 2 sum_i (h_i sin theta_g,i)^2,

one number per row, the ``roughness_m2`` column (m^2), which synthesis applies per frequency
bin (:func:`acoustisim.propagation.responses.roughness_factor`). The lost coherent energy,
|R|^2 (1 - chi^2) per reflection, is scattered diffusely: the diffuse tracer carries it
(:mod:`acoustisim.propagation.reference.diffuse`).

The grazing angle at a specular vertex follows from the row's own geometry: with unit incoming
and outgoing directions d_in, d_out and the surface normal n, d_out = d_in - 2 (d_in . n) n,
so d_in . d_out = 1 - 2 (d_in . n)^2 and

    sin theta_g = |d_in . n| = sqrt((1 - d_in . d_out) / 2).

Two reflections on a corner line (a post standing on the floor, two walls) share one point: the
leg between them has no direction. There the normal of one of the two surfaces (a planar
mirror's plane, a sphere's or a cylinder's side) gives the missing direction by reflection,
d_mid = d_in - 2 (d_in . n_1) n_1 (or from the far side, d_mid = d_out - 2 (d_out . n_2) n_2),
and each vertex then has both its directions.

Method
------
:func:`apply_coherent_roughness` is a step of :func:`acoustisim.propagation.solve` after the
engine has assembled the rows, the same for both engines: for every specular row touching a
surface with ``roughness_rms_m`` h > 0 it fills ``roughness_m2`` and multiplies ``amplitude``
(the echo's pressure factor at the centre frequency f0) by exp(-S k0^2). Vectorised over rows,
looping over the (at most :data:`~acoustisim.propagation.paths.MAX_INTERACTIONS`) vertices.
Rows of other kinds and scenes without rough surfaces are left untouched (byte for byte).

Accuracy
--------
Exact to float64 rounding within the Kirchhoff model (valid for correlation lengths well above
the wavelength and moderate slopes; ``acoustisim.scattering.roughness``). The amplitude floor
is applied by the engine before this step, to the smooth levels: it keeps every row it would
keep for smooth surfaces. A corner line where neither surface's normal is known (two smooth
meshes meeting) shares the turn between its reflections equally: sin^2 theta_g,i =
(1 - d_in . d_out) / (2 m) for m reflections there, exact for perpendicular surfaces of equal h
(the sum of the sin^2 over perpendicular mirrors is (1 - d_in . d_out) / 2); no built-in
scene has such a corner.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.geometry import SpherePrimitive
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.paths import MAX_INTERACTIONS, PathKind
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.scene import Scene

ZERO_LEG_M = 1e-9
"""A leg shorter than this (m) joins two reflections on one corner line (the specular engines'
duplicate resolution)."""

ON_SURFACE_M = 1e-8
"""A point this close (m) to a mirror's plane or a primitive's side lies on it (specular
points are solved to float64 rounding; cylinder ends are resolved to 1e-9 m)."""

def surface_rms_heights(scene: Scene) -> NDArray[np.float64]:
    """The rms height h (m) of each surface (boundaries, then objects: the index of
    ``scene.surface_names`` and the rows' ``object_ids``), shape (n_surfaces,)."""
    return np.array([b.material.roughness_rms_m for b in scene.boundaries]
                    + [o.material.roughness_rms_m for o in scene.objects], dtype=float)


def vertex_normals(prepared: PreparedScene, surface: NDArray[np.int64],
                   points_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit normals (k, 3) of surfaces ``surface`` (k,) at ``points_m`` (k, 3) on them; NaN where
    none is known (a smooth mesh).

    The side of a sphere or cylinder holding the point first (a post's side at the floor also
    lies in the plane of its bottom cap), then a planar mirror of the surface whose plane and
    polygon hold the point (tank boundaries, polyhedral facets, cylinder caps).
    """
    points = np.asarray(points_m, dtype=float).reshape(-1, 3)
    surface = np.asarray(surface, dtype=np.int64).reshape(-1)
    normals = np.full(points.shape, np.nan)
    for reflector in prepared.curved:  # a loop over the scene's curved objects (few)
        on = np.flatnonzero(surface == reflector.surface)
        if on.size == 0:
            continue
        primitive = reflector.primitive
        offset = points[on] - np.asarray(primitive.center_m, dtype=float)
        if isinstance(primitive, SpherePrimitive):
            side = np.abs(np.linalg.norm(offset, axis=1) - primitive.radius_m) <= ON_SURFACE_M
        else:
            along = offset @ np.asarray(primitive.axis, dtype=float)
            radial = np.linalg.norm(offset - np.outer(along, primitive.axis), axis=1)
            side = ((np.abs(radial - primitive.radius_m) <= ON_SURFACE_M)
                    & (np.abs(along) <= 0.5 * primitive.length_m + ON_SURFACE_M))
        normals[on[side]] = primitive.outward_normal(points[on[side]])
    mirrors = prepared.mirrors
    for s in np.unique(surface[np.isnan(normals[:, 0])]):  # a loop over distinct surfaces
        queries = np.flatnonzero((surface == s) & np.isnan(normals[:, 0]))
        for m in np.flatnonzero(mirrors.surface == s):  # the surface's planar mirrors
            index = np.full(queries.size, m, dtype=np.int64)
            found = (np.abs(mirrors.signed_distance(points[queries], index)) <= ON_SURFACE_M) & mirrors.contains(
                points[queries], index)
            normals[queries[found]] = mirrors.normal[m]
            queries = queries[~found]
            if queries.size == 0:
                break
    return normals


def _reflect(direction: NDArray[np.float64], normal: NDArray[np.float64]) -> NDArray[np.float64]:
    """Directions (n, 3) mirrored by planes of unit normals (n, 3)."""
    return direction - 2.0 * np.einsum("ij,ij->i", direction, normal)[:, None] * normal


def grazing_sines(rows: NDArray[Any], prepared: PreparedScene, transmitter_m: NDArray[np.float64],
                  receivers_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """sin theta_g at each reflection of specular ``rows``, shape (n, MAX_INTERACTIONS), NaN beyond
    each row's order (see the module docstring).

    Parameters
    ----------
    rows : structured ndarray of PATH_DTYPE, shape (n,)
        Specular rows (``order`` reflections at ``points_m`` on ``object_ids``).
    prepared : PreparedScene
        For the normals at corner lines.
    transmitter_m : ndarray, shape (3,)
    receivers_m : ndarray, shape (n_rx, 3)
        Indexed by the rows' ``channel``.
    """
    sines = np.full((rows.size, MAX_INTERACTIONS), np.nan)
    tx = np.asarray(transmitter_m, dtype=float)
    rx = np.asarray(receivers_m, dtype=float)
    for order in np.unique(rows["order"]):  # at most MAX_INTERACTIONS groups
        m = int(order)
        at = np.flatnonzero(rows["order"] == order)
        chain = rows[at]
        ends = np.concatenate([np.broadcast_to(tx, (at.size, 1, 3)), chain["points_m"][:, :m],
                               rx[chain["channel"].astype(np.intp)][:, None, :]], axis=1)  # (k, m + 2, 3)
        legs = np.diff(ends, axis=1)  # leg j arrives at vertex j, leaves vertex j - 1
        length = np.linalg.norm(legs, axis=2)
        zero = length <= ZERO_LEG_M
        directions = np.where(zero[:, :, None], np.nan, legs / np.where(zero, 1.0, length)[:, :, None])
        if np.any(zero):
            _fill_corner_directions(directions, zero, chain, prepared)
        dots = np.einsum("ijk,ijk->ij", directions[:, :-1], directions[:, 1:])  # d_in . d_out at each vertex
        sin_g = np.sqrt(np.clip(0.5 * (1.0 - dots), 0.0, 1.0))
        unresolved = np.isnan(dots)
        if np.any(unresolved):
            _share_unresolved_turns(sin_g, unresolved, directions)
        sines[at, :m] = sin_g
    return sines


def _fill_corner_directions(directions: NDArray[np.float64], zero: NDArray[np.bool_], chain: NDArray[Any],
                            prepared: PreparedScene) -> None:
    """Give the zero-length legs of ``directions`` (k, m + 1, 3) (NaN there) the direction the
    reflection at their start (forward) or end (backward) gives, where that surface's normal is
    known (:func:`vertex_normals`); in place."""
    k, legs, _ = directions.shape
    m = legs - 1
    near = np.zeros((k, m), dtype=bool)  # vertices at a zero-length leg
    near |= zero[:, :m]
    near |= zero[:, 1:]
    normals = np.full((k, m, 3), np.nan)
    row, vertex = np.nonzero(near)
    normals[row, vertex] = vertex_normals(prepared, chain["object_ids"][row, vertex].astype(np.int64),
                                          chain["points_m"][row, vertex])
    for j in range(1, m):  # forward: leg j leaves vertex j - 1
        fill = np.isnan(directions[:, j, 0]) & ~np.isnan(directions[:, j - 1, 0]) & ~np.isnan(normals[:, j - 1, 0])
        directions[fill, j] = _reflect(directions[fill, j - 1], normals[fill, j - 1])
    for j in range(m - 1, 0, -1):  # backward: leg j arrives at vertex j, which sends leg j + 1
        fill = np.isnan(directions[:, j, 0]) & ~np.isnan(directions[:, j + 1, 0]) & ~np.isnan(normals[:, j, 0])
        directions[fill, j] = _reflect(directions[fill, j + 1], normals[fill, j])


def _share_unresolved_turns(sin_g: NDArray[np.float64], unresolved: NDArray[np.bool_],
                            directions: NDArray[np.float64]) -> None:
    """At corner lines with no known normal, share the turn (1 - d_in . d_out) / 2 between the
    line's reflections equally (module docstring, Accuracy); in place.

    A Python loop over the (rare) rows concerned and their runs of unresolved reflections.
    """
    for r in np.flatnonzero(np.any(unresolved, axis=1)):
        vertex = 0
        m = unresolved.shape[1]
        while vertex < m:
            if not unresolved[r, vertex]:
                vertex += 1
                continue
            last = vertex
            while last + 1 < m and unresolved[r, last + 1]:
                last += 1
            turn = 0.5 * (1.0 - float(directions[r, vertex] @ directions[r, last + 1]))
            sin_g[r, vertex:last + 1] = math.sqrt(min(max(turn / (last - vertex + 1), 0.0), 1.0))
            vertex = last + 1


def roughness_m2(rows: NDArray[Any], prepared: PreparedScene, transmitter_m: NDArray[np.float64],
                 receivers_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """S = 2 sum_i (h_i sin theta_g,i)^2 (m^2) of specular ``rows`` (n,), shape (n,).

    Parameters as :func:`grazing_sines`; h from the materials of the rows' ``object_ids``.
    """
    heights = surface_rms_heights(prepared.scene)
    if rows.size == 0:
        return np.zeros(0)
    ids = rows["object_ids"].astype(np.intp)
    h = np.where(ids >= 0, np.append(heights, 0.0)[ids], 0.0)
    sines = grazing_sines(rows, prepared, transmitter_m, receivers_m)
    term = np.where(h > 0.0, h * np.nan_to_num(sines), 0.0)
    return 2.0 * np.sum(term * term, axis=1)


def apply_coherent_roughness(rows: NDArray[Any], prepared: PreparedScene, context: SolveContext) -> None:
    """Fill ``roughness_m2`` of the specular rows that touch a rough surface and multiply their
    ``amplitude`` by exp(-S k0^2) (k0 at the centre frequency), in place.

    Parameters
    ----------
    rows : structured ndarray of PATH_DTYPE, shape (n,)
        The assembled rows (derived columns filled), writeable.
    prepared : PreparedScene
    context : SolveContext
        The pose (transmitter, receivers), f0 and c.
    """
    heights = surface_rms_heights(prepared.scene)
    if rows.size == 0 or not np.any(heights > 0.0):
        return
    specular = np.flatnonzero(rows["kind"] == PathKind.SPECULAR)
    rough = np.append(heights, 0.0) > 0.0  # index -1 (padding): smooth
    at = specular[np.any(rough[rows["object_ids"][specular]], axis=1)]
    if at.size == 0:
        return
    s = roughness_m2(rows[at], prepared, context.transmitter_m, context.receivers_m)
    k0 = 2.0 * math.pi * float(context.centre_frequency_hz) / float(context.sound_speed_m_s)
    rows["roughness_m2"][at] = s
    rows["amplitude"][at] *= np.exp(-s * (k0 * k0))


__all__ = ("ON_SURFACE_M", "ZERO_LEG_M", "apply_coherent_roughness", "grazing_sines",
           "roughness_m2", "surface_rms_heights", "vertex_normals")
