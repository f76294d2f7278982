"""The direct path: transmitter straight to each receiver.

Physics
-------
A point source in a homogeneous medium: the pressure at distance r relative to the source's
pressure at 1 m is 1 / r (spherical spreading), delayed by r / c; directivity and absorption
are the derived columns (:mod:`acoustisim.propagation.reference.columns`).

Method
------
One leg per receiver, tested for occlusion by one batched Embree query
(:meth:`~acoustisim.propagation.raycast.RayCaster.occluded`); a receiver that is the
transmitter itself (the centre transducer, which transmits and receives) gets no direct row.

Accuracy
--------
Exact within geometric acoustics. A leg is blocked when any surface lies on it beyond
``DEFAULT_EPS_M`` of its ends (the transducer faces themselves); a blocked leg is dropped
whole (no diffraction around the obstacle).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.paths import PathKind, empty_paths_array

SAME_POINT_M = 1e-9
"""A receiver closer than this to the transmitter is the transmitter itself (m)."""


def direct_rows(context: SolveContext) -> NDArray[Any]:
    """Unblocked transmitter-to-receiver rows: gain 1 / r, path id ``context.first_path_id``."""
    tx = context.transmitter_m
    rx = context.receivers_m
    distance = np.linalg.norm(rx - tx, axis=1)
    channels = np.flatnonzero(distance > SAME_POINT_M)
    direction = (rx[channels] - tx) / distance[channels, None]
    blocked = context.raycaster.occluded(np.broadcast_to(tx, direction.shape), rx[channels])
    channels = channels[~blocked]
    r = distance[channels]
    rows = empty_paths_array(channels.size)
    rows["path_id"] = context.first_path_id
    rows["channel"] = channels
    rows["kind"] = PathKind.DIRECT
    rows["order"] = 0
    rows["path_length_m"] = r
    rows["geometric_gain"] = 1.0 / r
    rows["departure_dir"] = direction[~blocked]
    rows["arrival_dir"] = direction[~blocked]
    return rows


__all__ = ["direct_rows"]
