"""The fast diffuse tracer against the reference on rough surfaces: the Lambert strength that
carries the coherent-roughness loss (reference ``rough_lambert_mu``, compiled
``diffuse_kernels.rough_lambert_mu``) for every reflection model, and the same rows."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from acoustisim.materials import get_material
from acoustisim.propagation import SolverConfig, prepare
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast import diffuse as fast
from acoustisim.propagation.fast.diffuse_kernels import rough_lambert_mu as compiled_rough_mu
from acoustisim.propagation.reference import diffuse as reference
from support.parity import assert_rows_match


def rough_thesis_tank(scene):
    """Every reflection model rough (rigid as fixed: a constant): an elastic floor (concrete) and
    fluid-model walls (concrete, its shear ignored) without a mu of their own (only the roughness
    scatters there), a pressure-release surface, a fixed-model pipe."""
    concrete = get_material("concrete")
    floor = replace(concrete, name="floor-rough", roughness_rms_m=0.5e-3)
    wall = replace(concrete, name="wall-rough", model="fluid", roughness_rms_m=0.2e-3, diffuse_mu=0.0)
    surface = replace(get_material("pressure-release"), name="waves", roughness_rms_m=0.1e-3)
    pipe = replace(get_material("pvc-pipe-air"), name="pipe-rough", roughness_rms_m=0.3e-3)
    tank = replace(scene.tank, materials=(floor, wall, surface), floor_material=floor.name,
                   wall_material=wall.name, surface_material=surface.name)
    objects = tuple(replace(o, material=pipe) if o.name == "pipe-1" else o for o in scene.objects)
    return replace(scene, tank=tank, objects=objects)


@pytest.fixture(scope="module")
def rough_context(thesis_tank) -> SolveContext:
    scene = rough_thesis_tank(thesis_tank)
    return SolveContext.build(scene, scene.sonar, prepare(scene).raycaster, first_path_id=5)


def test_compiled_rough_mu_is_the_references(rough_context):
    # Every surface (four reflection models) over grazing sines 0..1, the critical angles of the
    # fluid and elastic ones included: the same formulas, real arithmetic (fluid) or compiled
    # complex scalars (elastic) against numpy's complex arrays (|R|^2 within a few ulp): 1e-13
    # relative, or 1e-18 absolute where it vanishes (grazing, or R = 0).
    rough = reference.rough_scattering(rough_context)
    table = fast.rough_table(rough, len(rough_context.scene.surface_names))
    assert {m.model for m in rough.material} == {"elastic", "fluid", "pressure-release", "fixed"}
    sines = np.linspace(0.0, 1.0, 2001)
    for s in range(len(rough_context.scene.surface_names)):
        expected = reference.rough_lambert_mu(rough, np.full(sines.size, s), sines)
        got = np.array([compiled_rough_mu(table, s, x) for x in sines])
        np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-18, err_msg=f"surface {s}")
        assert (np.any(expected > 0.0)) == (rough.rms_height_m[s] > 0.0)


@pytest.mark.parametrize("bounces", [1, 2])
def test_engines_agree_on_a_rough_tank(rough_context, thesis_tank, bounces):
    # Same rows, event by event; and the roughness adds events (the walls scatter only through
    # it, the free surface and further bounces too) and energy to the smooth tank's.
    config = SolverConfig(diffuse_rays=6000, diffuse_bounces=bounces, seed=4)
    rows = fast.diffuse_rows(rough_context, config)
    expected = reference.diffuse_rows(rough_context, config)
    assert_rows_match(rows, expected, label=f"{bounces} bounces")
    for name in ("path_id", "channel", "order", "object_ids"):
        assert np.array_equal(rows[name], expected[name]), name
    assert np.array_equal(rows["points_m"], expected["points_m"], equal_nan=True)
    smooth_context = SolveContext.build(thesis_tank, thesis_tank.sonar, prepare(thesis_tank).raycaster, 5)
    smooth = fast.diffuse_rows(smooth_context, config)
    names = rough_context.scene.surface_names
    hit = set(np.unique(rows["object_ids"][rows["object_ids"] >= 0]).tolist())
    assert {names.index("wall-y0"), names.index("surface")} <= hit
    assert rows.size > smooth.size
    assert np.sum(rows["geometric_gain"] ** 2) > np.sum(smooth["geometric_gain"] ** 2)
