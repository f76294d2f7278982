"""The scene geometry of edge diffraction: sharp edges, and the edges that diffract.

An edge shared by two triangles of one surface is *sharp* when the angle between the two face
normals exceeds a threshold (default 30 degrees). A finely tessellated cylinder's side turns by
360 / n_segments degrees between neighbouring facets (11.25 degrees for 32 segments) and is not
sharp; its rims (90 degrees), a prism's edges, a plate's edges and the tank's corners (the
boundaries meet at 90 degrees) are. An edge with a single triangle (an open mesh's border) is a
knife edge (a thin screen, exterior angle 2 pi). Edges shared by more than two triangles of one
surface (non-manifold) and edges of degenerate triangles are ignored.

The tank's six boundary rectangles are treated as one surface (their shared corners are
found by merging coincident vertices); each object is its own surface, so objects touching each
other or a boundary are not joined. Sharp edges meeting end to end with a small turn form a
*chain* (a polygonal rim): one physical diffracted arrival.

Wedge frame of an edge (the one :mod:`acoustisim.propagation.reference.btm` uses):
``face_dir`` is the unit vector perpendicular to the edge, lying in face 1 and pointing into
it; ``face_normal`` is face 1's unit normal (into the water); the edge direction is
``face_dir x face_normal``, so a point's angle ``atan2((p - start) . face_normal,
(p - start) . face_dir)`` in [0, 2 pi) runs from face 1 through the water to face 2 at
``wedge_angle``.

Of the sharp edges, those that diffract (:class:`DiffractingEdges`, built once per prepared
scene and shared by both propagation engines) leave out, each for a physical reason:

* wedges whose index nu = pi / theta_w is an integer (the tank's 90-degree corners, nu = 2):
  the BTM angular factor vanishes identically there (its four terms cancel in pairs), the
  image-source field being exact;
* object edges lying in a tank boundary plane (a prism's or a post's rim standing on the floor
  or touching the free surface): they are not wedges in the water.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from acoustisim.materials import Material
from acoustisim.propagation.raycast import RayCaster
from acoustisim.scene import Scene

DEFAULT_SHARP_ANGLE_DEG = 30.0
"""Normal turn (degrees) above which an edge is sharp."""

CHAIN_TURN_DEG = 45.0
"""Largest turn (degrees) between two sharp edges joined into one chain (a polygonal rim)."""


@dataclass(frozen=True, eq=False)
class SharpEdges:
    """Straight sharp edges with their wedge geometry and boundary condition.

    Attributes
    ----------
    start_m, end_m : ndarray, shape (n, 3)
        Ends of each edge (tank frame, m); ``end - start`` is along the edge direction.
    direction : ndarray, shape (n, 3)
        Unit edge direction (= face_dir x face_normal).
    face_dir : ndarray, shape (n, 3)
        Unit vector in face 1, perpendicular to the edge, pointing into the face.
    face_normal : ndarray, shape (n, 3)
        Unit normal of face 1, into the water.
    wedge_angle_rad : ndarray, shape (n,)
        Water-side (exterior) wedge angle theta_w in (0, 2 pi] (rad).
    surface : ndarray of int64, shape (n,)
        Index into ``scene.surface_names`` (face 1's surface).
    pressure_release : ndarray of bool, shape (n,)
        Boundary condition of the wedge (see :func:`is_pressure_release`).
    chain : ndarray of int64, shape (n,)
        Connected polygonal edge (a rim, a long tessellated edge) each segment belongs to:
        segments of one chain form one physical diffracted arrival.
    """

    start_m: NDArray[np.float64]
    end_m: NDArray[np.float64]
    direction: NDArray[np.float64]
    face_dir: NDArray[np.float64]
    face_normal: NDArray[np.float64]
    wedge_angle_rad: NDArray[np.float64]
    surface: NDArray[np.int64]
    pressure_release: NDArray[np.bool_]
    chain: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.surface.size)

    @property
    def length_m(self) -> NDArray[np.float64]:
        """Edge lengths (m), shape (n,)."""
        return np.linalg.norm(self.end_m - self.start_m, axis=1)

    @property
    def nu(self) -> NDArray[np.float64]:
        """Wedge index pi / theta_w, shape (n,)."""
        return np.pi / self.wedge_angle_rad

    def select(self, mask: NDArray[np.bool_]) -> "SharpEdges":
        """The edges where ``mask`` is true (chains keep their labels)."""
        return SharpEdges(
            self.start_m[mask], self.end_m[mask], self.direction[mask], self.face_dir[mask],
            self.face_normal[mask], self.wedge_angle_rad[mask], self.surface[mask],
            self.pressure_release[mask], self.chain[mask],
        )

    def local_coordinates(
        self, points_m: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Cylindrical wedge coordinates of points, one point per edge or one for all.

        Parameters
        ----------
        points_m : ndarray, shape (n, 3) or (3,)

        Returns
        -------
        r, theta, z : ndarray, shape (n,)
            Distance from the edge line (m), angle from face 1 in [0, 2 pi) (rad), position
            along the edge from ``start_m`` (m).
        """
        rel = np.asarray(points_m, dtype=float) - self.start_m
        x = np.einsum("ij,ij->i", rel, self.face_dir)
        y = np.einsum("ij,ij->i", rel, self.face_normal)
        z = np.einsum("ij,ij->i", rel, self.direction)
        return np.hypot(x, y), np.mod(np.arctan2(y, x), 2.0 * np.pi), z


def is_pressure_release(material: Material) -> bool:
    """Boundary condition of a wedge of this material.

    ``pressure-release`` materials (and ``fixed`` ones with a negative coefficient, such as an
    air-filled pipe) are pressure-release wedges. Every other material, including the solids
    (steel, PVC, concrete, on the ``elastic`` or ``fluid`` reflection model: |R| 0.4-0.94 at
    normal incidence), is treated as a *rigid* wedge: the BTM solution exists for the two ideal boundary conditions only, and rigid is the
    nearer one for a positive R.
    """
    if material.model == "pressure-release":
        return True
    return material.model == "fixed" and material.fixed_reflection < 0.0


def _row_ids(
    columns: list[NDArray[np.int64]],
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Label equal rows of integer columns (all shape (n,)).

    A lexicographic sort and a run split: O(n log n) in C, unlike ``np.unique(axis=0)``.

    Returns
    -------
    ids : ndarray of int64, shape (n,)
        0..k-1, in the rows' sorted order.
    counts : ndarray of int64, shape (k,)
    order : ndarray of int64, shape (n,)
        A stable sort of the rows by id (rows of one id are consecutive).
    """
    n = columns[0].size
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    order = np.argsort(columns[0], kind="stable") if len(columns) == 1 else np.lexsort(columns[::-1])
    change = np.zeros(n, dtype=bool)
    change[0] = True
    for column in columns:  # a handful of key columns
        sorted_column = column[order]
        change[1:] |= sorted_column[1:] != sorted_column[:-1]
    run = np.cumsum(change) - 1
    ids = np.empty(n, dtype=np.int64)
    ids[order] = run
    return ids, np.bincount(run), order


def _unit(v: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    n = np.linalg.norm(v, axis=-1)
    safe = np.where(n > 0.0, n, 1.0)
    return v / safe[..., None], n


def sharp_edges(
    raycaster: RayCaster, scene: Scene, sharp_angle_deg: float = DEFAULT_SHARP_ANGLE_DEG
) -> SharpEdges:
    """Every sharp edge of the scene's meshes (objects and tank boundaries).

    Parameters
    ----------
    raycaster : RayCaster
        Its triangle arrays (vertices, faces, unit normals into the water, surface index).
    scene : Scene
        For the materials of the surfaces.
    sharp_angle_deg : float
        Normal turn (degrees) above which a shared edge is sharp.

    Returns
    -------
    SharpEdges
    """
    vertices = np.asarray(raycaster.vertices, dtype=float)
    faces = np.asarray(raycaster.faces, dtype=np.int64)
    normals = np.asarray(raycaster.face_normals, dtype=float)
    surface = np.asarray(raycaster.surface_index, dtype=np.int64)
    n_boundaries = len(scene.boundaries)
    materials = [b.material for b in scene.boundaries] + [o.material for o in scene.objects]
    soft_of_surface = np.array([is_pressure_release(m) for m in materials], dtype=bool)

    # merge coincident vertices of one surface (the boundary rectangles share corners) on a 1e-9
    # relative grid; each object is its own surface, all boundaries one
    group = np.where(surface < n_boundaries, -1, surface)
    scale = max(float(np.max(np.abs(vertices))) if vertices.size else 1.0, 1.0)
    quantum = 1e-9 * scale
    vertex_group = np.full(vertices.shape[0], -2, dtype=np.int64)
    vertex_group[faces] = group[:, None]
    q = np.round(vertices / quantum).astype(np.int64)
    vid = _row_ids([vertex_group, q[:, 0], q[:, 1], q[:, 2]])[0]
    tri = vertices[faces]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    good_face = (area2 > 1e-12 * scale * scale) & (np.abs(np.linalg.norm(normals, axis=1) - 1.0) < 1e-6)

    # half-edges: (face, local corner k) is the edge faces[k] -> faces[k+1], opposite faces[k+2]
    n_faces = faces.shape[0]
    face_of = np.repeat(np.arange(n_faces), 3)
    a = faces.reshape(-1)
    b = faces[:, [1, 2, 0]].reshape(-1)
    opp = faces[:, [2, 0, 1]].reshape(-1)
    keep = good_face[face_of]
    face_of, a, b, opp = face_of[keep], a[keep], b[keep], opp[keep]
    va, vb = vid[a], vid[b]
    # merged vertex ids are per surface, so the pair (min, max) identifies an edge of one surface
    n_ids = int(vid.max()) + 1 if vid.size else 1
    _, counts, order = _row_ids([np.minimum(va, vb) * n_ids + np.maximum(va, vb)])
    first = np.cumsum(counts) - counts  # start of each edge's half-edges in `order`
    pair_edges = np.flatnonzero(counts == 2)
    single_edges = np.flatnonzero(counts == 1)
    h1 = order[first[pair_edges]]
    h2 = order[first[pair_edges] + 1]
    hs = order[first[single_edges]]
    # sharp: the normals turn by more than the threshold (only those get the wedge geometry)
    turn = np.arccos(np.clip(np.einsum("ij,ij->i", normals[face_of[h1]], normals[face_of[h2]]), -1.0, 1.0))
    sharp = turn > math.radians(sharp_angle_deg)
    h1, h2 = h1[sharp], h2[sharp]

    def wedge(h: NDArray[np.int64]) -> tuple[NDArray[np.float64], ...]:
        p0, p1, po = vertices[a[h]], vertices[b[h]], vertices[opp[h]]
        u, _ = _unit(p1 - p0)
        w = po - p0
        f, _ = _unit(w - np.einsum("ij,ij->i", w, u)[:, None] * u)
        return p0, p1, u, f, normals[face_of[h]]

    p0, p1, u, f1, n1 = wedge(h1)
    f2 = wedge(h2)[3]
    theta_pair = np.mod(np.arctan2(np.einsum("ij,ij->i", f2, n1), np.einsum("ij,ij->i", f2, f1)), 2.0 * np.pi)
    q0, q1, _, g1, m1 = wedge(hs)

    start = np.concatenate([p0, q0])
    end = np.concatenate([p1, q1])
    fdir = np.concatenate([f1, g1])
    fnorm = np.concatenate([n1, m1])
    theta = np.concatenate([theta_pair, np.full(len(hs), 2.0 * np.pi)])
    surf = np.concatenate([surface[face_of[h1]], surface[face_of[hs]]])
    vids = np.concatenate([np.column_stack([vid[a[h1]], vid[b[h1]]]),
                           np.column_stack([vid[a[hs]], vid[b[hs]]])]).reshape(-1, 2)
    # orient each edge along face_dir x face_normal
    direction, _ = _unit(np.cross(fdir, fnorm))
    flip = np.einsum("ij,ij->i", end - start, direction) < 0.0
    start, end = np.where(flip[:, None], end, start), np.where(flip[:, None], start, end)
    chain = _chains(start, end, theta, surf, vids, n_boundaries)
    return SharpEdges(
        start_m=start,
        end_m=end,
        direction=direction,
        face_dir=fdir,
        face_normal=fnorm,
        wedge_angle_rad=theta,
        surface=surf,
        pressure_release=soft_of_surface[surf] if surf.size else np.zeros(0, dtype=bool),
        chain=chain,
    )


def _chains(
    start: NDArray[np.float64],
    end: NDArray[np.float64],
    theta: NDArray[np.float64],
    surface: NDArray[np.int64],
    vids: NDArray[np.int64],
    n_boundaries: int,
) -> NDArray[np.int64]:
    """Label polygonal chains: edges meeting at a vertex shared by exactly two sharp edges of one
    surface, with similar wedge angles and a turn below :data:`CHAIN_TURN_DEG`."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = start.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    group = np.where(surface < n_boundaries, -1, surface)
    edge_of = np.repeat(np.arange(n), 2)
    _, counts, order = _row_ids([np.repeat(group, 2), vids.reshape(-1)])
    first = np.cumsum(counts) - counts
    joints = np.flatnonzero(counts == 2)
    e1 = edge_of[order[first[joints]]]
    e2 = edge_of[order[first[joints] + 1]]
    d = end - start
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    turn = np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", d[e1], d[e2])), -1.0, 1.0))
    ok = (turn < math.radians(CHAIN_TURN_DEG)) & (np.abs(theta[e1] - theta[e2]) < math.radians(CHAIN_TURN_DEG))
    graph = coo_matrix((np.ones(int(ok.sum())), (e1[ok], e2[ok])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    return labels.astype(np.int64)




ON_PLANE_M = 1e-6
"""An object edge with both ends within this of a tank boundary plane lies in it (m)."""

INTEGER_NU_TOLERANCE = 1e-9
"""A wedge index within this of an integer is one (the wedge does not diffract)."""

VISIBILITY_OFFSET_M = 2e-4
"""Visibility probes sit this far from the edge along the wedge's bisector, in the water, so that
the wedge's own faces never block a leg (float32 Embree rounding is about 5e-7 m in the tank;
an element's occlusion is that of its probe, 2e-4 m from the edge, within an element length)."""


def select_diffracting(edges: SharpEdges, scene: Scene) -> SharpEdges:
    """The edges of ``edges`` that diffract (see the module docstring for what is left out)."""
    nu = edges.nu
    integer_nu = np.abs(nu - np.round(nu)) < INTEGER_NU_TOLERANCE
    embedded = np.zeros(len(edges), dtype=bool)
    n_boundaries = len(scene.boundaries)
    for boundary in scene.boundaries:  # the six tank planes
        p = np.asarray(boundary.plane.point_m, dtype=float)
        n = np.asarray(boundary.plane.normal, dtype=float)
        on = (np.abs((edges.start_m - p) @ n) < ON_PLANE_M) & (np.abs((edges.end_m - p) @ n) < ON_PLANE_M)
        embedded |= on & (edges.surface >= n_boundaries)
    return edges.select(~integer_nu & ~embedded & (edges.length_m > 0.0))


def endpoint_partners(edges: SharpEdges) -> NDArray[np.int64]:
    """For each endpoint of ``edges`` ([starts; ends], shape (2 n,)), the other edge of its
    chain ending at that exact point (shared vertices are bit-identical), or -1."""
    n = len(edges)
    points = np.concatenate([edges.start_m, edges.end_m])
    keys = np.concatenate([np.tile(edges.chain, 2)[:, None].astype(float), points], axis=1)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(inverse, kind="stable")
    partner = np.full(2 * n, -1, dtype=np.int64)
    shared = counts[inverse[order]] == 2
    # the two endpoints of a shared point are consecutive in ``order``: pair them up
    first = order[shared][0::2]
    second = order[shared][1::2]
    partner[first], partner[second] = second % n, first % n
    return partner


@dataclass(frozen=True, eq=False)
class DiffractingEdges:
    """The per-scene part of edge diffraction, built once per prepared scene
    (:attr:`~acoustisim.propagation.prepared.PreparedScene.diffracting_edges`) and reused by
    every pose and both engines.

    Attributes
    ----------
    edges : SharpEdges
        The edges that diffract (:func:`select_diffracting`), n of them.
    length_m : ndarray, shape (n,)
        Their lengths (m).
    nu : ndarray, shape (n,)
        Their wedge indices pi / theta_w.
    partner : ndarray of int64, shape (2 n,)
        :func:`endpoint_partners`: the chains' joints.
    probe_offset_m : ndarray, shape (n, 3)
        :data:`VISIBILITY_OFFSET_M` along each wedge's bisector (m): the visibility probes'
        offset from the edge into the water.
    """

    edges: SharpEdges
    length_m: NDArray[np.float64] = field(repr=False)
    nu: NDArray[np.float64] = field(repr=False)
    partner: NDArray[np.int64] = field(repr=False)
    probe_offset_m: NDArray[np.float64] = field(repr=False)

    @classmethod
    def build(cls, sharp: SharpEdges, scene: Scene) -> "DiffractingEdges":
        """From a scene's sharp edges (:func:`sharp_edges`)."""
        edges = select_diffracting(sharp, scene)
        half = 0.5 * edges.wedge_angle_rad
        bisector = np.cos(half)[:, None] * edges.face_dir + np.sin(half)[:, None] * edges.face_normal
        return cls(edges, edges.length_m, edges.nu, endpoint_partners(edges), VISIBILITY_OFFSET_M * bisector)


__all__ = ("CHAIN_TURN_DEG", "DEFAULT_SHARP_ANGLE_DEG", "DiffractingEdges", "INTEGER_NU_TOLERANCE", "ON_PLANE_M",
           "SharpEdges", "VISIBILITY_OFFSET_M", "endpoint_partners", "is_pressure_release", "select_diffracting",
           "sharp_edges")
