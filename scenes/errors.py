"""The error a bad scene (file or description) raises."""

from __future__ import annotations

from acoustisim.errors import InputError


class SceneFileError(InputError):
    """A scene file or scene that cannot be used. The one-line message names the file (or the
    scene), the key (e.g. ``objects[2].radius_m``) and the offending value; the command line
    prints it and exits with code 2."""
