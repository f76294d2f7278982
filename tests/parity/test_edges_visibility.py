"""The fast engine's element visibility (:mod:`acoustisim.propagation.fast.edge_visibility`)
against Embree, the independent method its screen replaces where it decides, and against the
reference engine's visibility (every leg to Embree).

Every leg the screen decides must get Embree's answer (its margin covers Embree's float32
rounding), and the visibility of every element must be the reference engine's. Poses are drawn
over the whole thesis tank so that the posts, the prism and the pipe hide some legs (the tests
assert that they do: a screen that never blocks would fail).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from acoustisim.medium import Medium
from acoustisim.propagation import SolverConfig, prepare
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.edge_extraction import VISIBILITY_OFFSET_M
from acoustisim.propagation.fast import edge_visibility as fast_visibility
from acoustisim.propagation.fast.edge_visibility import (
    BLOCKED,
    CLEAR,
    MASK_BITS,
    OTHERS_BIT,
    UNDECIDED,
    ScreenGeometry,
    WALL_BIT,
    scene_screen,
    screen_legs,
    screen_tolerance,
    triangle_mask,
)
from acoustisim.propagation.raycast import DEFAULT_EPS_M, RayCaster
from acoustisim.propagation.reference import edges as reference_edges
from acoustisim.propagation.reference.edge_elements import discretise_edges
from acoustisim.propagation.solver import check_sonar
from acoustisim.scene import Scene, Tank
from acoustisim.sonar import SonarHead
from scenes.builders import plate, sphere
from scenes.builtin import builtin_scene


def _decisions(screen, origins: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """The screen's decision for legs origin -> target shrunk by Embree's eps at both ends."""
    leg = targets - origins
    length = np.linalg.norm(leg, axis=1, keepdims=True)
    unit = leg / length
    p0, p1 = origins + DEFAULT_EPS_M * unit, origins + (length - DEFAULT_EPS_M) * unit
    return _decide(p0, p1, screen)


def _decide(p0, p1, screen):
    """screen_legs of the segments p0[i] -> p1[i] (shapes (n, 3)), testing everything."""
    p0, p1 = np.ascontiguousarray(p0, dtype=float), np.ascontiguousarray(p1, dtype=float)
    return screen_legs(p0, p1, np.full(p0.shape[0], -1, dtype=np.int64), screen)


@pytest.fixture(scope="module")
def tank():
    return prepare(builtin_scene("thesis-tank"))


def _poses(prepared, count, seed):
    """Sonar poses in the thesis tank that check_sonar accepts (random positions and headings)."""
    rng = np.random.default_rng(seed)
    poses = []
    while len(poses) < count:
        position = tuple(rng.uniform((0.2, 0.2, 0.1), (8.8, 2.8, 0.9)))
        sonar = replace(prepared.scene.sonar, position_m=position)
        try:
            check_sonar(prepared, sonar)
        except Exception:  # a transducer inside or touching an object: not a pose
            continue
        poses.append(sonar)
    return poses


def _elements(prepared, sonar, config=SolverConfig()):
    """A pose's context, edge pairs and elements, as the engines make them."""
    context = SolveContext.build(prepared.scene, sonar, prepared.raycaster)
    pairs = reference_edges.edge_pairs(context, prepared.diffracting_edges)
    elements = discretise_edges(pairs.geometry, reference_edges.discretisation(config, context))
    return context, pairs, elements


def _element_legs(prepared, sonar):
    """Every element's legs probe -> transmitter and probe -> side receiver of one pose:
    (origins, targets) in float64."""
    context, pairs, elements = _elements(prepared, sonar)
    probes = reference_edges.element_probes(prepared.diffracting_edges, elements, pairs)
    channel = pairs.receiver[elements.pair]
    tx = np.asarray(context.transmitter_m, dtype=float)
    rx = np.asarray(context.receivers_m, dtype=float)
    side = ~np.all(rx[channel] == tx, axis=1)
    origins = np.concatenate([probes, probes[side]])
    targets = np.concatenate([np.broadcast_to(tx, probes.shape), rx[channel[side]]])
    return origins, targets


def _screen_against_embree(tank, poses):
    """Counts of the screen's decisions over the legs of these poses, each decided leg checked
    against Embree's answer."""
    screen = scene_screen(tank)
    counts = {CLEAR: 0, BLOCKED: 0, UNDECIDED: 0}
    for sonar in poses:
        origins, targets = _element_legs(tank, sonar)
        decided = _decisions(screen, origins, targets)
        embree = tank.raycaster.occluded(origins, targets)
        for value in counts:
            counts[value] += int(np.sum(decided == value))
        np.testing.assert_array_equal(embree[decided == CLEAR], False)
        np.testing.assert_array_equal(embree[decided == BLOCKED], True)
    return counts


