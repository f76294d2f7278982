"""Like-for-like set-ups for same-run comparisons with an older checkout, and the alternating runs.

A benchmark that compares this tree with an older one (``--before-tree DIR``) runs itself in
both, in alternating subprocesses, each importing its own ``acoustisim``. "This tree" is the one
named by :data:`TREE_VARIABLE` if set (e.g. ``ACOUSTISIM_BENCH_TREE=/tmp/main python
benchmarks/bench_propagation.py --before-tree /tmp/old`` compares two other checkouts, such as
``git archive`` snapshots), else the benchmark script's own checkout. For the two to do the same work, the
mechanisms the older tree lacks are switched off where the tree knows them:

* :data:`NEW_KNOBS`: ``SolverConfig`` fields of mechanisms added since (chains through two
  curved objects, elastic echoes, diffracted shadows of smooth obstacles, edge diffraction
  combined with reflections), set to the value that turns them off; a tree without the field has
  no such mechanism;
* the plane-wave reflection of the built-in solids: the ``elastic`` model (water on an elastic
  half-space) becomes the ``fluid`` one the older trees used (:func:`fluid_reflection_scene`);
* the record length, where synthesis is compared (:func:`with_record_length`).

Every helper works on any tree: it reads what the tree's classes have instead of assuming it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

TREE_VARIABLE = "ACOUSTISIM_BENCH_TREE"
"""Environment variable naming the checkout whose ``acoustisim`` and ``scenes`` a benchmark
imports (set by :func:`alternating_runs` for each side)."""

NEW_KNOBS: tuple[tuple[str, Any], ...] = (("max_curved_per_path", 1), ("elastic_echoes", False), ("shadows", False),
                                          ("edge_reflections", 0))
"""``SolverConfig`` fields of mechanisms that older trees lack, and the value that switches each off."""

PRE_SESSION_RECORD_S = 0.0125
"""The thesis tank's record length before it was lengthened (s): the default sonar's."""


def tree_root(script: str) -> Path:
    """The checkout to import: :data:`TREE_VARIABLE` if set, else the one holding ``script``."""
    named = os.environ.get(TREE_VARIABLE)
    return Path(named).resolve() if named else Path(script).resolve().parents[1]


def solver_config(like_for_like: bool = False, **fields: Any) -> Any:
    """``SolverConfig(**fields)`` of the tree imported, without the fields it does not know;
    ``like_for_like``: with :data:`NEW_KNOBS` too (the new mechanisms off)."""
    from acoustisim.propagation import SolverConfig

    known = {item.name for item in dataclasses.fields(SolverConfig)}
    wanted = dict(NEW_KNOBS) if like_for_like else {}
    wanted.update(fields)
    return SolverConfig(**{name: value for name, value in wanted.items() if name in known})


def fluid_reflection_scene(scene: Any) -> Any:
    """``scene`` with every material of the ``elastic`` reflection model on the ``fluid`` one (the
    reflection of the older trees; a tree without reflection models gets ``scene`` back)."""
    from acoustisim import materials

    if "elastic" not in getattr(materials, "REFLECTION_MODELS", ()):
        return scene  # a tree from before the elastic model: every solid reflects as a fluid

    def fluid(material: Any) -> Any:
        return dataclasses.replace(material, model="fluid") if material.model == "elastic" else material

    objects = tuple(dataclasses.replace(obj, material=fluid(obj.material)) for obj in scene.objects)
    tank = scene.tank
    if tank is not None:
        # the tank's materials are looked up by name among its own materials first
        own = tuple(fluid(tank.material(which)) for which in ("wall_material", "floor_material", "surface_material"))
        tank = dataclasses.replace(tank, materials=own + tuple(m for m in tank.materials if m.name not in
                                                               {o.name for o in own}))
    return dataclasses.replace(scene, objects=objects, tank=tank)


def with_record_length(scene: Any, record_length_s: float) -> Any:
    """``scene`` with its sonar's record ``record_length_s`` long."""
    return dataclasses.replace(scene, sonar=dataclasses.replace(scene.sonar, record_length_s=record_length_s))


def field_digests(rows: np.ndarray) -> dict[str, str]:
    """A digest of each field of structured ``rows`` (compare two trees' rows on their common fields)."""
    return {name: hashlib.sha1(np.ascontiguousarray(rows[name]).tobytes()).hexdigest()[:16]
            for name in rows.dtype.names}


def common_fields_verdict(before: dict[str, str], now: dict[str, str]) -> str:
    """Whether two :func:`field_digests` agree on every field both have, in words."""
    common = [name for name in before if name in now]
    differ = [name for name in common if before[name] != now[name]]
    if differ:
        return f"rows differ in {', '.join(differ)}"
    return f"rows byte-identical in the {len(common)} common fields"


def alternating_runs(script: str, trees: dict[str, str], arguments: list[str], rounds: int) -> dict[str, list[Any]]:
    """Run ``script`` with ``arguments`` once per tree per round, trees alternating, each
    subprocess importing its tree (:data:`TREE_VARIABLE`, ``PYTHONPATH``); the JSON object on the
    last line of each run's output, per tree name, in round order."""
    runs: dict[str, list[Any]] = {name: [] for name in trees}
    for _ in range(rounds):
        for name, root in trees.items():
            env = dict(os.environ, PYTHONPATH=root, **{TREE_VARIABLE: root})
            result = subprocess.run([sys.executable, script, *arguments], env=env, cwd=root, capture_output=True,
                                    text=True)
            if result.returncode:
                raise RuntimeError(f"{script} in {root} failed:\n{result.stderr[-3000:]}")
            runs[name].append(json.loads(result.stdout.strip().splitlines()[-1]))
    return runs


__all__ = ("NEW_KNOBS", "PRE_SESSION_RECORD_S", "TREE_VARIABLE", "alternating_runs", "common_fields_verdict",
           "field_digests", "fluid_reflection_scene", "solver_config", "tree_root", "with_record_length")
