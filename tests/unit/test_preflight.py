"""The pre-flight and the typed errors of the public Python API.

Every refusal is an InputError (InputTypeError for a wrong type) whose one-line message names
the argument and the value; resource refusals state the estimate, the limit and how to raise it.
"""

from __future__ import annotations

import itertools
import subprocess
import sys
import tracemalloc
from dataclasses import replace

import numpy as np
import pytest

from acoustisim.errors import InputError, InputTypeError, ResourceLimitError
from acoustisim.medium import Medium
from acoustisim.preflight import check_sampling, preflight
from acoustisim.propagation import SolverConfig, solve
from acoustisim.resources import (
    ResourceLimits,
    chain_bound,
    current_limits,
    reflector_count,
    resource_limits,
)
from acoustisim.scene import Scene, Tank
from acoustisim.simulation import simulate
from acoustisim.sonar import SonarHead
from scenes.builtin import builtin_scene
from scenes.validation import overlapping_pairs


# ------------------------------------------------------------------------------ typed errors
@pytest.mark.parametrize("make, error, needles", [
    (lambda: Scene(objects=(1, 2)), InputTypeError, ("scene.objects[0] = 1", "SceneObject")),
    (lambda: Scene(tank="big"), InputTypeError, ("scene.tank = 'big'", "Tank")),
    (lambda: Scene(medium=None), InputTypeError, ("scene.medium = None",)),
    (lambda: SonarHead(record_length_s=1e6), InputError, ("sonar.record_length_s = 1000000.0", "3600")),
    (lambda: SonarHead(adc_bits=12.0), InputTypeError, ("sonar.adc_bits = 12.0", "integer")),
    (lambda: SonarHead(position_m="here"), InputTypeError, ("sonar.position_m = 'here'",)),
    (lambda: SonarHead(source_level_pa=1e300), InputError, ("sonar.source_level_pa = 1e+300",)),
    (lambda: Medium(temperature_c="hot"), InputTypeError, ("medium.temperature_c = 'hot'", "a number")),
    (lambda: Medium(ph=1e300), InputError, ("medium.ph = 1e+300", "pH")),
    (lambda: Medium(depth_m=10**400), InputError, ("medium.depth_m", "too large")),
    (lambda: Tank(length_m=-1.0), InputError, ("tank.length_m = -1.0",)),
    (lambda: Tank(length_m=1e300), InputError, ("tank.length_m = 1e+300", "100000")),
    (lambda: Tank(wall_material="cheese"), InputError, ("tank.wall_material = 'cheese'",)),
    (lambda: Tank(floor_material=3), InputTypeError, ("tank.floor_material = 3",)),
])
def test_public_descriptors_raise_typed_one_line_errors(make, error, needles):
    with pytest.raises(error) as info:
        make()
    message = str(info.value)
    assert "\n" not in message
    for needle in needles:
        assert needle in message, message


def test_scenes_exports_load_scene_lazily():
    from scenes import load_scene

    assert load_scene("free-sphere").name == "free-sphere"
    code = "import sys, scenes; print('scenes.scene_file' in sys.modules, 'trimesh' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]  # `import scenes` stays light


@pytest.mark.parametrize("argument", [123, None, b"scene.toml", "", "a\0b"])
def test_load_scene_refuses_what_is_not_a_path(argument):
    from scenes import SceneFileError, load_scene

    with pytest.raises(SceneFileError, match="scene = "):
        load_scene(argument)


# ------------------------------------------------------------------------------ sampling
def test_sampling_names_the_key_at_fault():
    sonar = SonarHead()
    with pytest.raises(InputError, match=r"^sonar\.centre_frequency_hz = 1e\+07: at or above half"):
        check_sampling(replace(sonar, centre_frequency_hz=1e7))
    with pytest.raises(InputError, match=r"^sonar\.sample_rate_hz = 2e\+07 must exceed.*pulse_duration_s = 1e-08"):
        check_sampling(replace(sonar, pulse_duration_s=1e-8))
    with pytest.raises(InputError, match=r"^src: sonar\.record_length_s = 5e-06: shorter than the transmitted pulse"):
        check_sampling(replace(sonar, record_length_s=5e-6), source="src")
    check_sampling(sonar)  # the thesis sonar passes


# ------------------------------------------------------------------------------ limits
def test_limits_come_from_the_context_then_the_environment(monkeypatch):
    monkeypatch.setenv("ACOUSTISIM_MAX_MEMORY_GB", "16")
    assert current_limits().max_memory_gb == 16.0
    with resource_limits(ResourceLimits(max_memory_gb=1.5)):
        assert current_limits().max_memory_gb == 1.5
    assert current_limits().max_memory_gb == 16.0
    monkeypatch.setenv("ACOUSTISIM_MAX_TRIANGLES", "lots")
    with pytest.raises(InputError, match="ACOUSTISIM_MAX_TRIANGLES = 'lots': expected a number"):
        current_limits()
    monkeypatch.setenv("ACOUSTISIM_MAX_TRIANGLES", "-5")
    with pytest.raises(InputError, match="ACOUSTISIM_MAX_TRIANGLES = '-5': must be a finite number > 0"):
        current_limits()
    with pytest.raises(InputError, match="limits.max_rays"):
        ResourceLimits(max_rays=float("nan"))