def test_screen_decisions_equal_embree_over_poses(tank):
    counts = _screen_against_embree(tank, _poses(tank, 16, seed=11))
    # the objects hide legs in these poses, and nearly every leg is decided without Embree
    assert counts[BLOCKED] > 1000 and counts[CLEAR] > 100_000  # 16 poses: 2 790 and 214 107
    assert counts[UNDECIDED] < 1e-3 * (counts[CLEAR] + counts[BLOCKED])  # 4 of them


@pytest.mark.slow
def test_screen_decisions_equal_embree_over_many_poses(tank):
    counts = _screen_against_embree(tank, _poses(tank, 120, seed=2026))
    assert counts[BLOCKED] > 10_000 and counts[UNDECIDED] < 1e-3 * (counts[CLEAR] + counts[BLOCKED])


def test_visibility_equals_the_reference_engines(tank):
    """The fast engine's visibility (screen, then Embree for the rest) is the reference's (every
    leg to Embree), element for element, over poses and both discretisations."""
    hidden = 0
    for sonar in [tank.scene.sonar] + _poses(tank, 9, seed=5):
        for config in (SolverConfig(), SolverConfig(edge_adaptive=False)):
            context, pairs, elements = _elements(tank, sonar, config)
            want = reference_edges.element_visibility(context, tank, elements, pairs)
            got = fast_visibility.element_visibility(context, tank, elements, pairs)
            assert elements.pair.size > 1000
            np.testing.assert_array_equal(got, want)
            hidden += int(np.sum(~want))
    assert hidden > 100  # some elements are hidden in these poses


def test_tolerance_covers_float32_and_stays_below_the_probe_offset(tank):
    tolerance = scene_screen(tank).tolerance
    vertices = tank.raycaster.vertices  # the triangles' bounds: the tolerance's box
    assert tolerance == screen_tolerance(np.array([vertices.min(axis=0), vertices.max(axis=0)]))
    # 20 float32 ulps of the 9.54 m diagonal: 40 ulps of the largest shifted coordinate (4.5 m)
    ulp = np.spacing(np.float32(4.5))
    assert 30 * ulp < tolerance < 60 * ulp
    # a probe lies VISIBILITY_OFFSET_M along the bisector of a convex wedge (exterior angle up to
    # 270 degrees on the tank's objects): sin(135 deg) times that from its faces
    assert tolerance < VISIBILITY_OFFSET_M * np.sin(np.radians(135.0)) / 5


def _box_scene(objects):
    return Scene("screen", Medium(), SonarHead(position_m=(1.0, 1.5, 0.5)), Tank(9.0, 3.0, 1.0), tuple(objects))


def test_convex_decisions_of_single_legs():
    cube = plate("cube", (4.0, 1.5, 0.5), (1.0, 0.0, 0.0), 0.2, 0.2, 0.2, "steel")  # a 0.2 m cube
    screen = scene_screen(prepare(_box_scene([cube])))
    tol = screen.tolerance
    x_face = 4.1  # the cube's +x face
    legs = {
        "through": ((3.0, 1.5, 0.5), (5.0, 1.5, 0.5), BLOCKED),
        "beside": ((3.0, 1.7, 0.5), (5.0, 1.7, 0.5), CLEAR),  # 0.1 m off the +y face
        "grazing a face": ((3.0, 1.6 + 0.1 * tol, 0.5), (5.0, 1.6 + 0.1 * tol, 0.5), UNDECIDED),
        "just clear": ((3.0, 1.6 + 3 * tol, 0.5), (5.0, 1.6 + 3 * tol, 0.5), CLEAR),
        "just through": ((3.0, 1.6 - 3 * tol, 0.5), (5.0, 1.6 - 3 * tol, 0.5), BLOCKED),
        "ending on the face": ((x_face + 1.0, 1.5, 0.5), (x_face + 0.5 * tol, 1.5, 0.5), UNDECIDED),
        "ending short of it": ((x_face + 1.0, 1.5, 0.5), (x_face + 3 * tol, 1.5, 0.5), CLEAR),
        "starting inside": ((4.0, 1.5, 0.5), (6.0, 1.5, 0.5), UNDECIDED),
        "near the floor": ((1.0, 1.5, 0.5 * tol), (2.0, 1.5, 0.5), UNDECIDED),
        "near the surface": ((1.0, 1.5, 0.5), (1.0, 1.5, 1.0 - 0.5 * tol), UNDECIDED),
        "short of the surface": ((1.0, 1.5, 0.5), (1.0, 1.5, 1.0 - 3 * tol), CLEAR),
    }
    # the segments Embree would be asked about (already shrunk)
    p0 = np.array([a for a, _, _ in legs.values()])
    p1 = np.array([b for _, b, _ in legs.values()])
    got = _decide(p0, p1, screen)
    want = np.array([w for _, _, w in legs.values()])
    assert dict(zip(legs, got.tolist())) == dict(zip(legs, want.tolist()))


