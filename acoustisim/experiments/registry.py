"""Discovery of the experiments: every module of ``acoustisim.experiments`` that defines
``NAME`` and ``run``.

An experiment module plugs in by existing: no list to edit. Helper modules (runner, report,
...) define no ``NAME`` and are skipped.
"""

from __future__ import annotations

import importlib
import pkgutil
from types import ModuleType

from acoustisim.errors import InputError


def experiment_modules() -> dict[str, ModuleType]:
    """The experiment modules by ``NAME``, sorted by name.

    Raises
    ------
    RuntimeError
        Two modules claim the same ``NAME``.
    """
    import acoustisim.experiments as package

    found: dict[str, ModuleType] = {}
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("_") or info.ispkg:
            continue
        module = importlib.import_module(f"{package.__name__}.{info.name}")
        name = getattr(module, "NAME", None)
        if isinstance(name, str) and callable(getattr(module, "run", None)):
            if name in found:
                raise RuntimeError(f"experiment name {name!r} defined by {found[name].__name__} and {module.__name__}")
            found[name] = module
    return dict(sorted(found.items()))


def experiment_names() -> tuple[str, ...]:
    """Names of the registered experiments."""
    return tuple(experiment_modules())


def experiment_module(name: str) -> ModuleType:
    """The module of the experiment ``name``.

    Raises
    ------
    InputError
        Unknown name (the message lists the known ones).
    """
    modules = experiment_modules()
    try:
        return modules[name]
    except KeyError:
        raise InputError(f"unknown experiment {name!r} (known: {', '.join(modules) or 'none'})") from None
