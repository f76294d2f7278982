"""Hand-made path tables for the viewer's tests: many one-bounce rows of each kind."""

from __future__ import annotations

import numpy as np

from acoustisim.propagation.paths import PathKind, Paths, empty_paths_array
from acoustisim.sonar import SonarHead

C_WATER = 1482.38  # m/s, fresh water at 20 C


def fan_of_paths(*, n_diffuse: int, n_edge: int, n_specular: int, seed: int = 5) -> tuple[Paths, SonarHead]:
    """Rows on the centre channel, each with one interaction point ahead of the sonar (so two
    segments per row), of distinct amplitudes (1e-4 .. 1e-1, random order), each its own
    ``path_id`` (edge rows: one element per arrival).

    Returns
    -------
    paths : Paths
    sonar : SonarHead
        The default head, whose transducers close the polylines.
    """
    sonar = SonarHead()
    rng = np.random.default_rng(seed)
    kinds = np.repeat([PathKind.DIFFUSE, PathKind.EDGE, PathKind.SPECULAR], [n_diffuse, n_edge, n_specular])
    n = kinds.size
    rows = empty_paths_array(n)
    rows["kind"] = kinds
    rows["order"] = 1
    rows["channel"] = 1
    rows["path_id"] = np.arange(n)
    rows["amplitude"] = 10.0 ** rng.permutation(np.linspace(-4.0, -1.0, n))
    rows["geometric_gain"] = rows["amplitude"]
    points = rng.uniform([2.0, 0.5, 0.1], [8.0, 2.5, 0.9], (n, 3))
    rows["points_m"][:, 0] = points
    rows["object_ids"][:, 0] = 0
    length = np.linalg.norm(points - sonar.transmitter_position, axis=1) + np.linalg.norm(
        points - sonar.receiver_positions[1], axis=1)
    rows["path_length_m"] = length
    rows["delay_s"] = length / C_WATER
    return Paths(rows, ("floor",), 500e3, C_WATER), sonar
