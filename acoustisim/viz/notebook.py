"""Views that display themselves in Jupyter.

>>> from acoustisim.viz import view                                  # doctest: +SKIP
>>> view("thesis-tank", camera="top")                                # doctest: +SKIP
>>> view(scene, paths, camera="perspective").interactive()           # doctest: +SKIP

:func:`view` returns a :class:`SceneView`: the last expression of a cell shows it as the PNG
picture of :func:`acoustisim.viz.snapshot.render_image` (``_repr_png_``; it is rendered once,
when first shown, and kept). ``.interactive()`` gives the WebGL page of
:func:`acoustisim.viz.render.html_page` inside the notebook (``_repr_html_``: an ``iframe``
holding the self-contained page, nothing fetched from the network). ``.save(path)`` and
``.save_html(path)`` write them to files. The scene may be a Scene, a built-in scene's name or
a scene file's path, as everywhere in :mod:`acoustisim.viz`.
"""

from __future__ import annotations

import html
import io
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acoustisim.propagation.paths import Paths
from acoustisim.viz.render import ResultsInput, SceneInput, html_page, resolve_scene
from acoustisim.viz.snapshot import render_image

PAGE_HEIGHT_PX = 600
"""Height of the interactive page's frame in a notebook (pixels)."""


class InteractivePage:
    """The WebGL page of a view, shown inside a notebook cell.

    Parameters
    ----------
    page : str
        The self-contained HTML page.
    height_px : int
        Height of its frame in the notebook.
    """

    def __init__(self, page: str, height_px: int = PAGE_HEIGHT_PX) -> None:
        self.page = page
        self.height_px = int(height_px)

    def _repr_html_(self) -> str:
        # srcdoc keeps the page self-contained inside the notebook: no file, no server.
        return (f'<iframe srcdoc="{html.escape(self.page, quote=True)}" style="width:100%;height:{self.height_px}px;'
                'border:1px solid #ccc" sandbox="allow-scripts"></iframe>')


class SceneView:
    """A scene with its paths and estimates, displayed as a picture in Jupyter.

    Parameters
    ----------
    scene : Scene, built-in scene name or scene file path
    paths : Paths, optional
    results : sequence of EstimateMarker, or results JSON path, optional
    **options
        Keyword arguments of :func:`acoustisim.viz.snapshot.render_image` (``camera``,
        ``options``, ``sonar``, ``truths``, ``window_size``, ``title``); ``window_size`` and
        ``camera`` also set the interactive page's.
    """

    def __init__(self, scene: SceneInput, paths: Paths | None = None, results: ResultsInput = None,
                 **options: Any) -> None:
        self.scene = resolve_scene(scene)
        self.paths = paths
        self.results = results
        self.options = dict(options)
        self._image: NDArray[np.uint8] | None = None

    def __repr__(self) -> str:
        camera = self.options.get("camera", "perspective")
        paths = "no paths" if self.paths is None else f"{len(self.paths)} path rows"
        return f"SceneView({self.scene.name!r}, {paths}, camera={camera!r})"

    def image(self) -> NDArray[np.uint8]:
        """The picture, (height, width, 3) uint8 (rendered on first use, then kept)."""
        if self._image is None:
            self._image = render_image(self.scene, self.paths, self.results, **self.options)
        return self._image

    def png_bytes(self) -> bytes:
        """The picture as PNG file bytes."""
        from PIL import Image

        buffer = io.BytesIO()
        Image.fromarray(self.image()).save(buffer, format="PNG", optimize=True)
        return buffer.getvalue()

    def _repr_png_(self) -> bytes:
        return self.png_bytes()

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the picture to a PNG file; returns its path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(self.png_bytes())
        return path

    def _page_options(self) -> dict[str, Any]:
        keep = ("sonar", "truths", "options", "camera", "title", "window_size")
        return {k: v for k, v in self.options.items() if k in keep}

    def interactive(self, height_px: int = PAGE_HEIGHT_PX) -> InteractivePage:
        """The view as an interactive WebGL page inside the notebook."""
        return InteractivePage(html_page(self.scene, self.paths, self.results, **self._page_options()), height_px)

    def save_html(self, path: str | os.PathLike[str]) -> Path:
        """Write the interactive page to an HTML file; returns its path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(html_page(self.scene, self.paths, self.results, **self._page_options()), encoding="utf-8")
        return path


def view(scene: SceneInput, paths: Paths | None = None, results: ResultsInput = None, **options: Any) -> SceneView:
    """A :class:`SceneView` of ``scene`` (the scene first, as everywhere in :mod:`acoustisim.viz`)."""
    return SceneView(scene, paths, results, **options)
