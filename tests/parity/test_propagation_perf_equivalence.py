"""Fast paths against the straightforward computation: the fast engine's ``complete_columns``
(transmitter columns once per run of equal departure directions, any field layout) against the
reference engine's; ``RayCaster``'s unit-direction and hit-only paths against its general
queries.
"""

from __future__ import annotations

import numpy as np

from acoustisim.medium import Medium
from acoustisim.propagation.fast.columns import complete_columns
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.paths import PATH_DTYPE, empty_paths_array
from acoustisim.propagation.reference import columns as reference_columns
from acoustisim.propagation.raycast import RayCaster
from acoustisim.scene import Scene, Tank
from acoustisim.sonar import SonarHead
from scenes.builders import sphere


def _scene() -> Scene:
    ball = sphere("ball", (4.0, 1.5, 0.5), 0.2, "steel")
    return Scene("eq", Medium(), SonarHead(), Tank(9.0, 3.0, 1.0), (ball,))


def _random_rows(rng: np.random.Generator, n_events: int) -> np.ndarray:
    """Rows in diffuse layout: 1..3 receivers per event sharing its departure direction."""
    per_event = rng.integers(1, 4, n_events)
    event = np.repeat(np.arange(n_events), per_event)
    departure = rng.normal(size=(n_events, 3))
    departure /= np.linalg.norm(departure, axis=1, keepdims=True)
    rows = empty_paths_array(event.size)
    rows["path_length_m"] = rng.uniform(0.1, 20.0, event.size)
    rows["geometric_gain"] = rng.normal(size=event.size)
    rows["departure_dir"] = departure[event]
    arrival = rng.normal(size=(event.size, 3))
    rows["arrival_dir"] = arrival / np.linalg.norm(arrival, axis=1, keepdims=True)
    return rows


DERIVED = ("delay_s", "angle_tx_rad", "angle_rx_rad", "directivity_tx", "directivity_rx", "absorption_db", "amplitude")


def test_complete_columns_matches_the_reference_engine_in_any_layout():
    scene = _scene()
    context = SolveContext.build(scene, scene.sonar, RayCaster.from_scene(scene))
    rows = _random_rows(np.random.default_rng(3), 2000)
    filled = reference_columns.complete_columns(rows.copy(), context)
    expected = {name: filled[name] for name in DERIVED}
    # the same fields in another order: the derived columns are no longer back to back, so the
    # per-field fallback runs instead of the block write
    names = list(PATH_DTYPE.names)
    shuffled = np.dtype([(name, PATH_DTYPE.fields[name][0]) for name in names[::-1]])
    other = np.zeros(rows.size, dtype=shuffled)
    for name in names:
        other[name] = rows[name]
    for filled in (complete_columns(rows.copy(), context), complete_columns(other, context),
                   complete_columns(rows.copy()[::-1], context)[::-1]):
        for name, value in expected.items():
            # the fast path forms sin(angle) as |d x a| / hypot and 10^(-L/20) as an exponential:
            # a few ulps of O(1) quantities, hence 1e-12 relative
            np.testing.assert_allclose(filled[name], value, rtol=1e-12, atol=1e-15, err_msg=name)
        # the source columns are left untouched
        np.testing.assert_array_equal(filled["departure_dir"], rows["departure_dir"])
        np.testing.assert_array_equal(filled["geometric_gain"], rows["geometric_gain"])


def test_ray_caster_fast_paths_agree_with_the_general_queries():
    scene = _scene()
    rc = RayCaster.from_scene(scene)
    rng = np.random.default_rng(5)
    n = 3000
    # rays inside the closed tank all hit; a tenth start outside it, pointing away: misses
    origins = rng.uniform((0.2, 0.2, 0.2), (8.8, 2.8, 0.8), (n, 3))
    origins[: n // 10] = (20.0, 1.5, 0.5)
    directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    directions[: n // 10] = (1.0, 0.0, 0.0)
    general = rc.intersect(origins, directions)
    fast = rc.intersect(origins, directions, unit_directions=True)
    assert 0 < np.count_nonzero(~general.hit) < n
    for name in ("distance_m", "triangle", "surface", "normal"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(general, name), err_msg=name)
    # misses carry the documented sentinels; hits the face normal of the hit triangle
    assert np.all(np.isnan(general.normal[~general.hit])) and np.all(np.isinf(general.distance_m[~general.hit]))
    assert np.all(general.surface[~general.hit] == -1)
    np.testing.assert_array_equal(general.normal[general.hit], rc.face_normals[general.triangle[general.hit]])

    targets = rng.uniform((0.2, 0.2, 0.2), (8.8, 2.8, 0.8), (n, 3))
    targets[:50] = origins[:50] + 1e-5  # shorter than 2 eps: never blocked
    seg = targets - origins
    length = np.linalg.norm(seg, axis=1)
    blocked = rc.occluded(origins, targets)
    assert 0 < np.count_nonzero(blocked) < n and not np.any(blocked[:50])
    np.testing.assert_array_equal(rc.occluded_rays(origins, seg / length[:, None], length), blocked)
    ball_patch = rc.patch_index[rc.surface_index == scene.surface_names.index("ball")][0]
    exclude = np.full((n, 2), -1)
    exclude[::2, 0] = ball_patch
    with_exclusion = rc.occluded(origins, targets, exclude_patches=exclude)
    assert np.count_nonzero(with_exclusion) < np.count_nonzero(blocked)  # some legs only crossed the ball
    np.testing.assert_array_equal(
        rc.occluded_rays(origins, seg / length[:, None], length, exclude_patches=exclude), with_exclusion)
