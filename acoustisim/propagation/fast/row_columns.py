"""The mechanism's columns of one ``PATH_DTYPE`` row, written by the compiled row writers.

A mechanism fills the columns that describe its path (identity, kind, order, path length, the
signed gain and phase, the geometry) and leaves the derived ones (delay, angles, directivities,
absorption, amplitude, roughness, response) to the assembly and the steps after it. The edge,
edge-and-reflection and diffuse writers write their rows field by field in one pass;
:func:`write_path_columns` is the part they share, so every derived column is zeroed in one
place (``response_id`` -1: no transfer function).
"""

from __future__ import annotations

from typing import Any

from numba import njit


@njit(cache=True, nogil=True)
def write_path_columns(row: Any, path_id: int, channel: int, kind: int, order: int, path_length_m: float,
                       gain: float, phase_rad: float) -> None:
    """Write ``row``'s mechanism columns (path id, channel, kind, order, path length (m), signed
    gain, phase (rad)) and zero its derived columns, in place."""
    row.path_id = path_id
    row.channel = channel
    row.kind = kind
    row.order = order
    row.delay_s = 0.0
    row.path_length_m = path_length_m
    row.geometric_gain = gain
    row.phase_rad = phase_rad
    row.angle_tx_rad = 0.0
    row.angle_rx_rad = 0.0
    row.directivity_tx = 0.0
    row.directivity_rx = 0.0
    row.absorption_db = 0.0
    row.amplitude = 0.0
    row.roughness_m2 = 0.0
    row.response_id = -1


__all__ = ("write_path_columns",)
