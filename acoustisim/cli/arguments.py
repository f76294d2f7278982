"""Argument types and options shared by the ``acoustisim`` verbs.

Each type raises ``argparse.ArgumentTypeError`` with a message naming the bound, which the
parser prints on one line with exit code 2. The resource-limit options
(:func:`add_limit_arguments`) and :func:`with_limits` put the limits the user asked for in
force around a verb (:func:`acoustisim.resources.resource_limits`).
"""

from __future__ import annotations

import argparse
import math
from typing import Callable

from acoustisim.ranges import PhysicalRange

MAX_SEED = 2**63 - 1
"""Largest seed accepted (stored as a signed 64-bit integer in recordings and datasets)."""


def int_at_least(minimum: int, maximum: int | None = None) -> Callable[[str], int]:
    """An argparse type accepting integers >= ``minimum`` (and <= ``maximum``), naming the bounds."""
    bounds = f">= {minimum}" + ("" if maximum is None else f" and <= {maximum}")

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer {bounds}, got {text[:40]!r}") from None
        if value < minimum or (maximum is not None and value > maximum):
            raise argparse.ArgumentTypeError(f"expected an integer {bounds}, got {text[:40]!r}")
        return value

    parse.__name__ = f"integer {bounds}"
    return parse


def seed(text: str) -> int:
    """A seed: an integer in [0, 2^63 - 1]."""
    return int_at_least(0, MAX_SEED)(text)


def finite_float(allowed: PhysicalRange | None = None) -> Callable[[str], float]:
    """An argparse type accepting finite numbers (inside ``allowed`` when given)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text[:40]!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"expected a finite number, got {text[:40]!r}")
        if allowed is not None and not allowed.contains(value):
            raise argparse.ArgumentTypeError(f"{text[:40]!r} {allowed.describe()}")
        return value

    parse.__name__ = "number"
    return parse


def positive_number(text: str) -> float:
    """A finite number > 0."""
    return finite_float(PhysicalRange(0.0, math.inf, "", "a positive limit", low_open=True))(text)


def path_argument(text: str) -> str:
    """A file or folder path: not empty, no NUL character."""
    if not text:
        raise argparse.ArgumentTypeError("expected a path, got an empty string")
    if "\0" in text:
        raise argparse.ArgumentTypeError("a path cannot contain a NUL character")
    return text


def add_limit_arguments(parser: argparse.ArgumentParser) -> None:
    """The options that raise (or lower) the resource limits of one command."""
    from acoustisim.resources import ResourceLimits

    default = ResourceLimits()
    group = parser.add_argument_group(
        "resource limits", "refuse, before any work, what would exceed them (defaults, or the "
        "ACOUSTISIM_MAX_MEMORY_GB, _TRIANGLES, _RAYS, _CHAINS, _OBJECTS environment variables)")
    group.add_argument("--max-memory-gb", type=positive_number, default=None, metavar="GB",
                       help=f"estimated peak memory (default {default.max_memory_gb:g})")
    group.add_argument("--max-triangles", type=positive_number, default=None, metavar="N",
                       help=f"triangles over all objects (default {default.max_triangles:,})")
    group.add_argument("--max-rays", type=positive_number, default=None, metavar="N",
                       help=f"diffuse ray-bounces (default {default.max_rays:,})")
    group.add_argument("--max-chains", type=positive_number, default=None, metavar="N",
                       help=f"specular reflector sequences (default {default.max_chains:g})")
    group.add_argument("--max-objects", type=positive_number, default=None, metavar="N",
                       help=f"objects in the scene (default {default.max_objects:,})")


def with_limits(run: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """``run`` with the limits of :func:`add_limit_arguments` (over the environment's) in force."""

    def limited(args: argparse.Namespace) -> int:
        from acoustisim.resources import ResourceLimits, resource_limits

        limits = ResourceLimits.from_environment().raised(
            max_memory_gb=args.max_memory_gb, max_triangles=args.max_triangles, max_rays=args.max_rays,
            max_chains=args.max_chains, max_objects=args.max_objects)
        with resource_limits(limits):
            return run(args)

    limited.__name__ = getattr(run, "__name__", "run")
    limited.__doc__ = run.__doc__
    return limited


__all__ = ("MAX_SEED", "add_limit_arguments", "finite_float", "int_at_least", "path_argument", "positive_number",
           "seed", "with_limits")
