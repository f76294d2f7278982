"""Compiled kernels called with typed bundles at the cost of plain tuples.

The fast engine's kernels take small NamedTuples (one per concern: geometry, candidates,
output). numba's dispatcher types a plain tuple of arrays in C, but a NamedTuple in Python,
which for a dozen arrays costs more than many a kernel's whole work. So a kernel receives each
bundle as a plain tuple of its fields and rebuilds the NamedTuple first thing (free in compiled
code), and :func:`plain_tuple_arguments` makes the Python-side call take the NamedTuples.
"""

from __future__ import annotations

import functools
from typing import Any, Callable


def plain_tuple_arguments(kernel: Any) -> Callable[..., Any]:
    """``kernel`` (a numba dispatcher) called with every tuple argument (a bundle) passed as a
    plain tuple of its fields; the dispatcher stays reachable as ``.dispatcher``."""

    @functools.wraps(kernel)
    def call(*args: Any) -> Any:
        return kernel(*[tuple(arg) if isinstance(arg, tuple) else arg for arg in args])

    call.dispatcher = kernel  # type: ignore[attr-defined]
    return call


__all__ = ("plain_tuple_arguments",)
