"""3-D visualisation of the tank, the echo paths and the localisation estimates (pyvista/VTK).

Python API (imported on first use, so ``import acoustisim.viz`` stays light):
:func:`show_scene` (a pyvista plotter: ``.show()`` opens a window), :func:`render_png`
(off-screen), :func:`export_html` (one self-contained page with an embedded WebGL viewer),
:class:`ViewOptions`. Command line: ``acoustisim view``.

Modules: ``layers`` (the drawable unit), ``actors`` (layer builders), ``beam`` (piston beam
angles), ``cameras`` (presets), ``render`` (plotter, PNG, HTML), ``webgl`` (the HTML writer),
``results_file`` (localisation results JSON), ``ping_file`` (pose and truth of a ping file).
"""

from __future__ import annotations

from typing import Any

__all__ = ["ViewOptions", "export_html", "render_png", "show_scene"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from acoustisim.viz import render

        return getattr(render, name)
    raise AttributeError(f"module 'acoustisim.viz' has no attribute {name!r}")
