"""Naming detected echoes from the ground-truth arrivals ("post-1", "post-1 via surface", "wall-x1")."""

from __future__ import annotations

from typing import Sequence

import numpy as np
from numpy.typing import NDArray

MATCH_WINDOW_S = 1.0e-6
"""An echo is attributed to the strongest arrival within this time of its TOF (s): 0.74 mm of
range, a fifth of the 5 us pulse, wider than any TOF error above ~10 dB of SNR."""


def path_label(objects: Sequence[str], boundary_names: Sequence[str]) -> str:
    """A readable name of a path from the surfaces it touches, in order.

    The first scene object names the path, the tank boundaries it also touches follow after
    "via" ("post-1 via surface"); a path of boundaries only is named by them ("floor+surface");
    no interaction is the direct path.
    """
    if not objects:
        return "direct path"
    targets = [o for o in objects if o not in boundary_names]
    bounces = [o for o in objects if o in boundary_names]
    if not targets:
        return "+".join(dict.fromkeys(objects))
    others = [o for o in dict.fromkeys(targets[1:]) if o != targets[0]]
    label = targets[0] + ("+" + "+".join(others) if others else "")
    return label + (" via " + "+".join(dict.fromkeys(bounces)) if bounces else "")


def arrival_labels(arrivals: NDArray, surface_names: Sequence[str], boundary_names: Sequence[str]) -> list[str]:
    """``path_label`` of every row of an arrivals array (``Paths.arrivals()``)."""
    names = list(surface_names)
    return [path_label([names[i] for i in row if i >= 0], boundary_names) for row in arrivals["object_ids"]]


def label_echo(arrivals: NDArray, labels: Sequence[str], channel: int, tof_s: float,
               window_s: float = MATCH_WINDOW_S, internal: NDArray | None = None,
               resolution_s: float = 0.0) -> tuple[str, float]:
    """The label and delay (s) of what made an echo on ``channel`` at ``tof_s``.

    1. The strongest of the arrivals within ``window_s`` of ``tof_s`` and, with ``internal`` (the
       truth's internal arrivals of elastic echoes,
       :func:`acoustisim.propagation.elastic_echoes.internal_arrival_table`), the elastic echoes
       whose own pulse holds ``tof_s`` (from ``window_s`` before their delay to
       ``resolution_s`` after it: internal arrivals closer than that are not resolved from the
       echo, and move its peak), unless it is diffuse. A ringing echo peaks later than its
       specular delay: a weak arrival nearer that peak (a chain grazing another object) does
       not name it.
    2. Else a resolved internal arrival within ``window_s``, named "<echo> (<arrival>)", e.g.
       "post-1 (compressional through the diameter)" (the strongest, by the echo's amplitude and
       the arrival's level).
    3. Else that strongest arrival, diffuse ("<label> (diffuse)").

    Returns ("unexplained", NaN) when nothing explains it (noise or a detector artefact).
    """
    on_channel = (arrivals["channel"] == channel) & (arrivals["kind"] != 0)
    near = np.flatnonzero(on_channel & (np.abs(arrivals["delay_s"] - tof_s) <= window_s))
    if internal is not None and internal.size:
        holding = np.flatnonzero(on_channel & np.isin(arrivals["path_id"], internal["path_id"])
                                 & (arrivals["delay_s"] - window_s <= tof_s)
                                 & (tof_s <= arrivals["delay_s"] + resolution_s))
        near = np.union1d(near, holding)
    best = near[int(np.argmax(np.abs(arrivals["amplitude"][near])))] if near.size else -1
    if best >= 0 and int(arrivals["kind"][best]) != 3:
        return labels[best], float(arrivals["delay_s"][best])
    if internal is not None and internal.size:
        rows = internal[(internal["channel"] == channel) & (np.abs(internal["delay_s"] - tof_s) <= window_s)
                        & (internal["after_echo_s"] >= resolution_s)]
        scored = []
        for row in rows:
            echo = np.flatnonzero(on_channel & (arrivals["path_id"] == row["path_id"]))
            if echo.size:
                scored.append((abs(float(arrivals["amplitude"][echo[0]])) * 10.0 ** (row["level_db"] / 20.0),
                               f"{labels[echo[0]]} ({row['arrival'].decode()})", float(row["delay_s"])))
        if scored:
            _, label, delay = max(scored, key=lambda item: item[0])
            return label, delay
    if best >= 0:
        return labels[best] + " (diffuse)", float(arrivals["delay_s"][best])
    return "unexplained", float("nan")
