"""The fast engine's direct path: :mod:`acoustisim.propagation.reference.direct`'s rows, its legs
written straight to Embree's float32 buffers (the buffers ``RayCaster.occluded`` would build)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.fast.chain_kernels import ChainLegs, occlusion_queries32
from acoustisim.propagation.paths import PathKind, empty_paths_array
from acoustisim.propagation.raycast import DEFAULT_EPS_M
from acoustisim.propagation.reference.direct import SAME_POINT_M


def direct_rows(context: SolveContext) -> NDArray[Any]:
    """Unblocked transmitter-to-receiver rows: gain 1 / r, path id ``context.first_path_id``."""
    tx = context.transmitter_m
    rx = context.receivers_m
    dist = np.linalg.norm(rx - tx, axis=1)
    channels = np.flatnonzero(dist > SAME_POINT_M)
    origins = np.tile(tx, (channels.size, 1))
    legs = rx[channels] - origins
    length = np.linalg.norm(legs, axis=1)
    raycaster = context.raycaster
    queries = occlusion_queries32(ChainLegs(origins, legs / length[:, None], length,
                                            np.full((channels.size, 2), -1, dtype=np.int64)),
                                  raycaster.shift_m, DEFAULT_EPS_M)
    blocked = np.zeros(channels.size, dtype=bool)
    hit = raycaster.occluded_segments32(queries.starts32, queries.directions32, queries.lengths32)
    blocked[queries.leg[hit]] = True
    channels = channels[~blocked]
    rows = empty_paths_array(channels.size)
    rows["path_id"] = context.first_path_id
    rows["channel"] = channels
    rows["kind"] = PathKind.DIRECT
    rows["order"] = 0
    r = dist[channels]
    rows["path_length_m"] = r
    rows["geometric_gain"] = 1.0 / r
    direction = (rx[channels] - tx) / r[:, None]
    rows["departure_dir"] = direction
    rows["arrival_dir"] = direction
    return rows


__all__ = ("direct_rows",)
