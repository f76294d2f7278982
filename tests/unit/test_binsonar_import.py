"""``import binsonar`` stays light and never loads the simulator (checked in a fresh interpreter)."""

from __future__ import annotations

import json
import subprocess
import sys

# numba too: the detection kernels (local matched, threshold, the matched filter's overlap-save
# gather) import it when a method runs, never at import.
HEAVY = ("acoustisim", "scenes", "scipy", "h5py", "pywt", "matplotlib", "numba")


def _loaded_after(statement: str) -> list[str]:
    code = (
        f"import sys, json; {statement}; "
        f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}})))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def test_import_binsonar_loads_no_heavy_module():
    loaded = _loaded_after("import binsonar")
    assert not [m for m in HEAVY if m in loaded], loaded


def test_import_detection_and_recording_load_no_heavy_module():
    # The detection API and the recording format import numpy only; each method imports scipy
    # or PyWavelets when it runs.
    loaded = _loaded_after("import binsonar.detection, binsonar.recording, binsonar.preprocess, binsonar.bounds")
    assert not [m for m in HEAVY if m in loaded], loaded


def test_running_every_detector_never_loads_the_simulator():
    statement = (
        "import numpy as np; from binsonar.detection import detect, METHODS; "
        "t = (np.arange(201) - 100) / 20e6; "
        "s = np.exp(-13.8 * t**2 / 25e-12) * np.cos(2 * np.pi * 5e5 * t); "
        "x = np.zeros((2, 3, 4096)); x[:, :, 1000:1201] = s; "
        "x += np.random.default_rng(0).standard_normal(x.shape) * 0.01; "
        "[detect(x, m, sample_rate_hz=20e6, template=s) for m in METHODS]"
    )
    loaded = _loaded_after(statement)
    assert "acoustisim" not in loaded and "scenes" not in loaded and "matplotlib" not in loaded


def test_no_module_level_mutable_state():
    # Team standard: no module-level mutable state. Every binsonar module's public and private
    # globals (dunders aside) must be immutable: no list, dict, set or bytearray, and numpy
    # arrays read-only. Imports every submodule (scipy and friends too): run in-process.
    import importlib
    import pkgutil

    import numpy as np

    import binsonar

    offenders = []
    for info in pkgutil.walk_packages(binsonar.__path__, "binsonar."):
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if name.startswith("__") and name != "__all__":
                continue
            if isinstance(value, (list, dict, set, bytearray)) or (
                isinstance(value, np.ndarray) and value.flags.writeable
            ):
                offenders.append(f"{info.name}.{name}")
    assert not offenders, offenders
    for package in ("binsonar.cli", "binsonar.detection", "binsonar.localization"):
        exported = importlib.import_module(package).__all__
        assert isinstance(exported, tuple) and all(isinstance(n, str) and n for n in exported), package
