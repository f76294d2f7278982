"""Shared fixtures: the canonical scenes every layer tests on, and the two propagation engines.

Layers (one directory each): ``unit`` (one function or class, no full solve), ``physics``
(analytic answers and physical invariants; propagation physics runs on both engines),
``parity`` (the fast engine against the reference engine and compiled kernels against their
definitions), ``regression`` (stored arrival tables of the built-in scenes), ``e2e`` (the
command line, the demo, datasets, the viewer). Shared helpers live in ``tests/support``.
"""

from __future__ import annotations

import pytest

from acoustisim.propagation.config import BACKENDS

CANONICAL_SCENES: tuple[str, ...] = ("free-sphere", "free-plane", "free-post", "free-edge", "free-cylinder")
"""The built-in single-object scenes whose echoes are known analytically (small: quick on the
reference engine)."""


@pytest.fixture(params=BACKENDS)
def backend(request: pytest.FixtureRequest) -> str:
    """Each propagation engine in turn ("fast", "reference"): physics tests run on both."""
    return request.param


@pytest.fixture(scope="session")
def builtin_scenes():
    """A cache of built-in scenes by name (built once per test session; scenes are immutable)."""
    from scenes.builtin import builtin_scene

    cache: dict = {}

    def get(name: str):
        if name not in cache:
            cache[name] = builtin_scene(name)
        return cache[name]

    return get


@pytest.fixture(scope="session")
def thesis_tank(builtin_scenes):
    """The thesis tank (posts, prism edge, pipe) with its default sonar."""
    return builtin_scenes("thesis-tank")
