"""The fast engine against the reference engine: the same rows, mechanism by mechanism.

Deterministic mechanisms (direct, specular, edge) must give the same arrivals with delays
within 1 ps and amplitudes within 1e-9 relative (:mod:`support.parity`). The diffuse tracer
draws the same counter-based random numbers in both engines, so its rows match too.
Canonical scenes and random poses run by default; the thesis tank at several poses is
``slow``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from acoustisim.propagation import SolverConfig, prepare, solve
from conftest import CANONICAL_SCENES
from support.parity import assert_rows_match

MECHANISMS: tuple[str, ...] = ("direct", "specular", "edge", "diffuse")


def both_engines(scene, config: SolverConfig, sonar=None):
    prepared = prepare(scene)
    fast = solve(prepared, sonar, replace(config, backend="fast"))
    reference = solve(prepared, sonar, replace(config, backend="reference"))
    return fast.rows, reference.rows


def random_poses(scene, n: int, seed: int):
    """``n`` poses of ``scene``'s sonar: position moved up to 5 cm, yaw up to +/-20 deg, pitch up
    to +/-5 deg (the object stays in the beam's neighbourhood)."""
    rng = np.random.default_rng(seed)
    sonar = scene.sonar
    for _ in range(n):
        shift = rng.uniform(-0.05, 0.05, 3)
        yield sonar.with_pose(position_m=tuple(np.asarray(sonar.position_m) + shift),
                              yaw_deg=float(sonar.yaw_deg + rng.uniform(-20, 20)),
                              pitch_deg=float(rng.uniform(-5, 5)))


@pytest.mark.parametrize("mechanism", MECHANISMS)
@pytest.mark.parametrize("scene_name", CANONICAL_SCENES)
def test_engines_agree_on_the_canonical_scenes(scene_name: str, mechanism: str, builtin_scenes) -> None:
    config = SolverConfig(mechanisms=(mechanism,), amplitude_floor_db=None, diffuse_rays=4000)
    fast, reference = both_engines(builtin_scenes(scene_name), config)
    assert_rows_match(fast, reference, label=f"{scene_name}/{mechanism}")


@pytest.mark.parametrize("mechanism", MECHANISMS)
@pytest.mark.parametrize("scene_name", ("free-edge", "free-cylinder"))
def test_engines_agree_at_random_poses(scene_name: str, mechanism: str, builtin_scenes) -> None:
    scene = builtin_scenes(scene_name)
    config = SolverConfig(mechanisms=(mechanism,), amplitude_floor_db=None, diffuse_rays=2000)
    for i, sonar in enumerate(random_poses(scene, 3, seed=16)):
        fast, reference = both_engines(scene, config, sonar)
        assert_rows_match(fast, reference, label=f"{scene_name}/{mechanism}/pose {i}")


def test_engines_agree_on_the_assembled_solve_with_the_floor(builtin_scenes) -> None:
    """All mechanisms together, amplitude floor on: the same rows survive in the same order."""
    config = SolverConfig(diffuse_rays=4000)
    fast, reference = both_engines(builtin_scenes("free-edge"), config)
    assert_rows_match(fast, reference, label="free-edge/all")
    assert np.array_equal(fast["channel"], reference["channel"])
    assert np.all(np.abs(fast["delay_s"] - reference["delay_s"]) <= 1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_engines_agree_on_the_thesis_tank(mechanism: str, thesis_tank) -> None:
    config = SolverConfig(mechanisms=(mechanism,), amplitude_floor_db=None, diffuse_rays=20_000)
    poses = [thesis_tank.sonar, *random_poses(thesis_tank, 4, seed=17)]
    for i, sonar in enumerate(poses):
        fast, reference = both_engines(thesis_tank, config, sonar)
        assert_rows_match(fast, reference, label=f"thesis-tank/{mechanism}/pose {i}")
