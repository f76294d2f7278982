"""The edge mechanism's rows: first-order diffraction and diffraction combined with reflections.

The rows of :mod:`.edges` (each sharp edge between the transmitter and a receiver) and, with
``config.edge_reflections`` > 0, those of :mod:`.edge_reflections` (an edge between images)
within reach of a geometric boundary, under one element floor: rows weaker than
:data:`~.edges.ELEMENT_FLOOR` of the strongest impulse of either kind are dropped; then one row
per pair beyond reach, Keller's apex (:mod:`.edge_apex`). The physics, method and accuracy are in those two modules;
this one only joins them, so that neither imports the other's caller.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.config import SolverConfig
from acoustisim.propagation.context import SolveContext
from acoustisim.propagation.paths import empty_paths_array
from acoustisim.propagation.prepared import PreparedScene
from acoustisim.propagation.reference.edge_apex import apex_parts, apex_rows
from acoustisim.propagation.reference.edge_reflections import reference_kernels, reflected_impulses, reflected_rows
from acoustisim.propagation.reference.edges import ELEMENT_FLOOR, EdgeImpulses, first_order_impulses, impulse_rows


def edge_rows(context: SolveContext, config: SolverConfig, prepared: PreparedScene) -> NDArray[Any]:
    """Edge-diffraction rows of one pose: the first-order ones in (pair, element) order, then
    those of the edges combined with up to ``config.edge_reflections`` reflections, their path
    ids after the first-order ones, the element floor relative to the strongest impulse of both;
    then the apex rows of the pairs beyond reach (``response_id``
    :data:`~.edge_apex.APEX_RESPONSE_ID`: the solver's :func:`~.edge_apex.apex_response`).

    Returns
    -------
    structured ndarray of PATH_DTYPE, shape (n,)
        The mechanism's columns; the derived ones are left to the assembly.

    Raises
    ------
    InputError
        If ``config.edge_segment_m`` would make more than
        :data:`~acoustisim.propagation.reference.edges.MAX_ELEMENTS` elements.
    """
    pairs, impulses = first_order_impulses(context, config, prepared)
    parts = reflected_impulses(context, config, prepared)
    reflected = parts.impulses
    strongest = max([float(np.max(np.abs(impulses.gain), initial=0.0))]
                    + [float(np.max(np.abs(part.impulses.gain))) for part in reflected])
    if strongest == 0.0:
        rows, reflected = empty_paths_array(0), []
    else:
        strong = np.abs(impulses.gain) > ELEMENT_FLOOR * strongest
        rows = impulse_rows(context, prepared.diffracting_edges, pairs,
                            EdgeImpulses(*(column[strong] for column in impulses)))
    next_id = int(rows["path_id"].max()) + 1 if rows.size else context.first_path_id
    if reflected:
        rows = np.concatenate([rows, reflected_rows(context, prepared, reflected, ELEMENT_FLOOR * strongest, next_id)])
        next_id = int(rows["path_id"].max()) + 1
    apexes = apex_parts(context, prepared, parts.far, reference_kernels())
    return np.concatenate([rows, apex_rows(context, prepared, apexes, next_id)]) if apexes else rows


__all__ = ("edge_rows",)
