"""The fast diffuse tracer against the reference tracer: the same rows (same counter-based random
numbers, tables and float64 hit points), pose after pose, bounce after bounce, thread count
after thread count; and the parts the fast tracer adds (output placement, box screens, threads)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from acoustisim.errors import InputError
from acoustisim.propagation import SolverConfig, prepare
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast import diffuse as fast
from acoustisim.propagation.fast.diffuse_kernels import EventArrays
from acoustisim.propagation.fast.diffuse_output import ChunkPlacement
from acoustisim.propagation.fast.diffuse_screen import LEGS_TO_EMBREE, leg_screen, receiver_wedges, shared_wedges
from acoustisim.propagation.fast.ray_threads import resolve_threads, run_in_order
from acoustisim.propagation.reference import diffuse as reference
from acoustisim.propagation.reference.diffuse import CHUNK_RAYS
from support.parity import assert_rows_match


@pytest.fixture(scope="module")
def tank(thesis_tank) -> SolveContext:
    prepared = prepare(thesis_tank)
    return SolveContext.build(thesis_tank, thesis_tank.sonar, prepared.raycaster, first_path_id=3)


def assert_same_rows(context: SolveContext, config: SolverConfig, label: str = "") -> np.ndarray:
    """The two engines' rows for ``context``: the same arrivals within the parity tolerances, and
    the same events in the same order (path ids, channels, orders, object ids row by row);
    returns the fast rows."""
    rows = fast.diffuse_rows(context, config)
    expected = reference.diffuse_rows(context, config)
    assert_rows_match(rows, expected, label=label)
    for name in ("path_id", "channel", "order", "object_ids"):
        assert np.array_equal(rows[name], expected[name]), f"{label}: {name} differs"
    # the hit points are the same to the bit (both solve the plane in the same float64 steps)
    assert np.array_equal(rows["points_m"], expected["points_m"], equal_nan=True), label
    return rows


@pytest.mark.parametrize("bounces", [1, 2, 3])
def test_engines_agree_on_the_thesis_tank_through_every_bounce(tank, bounces):
    # 2.5 chunks (a short last one): every chunk's stream, chunk boundary and parent link
    config = SolverConfig(diffuse_rays=CHUNK_RAYS * 5 // 2 if bounces == 2 else 6000, diffuse_bounces=bounces,
                          seed=11)
    rows = assert_same_rows(tank, config, f"{bounces} bounces")
    assert set(np.unique(rows["order"])) == set(range(1, bounces + 1))


@pytest.mark.parametrize("visibility", ["exact", "centre"])
def test_engines_agree_at_poses_among_the_posts(thesis_tank, visibility):
    # Sonar poses among the posts and the prism, turned every way: the fast tracer's first hits
    # (tank box and face planes) and convex occlusion (face planes) against the reference's
    # Embree INTERSECT and OCCLUDED queries, leg by leg. They could differ only for a ray or leg
    # passing within Embree's float32 rounding (1e-6 m) of an edge: none in these poses.
    scene = thesis_tank
    raycaster = prepare(scene).raycaster
    rng = np.random.default_rng(21)
    tested = 0
    while tested < 8:
        position = (rng.uniform(1.5, 6.0), rng.uniform(0.5, 2.5), rng.uniform(0.2, 0.8))
        sonar = replace(scene.sonar, position_m=position, yaw_deg=float(rng.uniform(-180.0, 180.0)),
                        pitch_deg=float(rng.uniform(-20.0, 20.0)))
        context = SolveContext.build(scene, sonar, raycaster)
        if not np.all(scene.tank.contains(context.receivers_m)) or np.any(
                [np.all((obj.bounds_m[0] - 0.02 < context.receivers_m) & (context.receivers_m < obj.bounds_m[1] + 0.02))
                 for obj in scene.objects]):
            continue  # a transducer inside or touching an object
        config = SolverConfig(diffuse_rays=8000, diffuse_bounces=2, seed=tested, diffuse_visibility=visibility)
        assert_same_rows(context, config, f"pose {tested}")
        tested += 1


def test_engines_agree_with_a_receiver_outside_the_water(tank):
    # A receiver behind a wall: the boundaries can block its legs, so the fast screen is off and
    # Embree tests every leg (as the reference does); nothing in the water hears it through the
    # wall (the object faces turned towards it are hidden, the boundaries face away from it)
    receivers = tank.receivers_m.copy()
    receivers[0] = (1.0, -0.5, 0.5)
    context = replace(tank, receivers_m=receivers)
    assert leg_screen(context.scene, receivers, context.raycaster.convex_planes).mode == LEGS_TO_EMBREE
    rows = assert_same_rows(context, SolverConfig(diffuse_rays=5000, seed=10), "receiver outside")
    assert not np.any(rows["channel"] == 0) and np.any(rows["channel"] == 2)


def test_rows_do_not_depend_on_the_thread_count(tank):
    # 2.5 chunks through two bounces on one, two and three threads (chunks placed from scratch
    # blocks when they finish out of order): byte-identical rows
    config = SolverConfig(diffuse_rays=CHUNK_RAYS * 5 // 2, diffuse_bounces=2, seed=11)
    rows = [fast.diffuse_rows(tank, replace(config, threads=t)).tobytes() for t in (1, 2, 3)]
    assert rows[0] == rows[1] == rows[2]


def test_the_events_pack_into_the_rows(tank):
    # each row is its reception's event and receiver: the path to the point plus the leg to the
    # receiver, the leg's direction, the event's speckle phase and departure
    config = SolverConfig(diffuse_rays=3000, diffuse_bounces=2, seed=2, threads=1)
    events = fast.trace_diffuse(tank, config).events
    rows = fast.diffuse_rows(tank, config)
    assert np.array_equal(rows["path_id"], 3 + events.event)
    assert np.array_equal(rows["channel"], events.channel)
    np.testing.assert_array_equal(rows["geometric_gain"], events.gain)
    leg = tank.receivers_m[events.channel] - events.point[events.event]
    r2 = np.linalg.norm(leg, axis=1)
    np.testing.assert_allclose(rows["path_length_m"], events.travelled[events.event] + r2, rtol=1e-15)
    np.testing.assert_allclose(rows["arrival_dir"], leg / r2[:, None], atol=1e-15)
    np.testing.assert_array_equal(rows["phase_rad"], events.phase[events.event])
    np.testing.assert_array_equal(rows["departure_dir"], events.departure[events.event])
    np.testing.assert_array_equal(rows["order"], events.bounce[events.event])


def test_receiver_wedges_hold_every_leg_crossing_a_box():
    # The wedge of a box seen from a receiver (projected along the box's longest side) must
    # contain the direction of every leg receiver -> point crossing the box (a slab test in
    # float64), else the screen would skip a blocked leg; and it must reject most legs that
    # miss a small box, else it is useless. Random boxes, receivers (some inside a box's
    # projected rectangle: no wedge) and points.
    rng = np.random.default_rng(4)
    lo = rng.uniform(-1.0, 1.0, (20, 3))
    hi = lo + rng.uniform(0.01, 1.0, (20, 3))
    receivers = rng.uniform(-2.0, 2.0, (6, 3))
    wedges = receiver_wedges(lo, hi, receivers)
    points = rng.uniform(-3.0, 3.0, (20_000, 3))
    rejected, misses, inside = 0, 0, 0
    # a sonar-like cluster (receivers 65 mm apart) for the wedges the receivers share
    cluster = receivers[0] + np.array([[0.0, 0.065, 0.0], [0.0, 0.0, 0.0], [0.0, -0.065, 0.0]])
    shared = shared_wedges(lo, hi, cluster)
    any_crosses = np.zeros((lo.shape[0], points.shape[0]), dtype=bool)
    for j, q in enumerate(np.concatenate([receivers, cluster])):
        e = points - q
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (lo[:, None, :] - q) / e, (hi[:, None, :] - q) / e  # (k, n, 3): the ray q + t e
        enter = np.maximum(np.nanmax(np.minimum(t1, t2), axis=2), 0.0)
        leave = np.minimum(np.nanmin(np.maximum(t1, t2), axis=2), 1.0)
        crosses = enter <= leave  # (k, n)
        if j >= receivers.shape[0]:
            any_crosses |= crosses
            continue
        for b in range(lo.shape[0]):
            w = wedges[j, b]
            inside += int(not np.any(w))
            within = (e @ w[:3] >= 0) & (e @ w[3:] >= 0)
            assert np.all(within[crosses[b]]), (j, b)
            rejected += int(np.sum(~within & ~crosses[b]))
            misses += int(np.sum(~crosses[b]))
    assert 0 < inside < 60  # both cases occur
    assert rejected > 0.5 * misses
    # a point from which a leg to any receiver of the cluster crosses a box passes its shared
    # wedge; most others do not
    passes = (points @ shared[:, 0:3].T >= shared[:, 3]) & (points @ shared[:, 4:7].T >= shared[:, 7])  # (n, k)
    assert np.all(passes.T[any_crosses])
    assert np.sum(~passes.T & ~any_crosses) > 0.5 * np.sum(~any_crosses)


def test_low_level_queries_agree_with_the_public_ones(tank):
    # the float32 Embree calls the fast tracer makes directly, against the ray caster's public
    # intersect and occluded queries on the same rays
    raycaster = tank.raycaster
    rng = np.random.default_rng(5)
    origins = rng.uniform([0.5, 0.3, 0.1], [8.5, 2.7, 0.9], (2000, 3))
    directions = rng.normal(size=(2000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hits = raycaster.intersect(origins, directions)
    shifted = np.ascontiguousarray(origins - raycaster.shift_m, dtype=np.float32)
    triangle = raycaster.first_hit_triangles32(shifted, np.ascontiguousarray(directions, dtype=np.float32))
    assert np.array_equal(triangle, hits.triangle)
    # the plane offsets put every hit point on its triangle's plane (float32 Embree: 1e-5 m)
    points = origins + hits.distance_m[:, None] * directions
    hit = hits.triangle >= 0
    normal = raycaster.face_normals[hits.triangle[hit]]
    np.testing.assert_allclose(np.einsum("ij,ij->i", normal, points[hit]), raycaster.plane_offset[hits.triangle[hit]],
                               atol=1e-5)
    lengths = rng.uniform(0.1, 6.0, 2000)
    blocked = raycaster.occluded_rays(origins, directions, lengths, eps=0.0)
    low = raycaster.occluded_segments32(shifted, np.ascontiguousarray(directions, dtype=np.float32),
                                        lengths.astype(np.float32))
    assert 0.05 < blocked.mean() < 0.95  # both outcomes occur
    # identical but for segments ending within float32 rounding of a surface
    near_end = np.abs(hits.distance_m - lengths) < 1e-5
    assert np.array_equal(low[~near_end], blocked[~near_end])


def test_thread_helpers_keep_the_task_order_and_refuse_bad_counts():
    assert run_in_order(lambda k: k * k, range(20), 3) == [k * k for k in range(20)]

    def fail(k):
        if k == 7:
            raise ValueError("task 7")
        return k

    with pytest.raises(ValueError, match="task 7"):
        run_in_order(fail, range(10), 2)
    assert resolve_threads(None) >= 1 and resolve_threads(3) == 3
    for bad in (0, -1, 1.5, True):
        with pytest.raises(InputError, match="threads"):
            resolve_threads(bad)


def test_chunks_written_ahead_of_their_place_are_copied_to_it_exactly():
    # The output placement the threads rely on, driven by hand (a thread schedule cannot be
    # forced): chunk 0 starts first and writes in place; chunks 1 and 2 start before it is
    # placed and write into scratch blocks of their own; they finish out of order. The arrays
    # must equal the chunks' events and receptions concatenated in chunk order, event indices
    # (parents, the receptions' events) shifted to the final rows. A chunk starting once every
    # earlier one is placed writes in place again; a placed chunk's block is reused.
    n_rx, counts = 2, [(5, 7), (3, 0), (4, 6), (2, 3)]  # (events, receptions) per chunk
    placement = ChunkPlacement(CHUNK_RAYS * 4, 2, n_rx, CHUNK_RAYS)
    out = placement.output
    targets = [placement.start(c) for c in range(3)]
    assert targets[0][0] is out and targets[0][1:] == (0, 0)
    blocks = [targets[1][0], targets[2][0]]
    assert all(block is not out for block in blocks) and blocks[0] is not blocks[1]
    assert targets[1][1:] == targets[2][1:] == (0, 0)
    assert blocks[0].point.shape == (placement.slot_events, 3) and blocks[0].gain.shape == (placement.slot_receptions,)

    def write(c, target):
        arrays, e0, r0 = target
        n_e, n_r = counts[c]
        rows, recs = slice(e0, e0 + n_e), slice(r0, r0 + n_r)
        points = np.arange(3 * n_e, dtype=float).reshape(n_e, 3) + 100.0 * c
        arrays.point[rows], arrays.departure[rows] = points, -points
        arrays.surface[rows], arrays.bounce[rows] = c, 1
        arrays.travelled[rows], arrays.phase[rows] = points[:, 0], points[:, 1]
        parent = np.where(np.arange(n_e) % 2 == 1, e0 + np.arange(n_e) - 1, -1)  # links inside the chunk
        arrays.parent[rows] = parent
        event = e0 + np.arange(n_r) % max(n_e, 1)
        arrays.event[recs], arrays.channel[recs] = event, np.arange(n_r) % n_rx
        arrays.gain[recs] = 1.0 + c + np.arange(n_r)
        return points, np.where(parent >= 0, parent - e0, -1), event - e0, 1.0 + c + np.arange(n_r)

    written = {c: write(c, targets[c]) for c in (2, 1, 0)}
    placement.finish(2, targets[2][0], *counts[2])
    placement.finish(1, targets[1][0], *counts[1])
    assert placement.start(3)[0] is not out  # chunk 0 still unplaced: a scratch block
    placement.finish(0, out, *counts[0])
    target3 = placement.start(3)
    assert target3[0] is out and target3[1:] == (sum(e for e, _ in counts[:3]), sum(r for _, r in counts[:3]))
    written[3] = write(3, target3)
    placement.finish(3, out, *counts[3])
    reused = placement.start(5)[0]
    assert any(reused is block for block in blocks)  # a placed chunk's block
    expected: dict[str, list[np.ndarray]] = {k: [] for k in ("point", "parent", "event", "gain")}
    first = 0
    for c in range(4):
        points, parent, event, gain = written[c]
        expected["point"].append(points)
        expected["parent"].append(np.where(parent >= 0, parent + first, -1))
        expected["event"].append(event + first)
        expected["gain"].append(gain)
        first += counts[c][0]
    events: EventArrays = placement.placed()
    for name, parts in expected.items():
        np.testing.assert_array_equal(getattr(events, name), np.concatenate(parts), err_msg=name)
    np.testing.assert_array_equal(events.departure, -np.concatenate(expected["point"]))
    np.testing.assert_array_equal(events.surface, np.repeat(np.arange(4), [e for e, _ in counts]))
    assert events.point.shape == (first, 3) and events.channel.size == sum(r for _, r in counts)
