"""The built-in scenes' record lengths hold every arrival the default solver keeps: a default
``simulate`` drops nothing and warns about nothing."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from acoustisim.propagation import SolverConfig
from acoustisim.propagation.paths import PATH_DTYPE, Paths, empty_paths_array
from scenes.builtin import builtin_scene, builtin_scene_names

from regression.arrival_tables import stored_arrivals


def _paths(name: str) -> Paths:
    """The stored arrival table (default solver, direct + specular + edge) as Paths, each row a
    plain impulse (the table stores no transfer functions: ``response_id`` is left at -1; the
    delays, which are what the record length must hold, are the table's)."""
    scene = builtin_scene(name)
    stored = stored_arrivals(name)
    rows = empty_paths_array(stored.size)
    for field in stored.dtype.names:
        if field in PATH_DTYPE.names and field != "response_id":
            rows[field] = stored[field]
    return Paths(rows, scene.surface_names, scene.sonar.centre_frequency_hz, float(scene.medium.sound_speed))


@pytest.mark.parametrize("name", builtin_scene_names())
def test_default_simulation_keeps_every_deterministic_arrival_without_a_warning(name: str) -> None:
    from acoustisim.simulation import simulate

    scene = builtin_scene(name)
    paths = _paths(name)
    assert float(paths["delay_s"].max()) < scene.sonar.record_length_s
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any warning (e.g. "record_length_s ... too short") fails
        simulate(scene, paths=paths, seed=0, n_pings=1)


@pytest.mark.parametrize("name", builtin_scene_names())
def test_every_diffuse_arrival_fits_too(name: str) -> None:
    """The default diffuse tracer scatters once (checked), so its longest path goes from the
    transmitter to the farthest point of the tank (a corner) and back to a receiver: bounded by
    twice the transmitter-corner distance plus the receivers' offset. In free field the rays
    leave for good and the only diffuse rows are off the object, nearer than its far side."""
    scene = builtin_scene(name)
    assert SolverConfig().diffuse_bounces == 1
    tx = np.asarray(scene.sonar.transmitter_position, dtype=float)
    if scene.tank is None:
        far = max(np.max(np.linalg.norm(obj.bounds_m - tx, axis=1)) for obj in scene.objects)
    else:
        lo, hi = scene.tank.bounds_m
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        far = float(np.max(np.linalg.norm(corners - tx, axis=1)))
    offset = float(np.max(np.linalg.norm(scene.sonar.receiver_positions - tx, axis=1)))
    longest_s = (2.0 * far + offset) / float(scene.medium.sound_speed)
    assert longest_s < scene.sonar.record_length_s, f"{name}: {longest_s * 1e3:.2f} ms"
    assert math.isfinite(longest_s)
