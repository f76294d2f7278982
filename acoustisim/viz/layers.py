"""A drawable layer: one named mesh with its style, shared by the VTK and the WebGL back ends.

The scene builders in :mod:`acoustisim.viz.actors` return layers; :mod:`acoustisim.viz.render`
adds them to a pyvista plotter (one actor per layer, named ``Layer.name``) and
:mod:`acoustisim.viz.webgl` writes the same geometry into a standalone HTML page.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    import pyvista as pv

LayerStyle = Literal["surface", "wireframe", "lines", "points"]

RGBA_ARRAY = "rgba"
"""Name of the optional per-cell colour array (uint8, shape (n_cells, 4)) of a layer's mesh."""


@dataclass(frozen=True, eq=False)
class Layer:
    """One drawable thing.

    Attributes
    ----------
    name : str
        Unique actor name (tests look actors up by it), e.g. "tank-walls", "paths-specular".
    mesh : pyvista.PolyData
        Geometry in the tank frame (m). When it carries the cell array ``"rgba"`` (uint8,
        (n_cells, 4)), that array gives each cell's colour and opacity and ``color``/``opacity``
        are ignored.
    color : tuple of 3 float
        Uniform RGB colour in [0, 1].
    opacity : float
        Uniform opacity in [0, 1].
    style : {"surface", "wireframe", "lines", "points"}
        "lines" for line cells (paths, outlines), "points" for vertex markers.
    line_width : float
        Line width (pixels); WebGL draws every line 1 pixel wide.
    point_size : float
        Marker diameter (pixels) for the "points" style.
    flat_points : bool
        Draw points as flat squares instead of shaded spheres; a sphere marker at the same
        place is drawn in front of a flat one (truth under estimate).
    label : str
        Legend entry; "" keeps the layer out of the legend.
    group : str
        What the layer belongs to: "tank", "object", "sonar", "beam", "paths", "tof",
        "estimate", "truth".
    """

    name: str
    mesh: "pv.PolyData"
    color: tuple[float, float, float] = (0.5, 0.5, 0.5)
    opacity: float = 1.0
    style: LayerStyle = "surface"
    line_width: float = 1.0
    point_size: float = 10.0
    flat_points: bool = False
    label: str = ""
    group: str = ""

    @property
    def has_rgba(self) -> bool:
        """Whether the mesh carries its own per-cell colours."""
        return RGBA_ARRAY in self.mesh.cell_data
