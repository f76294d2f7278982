"""Property-based fuzzing of command-line arguments, and the inputs that could hang.

Argument lists for ``acoustisim scene validate/show``, ``simulate`` (a small free-field scene
with a 0.2 ms record, so a run that is accepted stays short), ``demo`` (one ping, 2 ms) and
``binsonar`` are drawn from hostile values (empty, negative, nan, inf, 1e300, huge integers,
text, option names where values belong) and run in this process: each must exit 0, or exit 2
with one line. The inputs that could hang or allocate without bound (a FIFO, ``/dev/zero``,
10^9 pings, a 1 TS/s digitiser) run in a child process under an address-space limit and a
timeout.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

from scenes.builtin import builtin_scene
from scenes.scene_file import scene_to_toml
from support.cli_contract import check_contract, run_guarded, run_in_process

DATA = Path(__file__).resolve().parents[2] / "scenes" / "data"

HOSTILE_TEXT = ("", " ", "-1", "0", "1", "2", "3", "nan", "inf", "-inf", "1e300", "-1e300", "1e-300", "1e309",
                "abc", "9" * 30, "9" * 5000, "0x10", "1_000", "--pings", "-o", "\u00e9", "thesis-tank", "free-sphere")
SIMULATE_OPTIONS = ("--seed", "--snr-db", "--snr-echo", "--pings", "--max-order", "--backend", "--max-memory-gb",
                    "--max-triangles", "--max-rays", "--max-chains", "--max-objects")
SIMULATE_FLAGS = ("--keep-all-paths", "--average", "--json", "--bogus")
DEMO_OPTIONS = ("--seed", "--method", "--pings", "--scene", "--record-length", "--backend", "--max-memory-gb")

FAST = settings(derandomize=True, database=None, deadline=None, max_examples=20,
                suppress_health_check=[HealthCheck.too_slow])
DEEP = settings(database=None, deadline=None, max_examples=300, suppress_health_check=[HealthCheck.too_slow])

values = st.one_of(st.sampled_from(HOSTILE_TEXT), st.text(max_size=12).filter(lambda t: "\0" not in t))


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("args")
    scene = builtin_scene("free-sphere")
    text = scene_to_toml(scene).replace("record_length_s = 0.0125", "record_length_s = 0.0002")
    assert "record_length_s = 0.0002" in text
    (folder / "tiny.toml").write_text(text)
    shutil.copy(DATA / "rock.stl", folder / "rock.stl")
    return folder


def _options(data: st.DataObject, names: tuple[str, ...], flags: tuple[str, ...] = ()) -> list[str]:
    argv: list[str] = []
    for _ in range(data.draw(st.integers(0, 3), label="options")):
        argv += [data.draw(st.sampled_from(names), label="option"), data.draw(values, label="value")]
    if flags and data.draw(st.booleans(), label="flag"):
        argv.append(data.draw(st.sampled_from(flags), label="flag name"))
    return argv


def _simulate(data: st.DataObject, workdir: Path) -> None:
    scene = data.draw(st.sampled_from([str(workdir / "tiny.toml"), "", "nowhere", str(workdir)]), label="scene")
    output = data.draw(st.sampled_from([str(workdir / "out.h5"), ""]), label="output")
    argv = ["simulate", scene, "-o", output, *_options(data, SIMULATE_OPTIONS, SIMULATE_FLAGS)]
    if data.draw(st.booleans(), label="shuffle"):
        argv = [argv[0], *data.draw(st.permutations(argv[1:]), label="order")]
    check_contract(run_in_process(argv, timeout_s=120.0))


def _scene_verbs(data: st.DataObject, workdir: Path) -> None:
    verb = data.draw(st.sampled_from(["validate", "show", "list", "frobnicate"]), label="verb")
    argv = ["scene", verb, *data.draw(st.lists(values, max_size=2), label="positionals"),
            *_options(data, ("--max-memory-gb", "--max-objects", "--max-triangles"), ("--json", "--bogus"))]
    check_contract(run_in_process(argv, timeout_s=60.0))


def _binsonar(data: st.DataObject, workdir: Path) -> None:
    verb = data.draw(st.sampled_from(["detect", "localize", "", "--help", "frobnicate"]), label="verb")
    argv = [verb] if verb else []
    argv += data.draw(st.lists(values, max_size=2), label="positionals")
    argv += _options(data, ("--method", "--json", "--ping", "--average", "--bogus"))
    run = run_in_process(argv, program="binsonar", timeout_s=60.0)
    check_contract(run)


@FAST
@given(data=st.data())
def test_simulate_arguments_keep_the_contract(data: st.DataObject, workdir: Path) -> None:
    _simulate(data, workdir)


@FAST
@given(data=st.data())
def test_scene_arguments_keep_the_contract(data: st.DataObject, workdir: Path) -> None:
    _scene_verbs(data, workdir)


@FAST
@given(data=st.data())
def test_binsonar_arguments_keep_the_contract(data: st.DataObject, workdir: Path) -> None:
    _binsonar(data, workdir)


@settings(derandomize=True, database=None, deadline=None, max_examples=3, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_demo_arguments_keep_the_contract(data: st.DataObject, workdir: Path) -> None:
    argv = ["demo", "--pings", "1", "--record-length", "0.002", "--out", str(workdir / "demo"),
            *_options(data, DEMO_OPTIONS)]
    check_contract(run_in_process(argv, timeout_s=120.0))


def test_option_errors_are_one_line_and_help_still_has_the_usage(capsys: pytest.CaptureFixture[str]) -> None:
    for program, argv in (("acoustisim", ["simulate"]), ("acoustisim", ["demo", "--record-length", "-1"]),
                          ("acoustisim", ["scene", "validate", "--bogus", "x"]), ("binsonar", ["--bogus"]),
                          ("binsonar", ["detect", "x.h5", "--frobnicate"])):
        run = run_in_process(argv, program=program)
        assert run.code == 2 and run.err.count("\n") == 1 and "usage:" not in run.err, run.err
        assert "--help" in run.err  # says where the usage is
    help_run = run_in_process(["simulate", "--help"])
    assert help_run.code == 0 and help_run.out.startswith("usage:") and "--max-memory-gb" in help_run.out


def _hostile_files(folder: Path) -> None:
    os.mkfifo(folder / "fifo.toml")
    os.mkfifo(folder / "fifo.stl")
    tiny = (folder / "tiny.toml").read_text()
    (folder / "fifo_mesh.toml").write_text(
        tiny + '\n[[objects]]\nkind = "mesh"\nname = "m"\npath = "fifo.stl"\nposition_m = [3.0, 0.0, 0.0]\n')
    (folder / "fast_adc.toml").write_text(tiny.replace("sample_rate_hz = 20000000.0", "sample_rate_hz = 1e12"))
    (folder / "long_record.toml").write_text(tiny.replace("record_length_s = 0.0002", "record_length_s = 1000.0"))
    (folder / "spec.toml").write_text("[dataset]\nn_samples = 2\nseed = 1\nn_pings = 1000000000\n")


def test_inputs_that_could_hang_finish_with_one_line(workdir: Path) -> None:
    """Each of these could hang (reading a FIFO or /dev/zero) or allocate without bound if a
    reader or the pre-flight did not stop it."""
    folder = workdir / "hostile"
    folder.mkdir()
    shutil.copy(workdir / "tiny.toml", folder / "tiny.toml")
    _hostile_files(folder)
    commands = [
        ("acoustisim", ["scene", "validate", "fifo.toml"]),
        ("acoustisim", ["scene", "show", "/dev/zero"]),
        ("acoustisim", ["scene", "validate", "fifo_mesh.toml"]),
        ("acoustisim", ["simulate", "tiny.toml", "-o", "out.h5", "--pings", "1000000000"]),
        ("acoustisim", ["simulate", "fast_adc.toml", "-o", "out.h5"]),
        ("acoustisim", ["simulate", "long_record.toml", "-o", "out.h5"]),
        ("acoustisim", ["dataset", "generate", "fifo.toml", "--out", "d.zarr"]),
        ("acoustisim", ["dataset", "generate", "spec.toml", "--out", "d.zarr", "--workers", "0"]),
        ("acoustisim", ["demo", "--pings", "1000000000", "--out", "demo"]),
    ]
    runs = run_guarded(commands, folder, timeout_s=180.0, memory_gb=6.0)
    for run in runs:
        check_contract(run)
        assert run.code == 2 and run.seconds < 30.0, (run.argv, run.seconds, run.err)
    assert not (folder / "out.h5").exists() and not (folder / "d.zarr").exists()


@pytest.mark.slow
def test_two_thousand_objects_validate_quickly(workdir: Path) -> None:
    folder = workdir / "many"
    folder.mkdir()
    posts = "".join(f'[[objects]]\nkind = "post"\nname = "p{i}"\ncenter_m = [{2.0 + 0.06 * (i // 40):.2f},'
                    f' {0.3 + 0.06 * (i % 40):.2f}]\nradius_m = 0.01\n' for i in range(2000))
    (folder / "many.toml").write_text((DATA / "example.toml").read_text().split("[[objects]]")[0] + posts)
    runs = run_guarded([("acoustisim", ["scene", "validate", "many.toml"]),
                        ("acoustisim", ["simulate", "many.toml", "-o", "many.h5", "--max-order", "4"])],
                       folder, timeout_s=300.0, memory_gb=8.0)
    for run in runs:
        check_contract(run)
    assert runs[0].code == 0 and runs[0].seconds < 60.0, runs[0]
    assert runs[1].code == 2 and "reflector sequences" in runs[1].err


@pytest.mark.slow
@seed(20260520)
@DEEP
@given(data=st.data())
def test_simulate_arguments_deep(data: st.DataObject, workdir: Path) -> None:
    _simulate(data, workdir)


@pytest.mark.slow
@seed(20260521)
@DEEP
@given(data=st.data())
def test_scene_and_binsonar_arguments_deep(data: st.DataObject, workdir: Path) -> None:
    _scene_verbs(data, workdir)
    _binsonar(data, workdir)
