"""Benchmark of the deterministic propagation solver (direct + specular to order 3 + edges).

Prints, for one pose of the thesis tank, medians over repeats against baselines measured in the
same run: wall and CPU time of direct + specular against one raw Embree occlusion query over as
many segments as the solver checks; then CPU-time medians of specular only, edges only and both,
each with the graded edge discretisation (the default, ``SolverConfig.edge_adaptive``) and with
the fine 1/16-period one (the same-run baseline of the edge work). Then it checks that a scene
of over a million triangles loads and solves.

Figures of the whole solve follow: the CPU-time cost of the amplitude floor (judged across
the pulse band, ``SolverConfig.amplitude_floor_db = -80``) against keep-all (``None``) on the
default configuration (with 20 000 diffuse rays); the floor alone
(:func:`~acoustisim.propagation.fast.floor.floor_mask`) on the keep-all rows against the same-run
baseline of the rule evaluated on every arrival
(:func:`~acoustisim.propagation.reference.floor.band_levels`); and the CPU time of
:func:`~acoustisim.propagation.fast.columns.complete_columns` on the diffuse rows of
``--columns-rays`` rays (about 2.1 rows per ray), with ``--columns-before FILE`` (another
``columns.py`` defining ``complete_columns(rows, context)``, e.g. the reference engine's
``acoustisim/propagation/reference/columns.py``) timed interleaved with it as the same-run
baseline.

The default deterministic solve (direct + specular + edges, amplitude floor on) is timed with
and without the elastic-echo step (``SolverConfig.elastic_echoes``), interleaved.

The reference engine's direct + specular solve of the same pose (``SolverConfig(backend="reference")``),
and its whole default solve (every mechanism, the diffuse rays included), are timed against the
fast engine's in the same run.

The default configuration (every mechanism on) is broken down, interleaved: the default
deterministic solve; without each new mechanism the tree knows in turn (:data:`same_work.NEW_KNOBS`:
the chains through two curved objects, the elastic-echo step, the shadows); without all of them;
and without all of them on the scene with the ``fluid`` reflection model (the like-for-like
set-up below); with the goal of 50 ms CPU. Then the CPU time of each step of the default solve
(direct, specular, edges, shadow step, assembly and the floor mask within it, roughness, elastic
step), each step's function wrapped where the solve looks it up.

The per-pose figures include ``specular_rows`` alone (the specular solve without the solver's
direct rows, checks and assembly), and the deterministic paths with the amplitude floor on
(``both floored``: the default -80 dB). ``--before-tree DIR`` (an older checkout's root, holding its
``acoustisim`` and ``scenes``, e.g. ``git archive b6e1281 acoustisim scenes | tar -x -C
/tmp/before``) adds a same-run A/B of the per-pose figures: this script is run on that tree and
on this one in alternating subprocesses (``--rounds`` each, ``PYTHONPATH`` set to the tree), and
the medians over the rounds and their ratios are printed, with whether the two trees' rows
agree byte for byte in the fields both have. ``--like-for-like`` makes the per-pose figures
(and the A/B) compute what an older tree computes (:mod:`same_work`): the chains through two
curved objects and the elastic echoes off, the built-in solids on the ``fluid`` reflection
model. ``--deterministic-only`` prints only the per-pose figures (what the A/B runs), the default
configuration's breakdown and the reference engine's figure.

Run: ``python benchmarks/bench_propagation.py [--repeats N] [--skip-large] [--columns-before FILE]
[--before-tree DIR [--rounds R]] [--like-for-like] [--deterministic-only]``
(``--repeats 21 --skip-large``: about 30 s on a quiet 2-core machine; the A/B adds about 10 s
per round and tree).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from same_work import (NEW_KNOBS, alternating_runs, common_fields_verdict, field_digests, fluid_reflection_scene,
                       solver_config, tree_root)

_FIGURES = {
    "specular_rows": "specular_rows alone (no solve overhead)",
    "specular_rows one curved": "specular_rows alone, max_curved_per_path = 1 (no chains between two objects)",
    "specular": "specular only (direct + specular)",
    "edges": "edges only graded edges",
    "both": "both (direct + specular + edges) graded edges",
    "both floored": "both (direct + specular + edges), amplitude floor -80 dB",
}
"""The per-pose CPU-time medians compared by ``--before-tree`` (key: label)."""


def _median_time(function, repeats: int, clock=time.perf_counter) -> float:
    times = []
    for _ in range(repeats):
        start = clock()
        function()
        times.append(clock() - start)
    return float(np.median(times))


def _specular_rows_function(max_curved_per_path: int | None = None):
    """``specular_rows(context, prepared, max_order)`` of the tree on the path: this tree's fast
    engine, or the top-level module of a tree from before the engines were split (the
    ``--before-tree`` side of the A/B). Trees that know ``max_curved_per_path`` get the given
    value (None: the ``SolverConfig`` default); for trees that do not, a value other than None
    gives None (no such figure)."""
    import importlib
    import inspect

    from acoustisim.propagation import SolverConfig

    for module in ("acoustisim.propagation.fast.specular", "acoustisim.propagation.specular"):
        try:
            specular_rows = importlib.import_module(module).specular_rows
        except ModuleNotFoundError:
            continue
        if "max_curved_per_path" in inspect.signature(specular_rows).parameters:
            knob = SolverConfig().max_curved_per_path if max_curved_per_path is None else max_curved_per_path
            return lambda context, prepared, max_order: specular_rows(context, prepared, max_order, knob)
        return specular_rows if max_curved_per_path is None else None
    raise ModuleNotFoundError("no specular_rows in this tree")


def _per_pose(prepared, repeats: int, fine: bool, like_for_like: bool = False
              ) -> dict[str, tuple[float, int, dict[str, str]]]:
    """CPU-time medians (s), row counts and the rows' :func:`~same_work.field_digests` per pose
    of the deterministic solves (``_FIGURES``; with ``fine``, also the edge solves with the fine
    1/16-period discretisation, the same-run baseline of the graded one); ``like_for_like``: the
    new mechanisms off (:func:`~same_work.solver_config`). Each repeat times every case once, in
    turn (round-robin), so that all cases see the same load of a shared machine."""
    from acoustisim.propagation import solve
    from acoustisim.propagation.context import SolveContext

    # like for like: one curved reflection per path (an older tree knows no other: its own function)
    specular_rows = (_specular_rows_function(1) if like_for_like else None) or _specular_rows_function()
    scene = prepared.scene
    context = SolveContext.build(scene, scene.sonar, prepared.raycaster)
    calls = {"specular_rows": lambda: np.asarray(specular_rows(context, prepared, 3))}
    one_curved = _specular_rows_function(1)
    if one_curved is not None and not like_for_like:
        calls["specular_rows one curved"] = lambda: np.asarray(one_curved(context, prepared, 3))
    cases = [("specular", ("direct", "specular"), True, None), ("edges", ("edge",), True, None),
             ("both", ("direct", "specular", "edge"), True, None),
             ("both floored", ("direct", "specular", "edge"), True, -80.0)]
    if fine:
        cases += [("edges fine", ("edge",), False, None), ("both fine", ("direct", "specular", "edge"), False, None)]
    for key, mechanisms, adaptive, floor_db in cases:
        config = solver_config(like_for_like, max_order=3, mechanisms=mechanisms, amplitude_floor_db=floor_db,
                               edge_adaptive=adaptive)
        calls[key] = lambda config=config: solve(prepared, config=config).rows
    first = {key: call() for key, call in calls.items()}  # also the warm-up
    samples: dict[str, list[float]] = {key: [] for key in calls}
    for _ in range(repeats):
        for key, call in calls.items():
            start = time.process_time()
            call()
            samples[key].append(time.process_time() - start)
    return {key: (float(np.median(samples[key])), int(rows.size), field_digests(rows)) for key, rows in first.items()}


def _print_per_pose(prepared, repeats: int, fine: bool, like_for_like: bool) -> None:
    labels = dict(_FIGURES, **{"edges fine": "edges only fine edges (1/16 period)",
                               "both fine": "both (direct + specular + edges) fine edges (1/16 period)"})
    setup = " like for like (new mechanisms off, fluid reflection)" if like_for_like else ""
    print(f"  CPU-time medians per pose over {repeats}{setup} (goal < 20 ms for direct + specular + edges):")
    for key, (cpu, n_rows, _) in _per_pose(prepared, repeats, fine, like_for_like).items():
        print(f"    {labels[key]}: {cpu * 1e3:.2f} ms, {n_rows} rows")


def _default_breakdown(prepared, repeats: int) -> None:
    """CPU-time medians of the default deterministic solve (direct + specular + edges, floor on),
    interleaved with it without each new mechanism the tree knows (:data:`~same_work.NEW_KNOBS`:
    the elastic-echo step, the chains through two curved objects, the shadows), without all of
    them, and without all of them on the ``fluid`` reflection model (the like-for-like set-up;
    goal: < 50 ms with every mechanism on)."""
    from dataclasses import fields, replace

    from acoustisim.propagation import SolverConfig, prepare, solve

    default = SolverConfig(mechanisms=("direct", "specular", "edge"))
    known = {item.name for item in fields(SolverConfig)}
    fluid = prepare(fluid_reflection_scene(prepared.scene))
    off = {name: value for name, value in NEW_KNOBS if name in known and getattr(default, name) != value}
    cases = {"all on (default)": (prepared, default)}
    cases.update({f"without {name} (= {value!r})": (prepared, replace(default, **{name: value}))
                  for name, value in off.items()})
    cases["all new mechanisms off"] = (prepared, replace(default, **off))
    cases["all new mechanisms off, fluid reflection (like for like)"] = (fluid, replace(default, **off))
    samples: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(repeats):
        for name, (scene, config) in cases.items():
            start = time.process_time()
            solve(scene, config=config)
            samples[name].append(time.process_time() - start)
    cpu = {name: float(np.median(values)) for name, values in samples.items()}
    rows = {name: len(solve(scene, config=config)) for name, (scene, config) in cases.items()}
    print(f"  deterministic paths, default settings (floor -80 dB), CPU-time medians over {repeats}, interleaved "
          "(goal < 50 ms with every mechanism on):")
    base = cpu["all on (default)"]
    for name, value in cpu.items():
        print(f"    {name}: {value * 1e3:.2f} ms, {rows[name]} rows; all on minus this {(base - value) * 1e3:.2f} ms")
    print(f"    all on: {base * 1e3:.2f} ms = {base / 0.050:.2f} of the 50 ms budget")


_STEPS = (
    ("direct", "acoustisim.propagation.fast", "FastEngine", "direct_rows"),
    ("specular", "acoustisim.propagation.fast", "FastEngine", "specular_rows"),
    ("edges", "acoustisim.propagation.fast", "FastEngine", "edge_rows"),
    ("shadow step", "acoustisim.propagation.solver", None, "shadow_rows"),
    ("assembly (with the floor mask)", "acoustisim.propagation.fast", "FastEngine", "assemble_rows"),
    ("floor mask", "acoustisim.propagation.fast.assemble", None, "floor_mask"),
    ("roughness", "acoustisim.propagation.solver", None, "apply_coherent_roughness"),
    ("elastic step", "acoustisim.propagation.elastic_echoes", None, "attach_elastic_echoes"),
)
"""The steps of a fast solve timed by :func:`_step_breakdown`: (label, module, class or None,
function), each the name the solve calls it by (a tree without it has no such step)."""


def _step_breakdown(prepared, repeats: int) -> None:
    """CPU-time medians per solve of each step of the default deterministic solve (direct +
    specular + edges, every mechanism on, floor -80 dB): :data:`_STEPS` timed by wrapping each
    function where the solve looks it up, restored afterwards."""
    import importlib

    from acoustisim.propagation import SolverConfig, solve

    config = SolverConfig(mechanisms=("direct", "specular", "edge"))
    spent: dict[str, float] = {}
    restore = []

    def timed(label, function):
        def call(*args, **kwargs):
            start = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                spent[label] = spent.get(label, 0.0) + time.process_time() - start
        return call

    for label, module_name, class_name, name in _STEPS:
        try:
            owner = importlib.import_module(module_name)
        except ModuleNotFoundError:
            continue
        owner = getattr(owner, class_name, None) if class_name else owner
        if owner is None or not hasattr(owner, name):
            continue
        original = owner.__dict__[name] if isinstance(owner, type) else getattr(owner, name)
        restore.append((owner, name, original))
        setattr(owner, name, timed(label, original))
    samples: dict[str, list[float]] = {}
    try:
        solve(prepared, config=config)
        for _ in range(repeats):
            spent.clear()
            start = time.process_time()
            solve(prepared, config=config)
            spent["total"] = time.process_time() - start
            for label, value in spent.items():
                samples.setdefault(label, []).append(value)
    finally:
        for owner, name, original in restore:
            setattr(owner, name, original)
    cpu = {label: float(np.median(values)) for label, values in samples.items()}
    print(f"  default deterministic solve (every mechanism on, floor -80 dB), CPU-time medians per step over "
          f"{repeats} solves:")
    for label, *_ in _STEPS:
        if label in cpu:
            print(f"    {label}: {cpu[label] * 1e3:.2f} ms")
    named = sum(value for label, value in cpu.items() if label not in ("total", "floor mask"))
    print(f"    the rest (checks, context, Paths): {(cpu['total'] - named) * 1e3:.2f} ms; "
          f"total {cpu['total'] * 1e3:.2f} ms")


def _engines_interleaved(prepared, fast, repeats: int) -> tuple[float, float, int, int]:
    """CPU-time medians (s) of ``fast`` and of it on the reference engine, timed in turn within
    each repeat, and the row counts of each."""
    from dataclasses import replace

    from acoustisim.propagation import solve

    configs = {"fast": fast, "reference": replace(fast, backend="reference")}
    n_rows = {key: len(solve(prepared, config=config)) for key, config in configs.items()}  # also the warm-up
    cpu: dict[str, list[float]] = {key: [] for key in configs}
    for _ in range(repeats):
        for key, config in configs.items():
            start = time.process_time()
            solve(prepared, config=config)
            cpu[key].append(time.process_time() - start)
    return float(np.median(cpu["fast"])), float(np.median(cpu["reference"])), n_rows["fast"], n_rows["reference"]


def _reference_engine(prepared, repeats: int) -> None:
    """CPU-time medians of direct + specular (order 3) on the reference and fast engines, interleaved
    (without the elastic-echo step, the same code after either engine); then of the default solve
    (every mechanism) on each."""
    from acoustisim.propagation import SolverConfig

    fast = SolverConfig(max_order=3, mechanisms=("direct", "specular"), amplitude_floor_db=None, elastic_echoes=False)
    fast_s, reference_s, fast_rows, reference_rows = _engines_interleaved(prepared, fast, repeats)
    print(f"  direct + specular (order 3, no elastic step), CPU medians over {repeats}: reference engine "
          f"{reference_s * 1e3:.1f} ms ({reference_rows} rows), fast engine {fast_s * 1e3:.2f} ms ({fast_rows} rows); "
          f"reference / fast = {reference_s / fast_s:.1f}")
    # the whole default solve (every mechanism, diffuse rays included) on each engine
    default = SolverConfig()
    fast_s, reference_s, fast_rows, reference_rows = _engines_interleaved(prepared, default, repeats)
    print(f"  default solve (SolverConfig(), {default.diffuse_rays} diffuse rays), CPU medians over {repeats}: "
          f"reference engine {reference_s * 1e3:.0f} ms ({reference_rows} rows), fast engine {fast_s * 1e3:.1f} ms "
          f"({fast_rows} rows); reference / fast = {reference_s / fast_s:.1f}")


def _before_and_after(args) -> None:
    """The per-pose figures of ``args.before_tree`` and of this tree (:func:`~same_work.tree_root`),
    in alternating subprocesses."""
    trees = {"before": str(Path(args.before_tree).resolve()), "now": str(tree_root(__file__))}
    arguments = ["--json", "--repeats", str(args.repeats)] + (["--like-for-like"] if args.like_for_like else [])
    runs = alternating_runs(__file__, trees, arguments, args.rounds)
    setup = ", like for like" if args.like_for_like else ""
    print(f"  A/B against {trees['before']}{setup}: per-pose CPU medians, median over {args.rounds} alternating "
          f"subprocess rounds of {max(3, args.repeats)} repeats each:")
    for key, label in _FIGURES.items():
        if key not in runs["now"][0]:
            continue
        now = float(np.median([run[key][0] for run in runs["now"]]))
        if key not in runs["before"][0]:
            print(f"    {label}: now {now * 1e3:.2f} ms ({runs['now'][0][key][1]} rows; not in the older tree)")
            continue
        before = float(np.median([run[key][0] for run in runs["before"]]))
        # each round's now / before (the two subprocesses ran one after the other)
        paired = sorted(n[key][0] / b[key][0] for b, n in zip(runs["before"], runs["now"]))
        rows = (runs["before"][0][key][1], runs["now"][0][key][1])
        print(f"    {label}: before {before * 1e3:.2f} ms, now {now * 1e3:.2f} ms, now / before = "
              f"{now / before:.2f} (per round: median {np.median(paired):.2f}, {paired[0]:.2f} to {paired[-1]:.2f}; "
              f"rows {rows[0]} / {rows[1]}; "
              f"{common_fields_verdict(runs['before'][0][key][2], runs['now'][0][key][2])})")


def _floor_and_columns(prepared, args) -> None:
    """The amplitude floor's cost in a full solve, and complete_columns on many diffuse rows."""
    import importlib.util

    from acoustisim.propagation import SolverConfig, solve
    from acoustisim.propagation.context import SolveContext
    from acoustisim.propagation.engine import engine_for
    from acoustisim.propagation.fast.columns import complete_columns
    from acoustisim.propagation.fast.floor import floor_mask
    from acoustisim.propagation.reference.floor import band_levels, floor_frequencies

    repeats = max(3, args.repeats)
    floored, keep_all = SolverConfig(), SolverConfig(amplitude_floor_db=None)
    n_floored, n_all = len(solve(prepared, config=floored)), len(solve(prepared, config=keep_all))
    cpu = {"floor": [], "keep": []}
    for _ in range(repeats):  # alternating, so both see the same load
        for key, config in (("floor", floored), ("keep", keep_all)):
            start = time.process_time()
            solve(prepared, config=config)
            cpu[key].append(time.process_time() - start)
    floor_s, keep_s = float(np.median(cpu["floor"])), float(np.median(cpu["keep"]))
    print(f"  full default solve ({floored.diffuse_rays} diffuse rays), CPU medians over {repeats}: "
          f"floor -80 dB across the band {floor_s * 1e3:.1f} ms ({n_floored} rows kept), keep-all "
          f"{keep_s * 1e3:.1f} ms ({n_all} rows); floor cost {(floor_s - keep_s) * 1e3:.1f} ms")

    scene = prepared.scene
    context = SolveContext.build(scene, scene.sonar, prepared.raycaster)
    # the floor alone on the keep-all rows, against the rule evaluated on every arrival
    everything = solve(prepared, config=keep_all).rows.copy()
    frequencies, weights = floor_frequencies(context, None)
    keys = everything["path_id"].astype(np.int64) * 8 + everything["channel"]
    _, group = np.unique(keys, return_inverse=True)
    group = group.ravel()
    mask = floor_mask(everything, floored.amplitude_floor_db, context)
    cpu = {"bounds": [], "rule": []}
    for _ in range(repeats):
        start = time.process_time()
        floor_mask(everything, floored.amplitude_floor_db, context)
        cpu["bounds"].append(time.process_time() - start)
        start = time.process_time()
        band_levels(everything, group, int(group.max()) + 1, context, frequencies, weights)
        cpu["rule"].append(time.process_time() - start)
    bounds_s, rule_s = float(np.median(cpu["bounds"])), float(np.median(cpu["rule"]))
    print(f"  floor_mask alone on those {everything.size} rows ({int(mask.sum())} kept): CPU median "
          f"{bounds_s * 1e3:.1f} ms; the rule's band levels of every arrival (numpy band_levels, the same-run "
          f"baseline) {rule_s * 1e3:.1f} ms; ratio {rule_s / bounds_s:.1f}")
    diffuse = SolverConfig(diffuse_rays=args.columns_rays)
    rows = engine_for(diffuse).diffuse_rows(context, diffuse, prepared)
    functions = {"compiled": complete_columns}
    if args.columns_before:
        spec = importlib.util.spec_from_file_location("columns_before", args.columns_before)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        functions["before"] = module.complete_columns
    for function in functions.values():  # compile / warm up
        function(rows.copy(), context)
    cpu = {key: [] for key in functions}
    for _ in range(repeats):
        for key, function in functions.items():
            work = rows.copy()
            start = time.process_time()
            function(work, context)
            cpu[key].append(time.process_time() - start)
    now = float(np.median(cpu["compiled"]))
    line = (f"  complete_columns on {rows.size} diffuse rows ({args.columns_rays} rays): CPU median "
            f"{now * 1e3:.1f} ms")
    if "before" in cpu:
        before = float(np.median(cpu["before"]))
        line += f"; before ({args.columns_before}) {before * 1e3:.1f} ms; before / now = {before / now:.2f}"
    print(line)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=21)
    parser.add_argument("--skip-large", action="store_true", help="skip the 1.3-million-triangle scene")
    parser.add_argument("--large-user-mesh", action="store_true",
                        help="also a 1.3-million-triangle user mesh without primitive (smooth-mesh tracer; ~1 min)")
    parser.add_argument("--columns-rays", type=int, default=200_000)
    parser.add_argument("--columns-before", default=None, help="an older columns.py to time against")
    parser.add_argument("--before-tree", default=None,
                        help="an older checkout's root (acoustisim and scenes): same-run A/B of the per-pose figures")
    parser.add_argument("--rounds", type=int, default=3, help="alternating subprocess rounds of --before-tree")
    parser.add_argument("--deterministic-only", action="store_true", help="only the per-pose figures (and the A/B)")
    parser.add_argument("--like-for-like", action="store_true",
                        help="per-pose figures without the newer mechanisms, on the fluid reflection model")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    sys.path.insert(0, str(tree_root(__file__)))

    import trimesh

    from acoustisim.geometry import SpherePrimitive
    from acoustisim.materials import get_material
    from acoustisim.propagation import SolverConfig, prepare, solve
    from acoustisim.scene import SceneObject
    from scenes.builtin import builtin_scene

    scene = builtin_scene("thesis-tank")
    start = time.perf_counter()
    prepared = prepare(scene)
    prepare_s = time.perf_counter() - start
    per_pose = prepare(fluid_reflection_scene(scene)) if args.like_for_like else prepared
    if args.json:  # one side of the --before-tree A/B: the per-pose figures, as JSON
        print(json.dumps(_per_pose(per_pose, max(3, args.repeats), fine=False, like_for_like=args.like_for_like)))
        return
    if args.deterministic_only:
        _print_per_pose(per_pose, max(3, args.repeats), False, args.like_for_like)
        _default_breakdown(prepared, max(3, args.repeats))
        _step_breakdown(prepared, max(3, args.repeats))
        _reference_engine(prepared, max(3, args.repeats // 3))
        if args.before_tree:
            _before_and_after(args)
        return
    specular = SolverConfig(max_order=3, mechanisms=("direct", "specular"), amplitude_floor_db=None)
    paths = solve(prepared, config=specular)
    t_specular = _median_time(lambda: solve(prepared, config=specular), args.repeats)
    cpu_specular = _median_time(lambda: solve(prepared, config=specular), args.repeats, time.process_time)

    # baseline: one raw Embree occlusion call over the same number of random segments in the tank
    rng = np.random.default_rng(0)
    n_legs = int(np.sum(paths["order"] + 1))
    a = rng.uniform((0.1, 0.1, 0.1), (8.9, 2.9, 0.9), (n_legs, 3))
    b = rng.uniform((0.1, 0.1, 0.1), (8.9, 2.9, 0.9), (n_legs, 3))
    t_raw = _median_time(lambda: prepared.raycaster.occluded(a, b), args.repeats)

    print(f"thesis tank: {prepared.raycaster.triangle_count} triangles, {prepared.mirrors.count} planar mirrors, "
          f"{len(prepared.curved)} curved reflectors; prepare {prepare_s * 1e3:.1f} ms")
    print(f"  solve direct+specular (order 3): median {t_specular * 1e3:.2f} ms over {args.repeats}, "
          f"{len(paths)} paths; process CPU time median {cpu_specular * 1e3:.2f} ms (less sensitive to other load)")
    print(f"  baseline raw Embree occlusion of {n_legs} segments: median {t_raw * 1e3:.3f} ms "
          f"(solve / baseline = {t_specular / t_raw:.1f})")
    _print_per_pose(per_pose, max(3, args.repeats), True, args.like_for_like)
    _default_breakdown(prepared, max(3, args.repeats))
    _step_breakdown(prepared, max(3, args.repeats))
    _reference_engine(prepared, max(3, args.repeats // 3))
    if args.before_tree:
        _before_and_after(args)

    _floor_and_columns(prepared, args)

    if args.skip_large:
        return
    # off the axis (in sight of the sonar past the targets), 20 x 4^8 triangles
    centre = (5.5, 2.4, 0.5)
    mesh = trimesh.creation.icosphere(subdivisions=8, radius=0.3)
    mesh.apply_translation(centre)
    big = SceneObject("big-ball", "sphere", get_material("steel"), mesh, SpherePrimitive(centre, 0.3))
    from dataclasses import replace

    large = replace(scene, objects=scene.objects + (big,))
    start = time.perf_counter()
    prepared_large = prepare(large)
    load_s = time.perf_counter() - start
    n_big = sum("big-ball" in label for label in solve(prepared_large, config=specular).object_labels())
    t_large = _median_time(lambda: solve(prepared_large, config=specular), 5)
    start = time.perf_counter()
    first = solve(large, config=specular)
    cold_s = time.perf_counter() - start
    print(f"large scene (sphere primitive): {prepared_large.raycaster.triangle_count} triangles; prepare (checks + "
          f"Embree build) {load_s:.2f} s; solve on the prepared scene median {t_large * 1e3:.1f} ms; cold "
          f"solve(scene) {cold_s:.2f} s; {len(first)} paths, {n_big} touch the big sphere")
    if args.large_user_mesh:
        blob = SceneObject("blob", "mesh", get_material("steel"), mesh)
        user = replace(scene, objects=scene.objects + (blob,))
        start = time.perf_counter()
        prepared_user = prepare(user)
        load_s = time.perf_counter() - start
        t_user = _median_time(lambda: solve(prepared_user, config=specular), 3)
        n_blob = sum("blob" in label for label in solve(prepared_user, config=specular).object_labels())
        print(f"large scene (user mesh, no primitive): {prepared_user.raycaster.triangle_count} triangles; prepare "
              f"{load_s:.2f} s; solve median {t_user * 1e3:.1f} ms; {n_blob} paths touch the mesh")


if __name__ == "__main__":
    main()
