"""scenes: builders, built-in scenes and the scene file (TOML) for acoustisim.

``from scenes import load_scene`` (and the other names below) works without importing the
heavy modules up front: each name is imported from its module on first use (PEP 562), so
``import scenes`` stays light.

Modules
-------
builders
    Scene objects (post, edge prism, cylinder, sphere, plate, user mesh) and the default sonar.
builtin
    Named scenes: ``thesis-tank`` and the free-field validation scenes ``free-*``.
scene_file
    Load, validate and save scene files; ``load_scene`` also takes a built-in name.
file_access
    Reading the files a scene names: regular files only, bounded in size.
validation
    Physical checks: objects in the water and apart, the sonar's transducers clear.
summary
    The JSON-ready description printed by ``acoustisim scene show``.
tessellation
    The sagitta criterion that sets how finely curved objects are meshed.
"""

from __future__ import annotations

import importlib
from types import MappingProxyType
from typing import Any

_LAZY = MappingProxyType({
    "load_scene": "scenes.scene_file",
    "read_scene_file": "scenes.scene_file",
    "save_scene": "scenes.scene_file",
    "scene_to_toml": "scenes.scene_file",
    "scene_from_toml": "scenes.scene_file",
    "SceneFileError": "scenes.errors",
    "builtin_scene": "scenes.builtin",
    "builtin_scene_names": "scenes.builtin",
    "default_sonar": "scenes.builders",
    "validate_scene": "scenes.validation",
    "scene_summary": "scenes.summary",
})

__all__ = tuple(_LAZY)


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'scenes' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


def __dir__() -> list[str]:
    return sorted((*globals(), *_LAZY))
