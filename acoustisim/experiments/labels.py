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
               window_s: float = MATCH_WINDOW_S) -> tuple[str, float]:
    """The label and delay (s) of the strongest arrival on ``channel`` within ``window_s`` of ``tof_s``.

    Returns ("unexplained", NaN) when no arrival is that close (noise or a detector artefact).
    """
    near = np.flatnonzero((arrivals["channel"] == channel) & (np.abs(arrivals["delay_s"] - tof_s) <= window_s)
                          & (arrivals["kind"] != 0))
    if near.size == 0:
        return "unexplained", float("nan")
    best = near[int(np.argmax(np.abs(arrivals["amplitude"][near])))]
    suffix = " (diffuse)" if int(arrivals["kind"][best]) == 3 else ""
    return labels[best] + suffix, float(arrivals["delay_s"][best])