def test_memory_refusal_states_estimate_limit_and_the_way_to_raise_it():
    scene = builtin_scene("thesis-tank")
    with pytest.raises(ResourceLimitError) as info:
        preflight(scene, n_pings=2000, limits=ResourceLimits(), source="tank.toml", pings_key="--pings")
    message = str(info.value)
    n = scene.sonar.n_samples  # 400,000 samples: the thesis tank's 20 ms record at 20 MHz
    assert message.startswith("tank.toml: needs about ")
    for needle in ("--pings = 2000", f"{n:,} samples", "limit of 4 GiB", "--max-memory-gb",
                   "ACOUSTISIM_MAX_MEMORY_GB"):
        assert needle in message, message
    estimate = preflight(scene, n_pings=2000, limits=ResourceLimits(max_memory_gb=64))
    assert estimate.recording_bytes == 2000 * 3 * n * 10  # int16 codes and float64 volts per sample
    # at least the recording and its synthesis (20 B per sample), below the raised limit
    assert 2000 * 3 * n * 20 / 2**30 < estimate.memory_bytes / 2**30 < 64


def test_every_limit_refuses_before_any_work():
    scene = builtin_scene("thesis-tank")
    cases = [
        (ResourceLimits(max_objects=3), "5 objects, more than the limit of 3"),
        (ResourceLimits(max_triangles=100), "424 triangles, more than the limit of 100"),
        (ResourceLimits(max_rays=1000), "20,000 ray-bounces, more than the limit of 1,000"),
        (ResourceLimits(max_chains=100), "17 reflecting surfaces, max_order = 3"),
    ]
    for limits, needle in cases:
        with pytest.raises(ResourceLimitError, match=needle):
            preflight(scene, limits=limits)
        with resource_limits(limits), pytest.raises(ResourceLimitError, match=needle):
            solve(scene)  # the solver's own pre-flight, with the limits in force


def test_simulate_checks_its_arguments_first():
    scene = builtin_scene("free-sphere")
    with pytest.raises(ResourceLimitError, match="n_pings = 1000000000"):
        simulate(scene, n_pings=10**9)
    with pytest.raises(InputTypeError, match="n_pings = 1.5"):
        simulate(scene, n_pings=1.5)
    with pytest.raises(InputError, match=r"snr_db = 1e\+300"):
        simulate(scene, snr_db=1e300)
    with pytest.raises(InputTypeError, match="scene = 'thesis-tank'"):
        simulate("thesis-tank")
    with pytest.raises(InputTypeError, match="solver_config = "):
        solve(scene, config={"max_order": 2})


def test_memory_model_is_within_a_factor_two_of_the_measured_peak():
    """The estimate is what a refusal quotes, so it must be close to the truth: tracemalloc's
    peak (numpy reports its buffers to it) while simulating pings of a traced scene."""
    base = builtin_scene("free-sphere")
    scene = replace(base, sonar=replace(base.sonar, record_length_s=0.003))
    paths = solve(scene, config=SolverConfig(mechanisms=("direct", "specular")))
    simulate(scene, paths=paths)  # compile and warm caches outside the measurement
    for n_pings in (1, 6):
        estimate = preflight(scene, n_pings=n_pings, solving=False).memory_bytes
        tracemalloc.start()
        try:
            simulate(scene, paths=paths, n_pings=n_pings)
            _, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
        assert 0.5 < peak / estimate < 2.0, (n_pings, peak, estimate)


def test_reflector_sequences_bound_counts_sequences_without_repeats():
    for m, order in ((2, 3), (4, 3), (5, 2), (3, 4)):
        brute = sum(1 for k in range(1, order + 1) for seq in itertools.product(range(m), repeat=k)
                    if all(a != b for a, b in zip(seq, seq[1:])))
        assert chain_bound(m, order) == brute
    # 6 tank planes, the prism's 5 faces, 3 posts (caps on floor and surface: sides only), the
    # pipe's side and two caps
    assert reflector_count(builtin_scene("thesis-tank")) == 6 + 5 + 3 + 3


def test_overlapping_pairs_match_brute_force():
    rng = np.random.default_rng(7)
    for n in (0, 1, 2, 40, 200):
        lo = rng.uniform(0.0, 1.0, (n, 3))
        boxes = np.stack([lo, lo + rng.uniform(0.0, 0.25, (n, 3))], axis=1)
        brute = [(i, j) for i in range(n) for j in range(i + 1, n)
                 if np.all(boxes[i, 0] <= boxes[j, 1]) and np.all(boxes[j, 0] <= boxes[i, 1])]
        assert [tuple(p) for p in overlapping_pairs(boxes)] == brute
