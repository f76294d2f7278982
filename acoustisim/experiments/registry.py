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


def discover() -> tuple[dict[str, ModuleType], dict[str, str]]:
    """The experiment modules by ``NAME`` (sorted), and the modules that failed to import.

    A module that cannot be imported (e.g. one being written) does not take the others down:
    it is reported in the second mapping, module name -> one-line error.

    Raises
    ------
    RuntimeError
        Two modules claim the same ``NAME``.
    """
    import acoustisim.experiments as package

    found: dict[str, ModuleType] = {}
    broken: dict[str, str] = {}
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("_") or info.ispkg:
            continue
        try:
            module = importlib.import_module(f"{package.__name__}.{info.name}")
        except Exception as exc:  # noqa: BLE001 - reported, not hidden: see import_errors()
            broken[info.name] = f"{type(exc).__name__}: {exc}".splitlines()[0]
            continue
        name = getattr(module, "NAME", None)
        if isinstance(name, str) and callable(getattr(module, "run", None)):
            if name in found:
                raise RuntimeError(f"experiment name {name!r} defined by {found[name].__name__} and {module.__name__}")
            found[name] = module
    return dict(sorted(found.items())), broken


def experiment_modules() -> dict[str, ModuleType]:
    """The experiment modules by ``NAME``, sorted by name (see ``discover``)."""
    return discover()[0]


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
    modules, broken = discover()
    try:
        return modules[name]
    except KeyError:
        extra = f"; modules that failed to import: {', '.join(f'{k} ({v})' for k, v in broken.items())}" if broken else ""
        raise InputError(f"unknown experiment {name!r} (known: {', '.join(modules) or 'none'}){extra}") from None