def test_non_convex_object_is_left_to_embree_unless_a_convex_one_blocks():
    # an open plate-like screen: a sphere mesh cut open is not a closed convex mesh
    ball = sphere("ball", (4.0, 1.5, 0.5), 0.1, "steel")
    mesh = ball.mesh.copy()
    mesh.update_faces(np.arange(len(mesh.faces)) != 0)  # open: no planes
    open_ball = replace(ball, name="open", mesh=mesh, primitive=None)
    wall = plate("wall", (6.0, 1.5, 0.5), (1.0, 0.0, 0.0), 0.02, 1.0, 0.5, "steel")
    scene = _box_scene([open_ball, wall])  # (prepare refuses the open mesh: the screen of its parts)
    raycaster = RayCaster.from_scene(scene)
    screen = ScreenGeometry.create(np.array([obj.bounds_m for obj in scene.objects]),
                                   np.asarray(scene.tank.bounds_m, dtype=float), raycaster.convex_planes)
    assert screen.plane_start[1] == screen.plane_start[0]  # the open ball has no planes
    origins = np.array([(3.0, 1.5, 0.5), (3.0, 1.5, 0.5), (3.0, 2.5, 0.5)])
    targets = np.array([(5.0, 1.5, 0.5), (7.0, 1.5, 0.5), (5.0, 2.5, 0.5)])
    got = _decisions(screen, origins, targets)
    # crossing the open ball's box only: Embree; through the wall as well: blocked; clear of both
    assert got.tolist() == [UNDECIDED, BLOCKED, CLEAR]
    assert raycaster.occluded(origins, targets).tolist() == [True, True, False]


def test_pair_pre_screen_masks():
    cube = plate("cube", (4.0, 1.5, 0.5), (1.0, 0.0, 0.0), 0.2, 0.2, 0.2, "steel")
    diamond = plate("diamond", (6.0, 1.5, 0.5), (1.0, 1.0, 0.0), 0.2, 0.2, 0.2, "steel")  # turned 45 degrees
    prepared = prepare(_box_scene([cube, diamond]))
    assert np.all(prepared.raycaster.convex_planes.convex)
    screen = scene_screen(prepared)
    tol = screen.tolerance

    def mask(a, b, t):
        return triangle_mask(np.array(a, dtype=float), np.array(b, dtype=float), np.array(t, dtype=float), screen)

    # far from everything: nothing to test
    assert mask((1.0, 0.5, 0.5), (1.0, 0.6, 0.5), (2.0, 0.5, 0.5)) == 0
    # in a corner of the diamond's box but 0.08 m outside its face of normal (1, 1, 0): its box
    # is met, that face plane separates
    assert mask((6.13, 1.63, 0.45), (6.13, 1.63, 0.55), (6.135, 1.635, 0.5)) == 0
    # across the cube: test it (bit 0), and only it
    assert mask((3.0, 1.5, 0.45), (3.0, 1.5, 0.55), (5.0, 1.5, 0.5)) == 1
    # reaching past both: the cube and the diamond (bits 0 and 1)
    assert mask((3.0, 1.5, 0.45), (3.0, 1.5, 0.55), (7.0, 1.5, 0.5)) == 3
    # a corner within the margin of the floor: the walls too
    assert mask((1.0, 0.5, 0.5 * tol), (1.0, 0.6, 0.5), (2.0, 0.5, 0.5)) == 1 << WALL_BIT


def test_objects_beyond_the_mask_bits_are_always_tested():
    # MASK_BITS + 3 small cubes along a row at y = 0.5; the last one, beyond the mask's bits,
    # stands on the leg
    cubes = [plate(f"cube-{k}", (0.2 + 0.12 * k, 0.5, 0.5), (1.0, 0.0, 0.0), 0.05, 0.05, 0.05, "steel")
             for k in range(MASK_BITS + 3)]
    prepared = prepare(_box_scene(cubes))
    raycaster = prepared.raycaster
    screen = scene_screen(prepared)
    last = np.asarray(cubes[-1].mesh.bounds).mean(axis=0)
    a, b, t = last + (0.0, -0.3, -0.01), last + (0.0, -0.3, 0.01), last + (0.0, 0.3, 0.0)
    mask = triangle_mask(a, b, t, screen)
    assert mask == np.int64(1) << OTHERS_BIT  # no masked object near, but not skippable
    p0, p1 = np.array([last + (0.0, -0.3, 0.0)]), np.array([last + (0.0, 0.3, 0.0)])
    assert screen_legs(p0, p1, np.array([mask]), screen).tolist() == [BLOCKED]
    assert raycaster.occluded(p0, p1).tolist() == [True]
