"""The thesis tank seen by a centred sonar: the expected echo families, with labels; the floor."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from acoustisim.propagation import PathKind, SolverConfig, prepare, solve
from acoustisim.propagation.config import BACKENDS
from scenes.builtin import builtin_scene

DETERMINISTIC = SolverConfig(max_order=3, mechanisms=("direct", "specular"), amplitude_floor_db=None)


@pytest.fixture(scope="module", params=BACKENDS)
def tank(request):
    scene = builtin_scene("thesis-tank")
    prepared = prepare(scene)
    return scene, prepared, solve(prepared, config=replace(DETERMINISTIC, backend=request.param)), request.param


def _rows(paths, channel: int, label: str):
    labels = np.array(paths.object_labels(), dtype=object)
    return paths.rows[(labels == label) & (paths["channel"] == channel)]


def test_target_echoes_at_their_ranges(tank):
    scene, _, paths, _ = tank
    c = scene.medium.sound_speed
    tx = scene.sonar.transmitter_position
    # (post-3 is left out: the line from the sonar to it grazes post-1 within 0.3 mm, where the
    # occlusion verdict belongs to the tessellation)
    for name in ("post-1", "post-2", "pipe-1"):
        prim = scene.object(name).primitive
        rows = _rows(paths, 1, name)
        assert rows.size == 1, name
        # monostatic echo of a vertical cylinder spanning the sonar's height: 2 (horizontal
        # distance to the axis - radius) / c, exact up to round-off
        horizontal = np.hypot(*(np.asarray(prim.center_m) - tx)[:2])
        assert rows["delay_s"][0] == pytest.approx(2 * (horizontal - prim.radius_m) / c, rel=1e-12)
        assert rows["kind"][0] == PathKind.SPECULAR and rows["order"][0] == 1
        for side in (0, 2):
            assert _rows(paths, side, name).size == 1


def test_surface_and_floor_multipaths(tank):
    scene, _, paths, _ = tank
    c = scene.medium.sound_speed
    surface = _rows(paths, 1, "surface")
    floor = _rows(paths, 1, "floor")
    # the sonar is at mid-depth (0.5 m in 1 m of water): both at 1 m of path
    assert surface["delay_s"][0] == pytest.approx(1.0 / c, rel=1e-12)
    assert surface["geometric_gain"][0] == pytest.approx(-1.0, rel=1e-12)  # R = -1 over 1 m
    # the floor at normal incidence: the concrete's complex (lossy, elastic) R, as |R| and -arg R
    concrete = scene.tank.boundaries[4].material.reflection_coefficient(1.0, scene.medium.density, c)
    assert floor["geometric_gain"][0] == pytest.approx(abs(concrete), rel=1e-12)
    assert floor["phase_rad"][0] == pytest.approx(-np.angle(concrete), rel=1e-9)
    # target echoes via the surface and the floor (the posts span the water: corner returns)
    for label in ("post-1>surface", "post-1>floor", "post-2>surface", "floor>pipe-1>surface"):
        assert _rows(paths, 1, label).size == 1, label
    direct = _rows(paths, 1, "post-1")["delay_s"][0]
    assert _rows(paths, 1, "post-1>surface")["delay_s"][0] > direct
    # the surface bounce flips the sign, the floor bounce keeps it (the lossy PVC's and
    # concrete's R carry small phases: the sign is that of the real part, gain x cos(phase))
    def signed(label):
        row = _rows(paths, 1, label)
        return row["geometric_gain"][0] * np.cos(row["phase_rad"][0])

    assert signed("post-1>surface") < 0 < signed("post-1>floor")


def test_far_wall_is_shadowed_by_the_prism_on_the_axis(tank):
    scene, _, paths, backend = tank
    c = scene.medium.sound_speed
    # the prism on the boresight hides the far wall's normal echo ...
    assert _rows(paths, 1, "wall-x1").size == 0
    # ... which appears, at 2 x 8 m, once the prism is taken out
    open_scene = replace(scene, objects=tuple(o for o in scene.objects if o.name != "edge-1"))
    open_paths = solve(open_scene, config=replace(DETERMINISTIC, backend=backend))
    far = _rows(open_paths, 1, "wall-x1")
    assert far.size == 1 and far["delay_s"][0] == pytest.approx(16.0 / c, rel=1e-12)
    # multipaths reaching the far wall around the prism remain
    labels = set(np.array(paths.for_channel(1).object_labels(), dtype=object))
    assert any("wall-x1" in label for label in labels)


def test_every_row_is_labelled_consistently(tank):
    _, _, paths, _ = tank
    labels = paths.object_labels()
    for row, label in zip(paths.rows, labels):
        k = int(row["order"])
        assert len(label.split(">")) == (k if k else 0) or (k == 0 and label == "")
        assert np.all(row["object_ids"][:k] >= 0) and np.all(row["object_ids"][k:] == -1)
        assert np.all(np.isfinite(row["points_m"][:k])) and np.all(np.isnan(row["points_m"][k:]))
    table = paths.arrivals_table()
    assert {"direct", "specular"} == {entry["kind"] for entry in table}
