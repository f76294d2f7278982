"""3-D visualisation of the tank, the echo paths and the localisation estimates (pyvista/VTK).

Python API (imported on first use, so ``import acoustisim.viz`` stays light). Every function
takes the scene first: a Scene, a built-in scene's name or a scene file's path.

- :func:`render_png` ``(scene, path, paths=None, results=None, **options)``: a picture (PNG)
  designed for reading: object names, axes or the tank's dimensions, a legend beside the scene;
  :func:`render_image` gives it as an array.
- :func:`export_html` ``(scene, path, ...)``: one self-contained HTML page with an embedded
  WebGL viewer; :func:`html_page` gives its text.
- :func:`show_scene` ``(scene, paths=None, results=None, ...)``: a pyvista plotter
  (``.show()`` opens a window).
- :func:`view` ``(scene, paths=None, results=None, ...)``: a :class:`SceneView` that displays
  itself in Jupyter (a PNG; ``.interactive()`` the WebGL page).
- :class:`ViewOptions`: what to draw.

Command line: ``acoustisim view``.

Modules: ``layers`` (the drawable unit), ``actors`` (layer builders, the palette), ``beam``
(piston beam angles), ``cameras`` (presets), ``render`` (layers, regions, window, HTML), ``snapshot`` (the PNG
picture), ``picture`` (its overlay, axes and legend), ``notebook`` (Jupyter display), ``webgl`` (the HTML
writer), ``results_file`` (localisation results JSON), ``ping_file`` (pose and truth of a ping
file).
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Any

__all__ = ("SceneView", "ViewOptions", "export_html", "html_page", "render_image", "render_picture", "render_png",
           "show_scene", "view")

_HOMES = MappingProxyType({"SceneView": "notebook", "view": "notebook", "render_image": "snapshot",
                           "render_picture": "snapshot", "render_png": "snapshot"})
"""The module of each public name not in ``render``."""


def __getattr__(name: str) -> Any:
    if name in __all__:
        import importlib

        module = importlib.import_module(f"acoustisim.viz.{_HOMES.get(name, 'render')}")
        return getattr(module, name)
    raise AttributeError(f"module 'acoustisim.viz' has no attribute {name!r}")
