"""Hostile recordings: refused with one line by ``read_recording``, ``binsonar detect`` and
``binsonar localize`` alike; nothing outside the file is read; nothing is read without bound."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from binsonar.cli.main import main
from binsonar.errors import InputTypeError
from binsonar.recording import ReadLimits, RecordingError, open_recording, read_recording
from support.hostile_recordings import damaged_file_cases, recording_cases, write_raw_recording

def _cases(folder: Path) -> list:
    return recording_cases(folder) + damaged_file_cases(folder)


CASE_NAMES = [case.name for case, _, _ in _cases(Path("."))]


@pytest.mark.parametrize("index", range(len(CASE_NAMES)), ids=CASE_NAMES)
def test_detect_and_localize_agree_on_every_case(tmp_path, capsys, index):
    case, builder, _ = _cases(tmp_path)[index]  # side files (linked, virtual sources) go to tmp_path
    file = tmp_path / "case.h5"
    builder(file)
    path = case.argv[0].replace("{file}", str(file)).replace("{dir}", str(tmp_path))
    codes = []
    for verb in ("detect", "localize"):
        code = main([verb, path])
        captured = capsys.readouterr()
        errors = [line for line in captured.err.splitlines() if not line.startswith("binsonar: warning:")]
        codes.append(code)
        if case.expect == "refuse":
            assert code == 2 and len(errors) == 1 and errors[0].startswith("binsonar: error:"), (verb, captured.err)
        else:
            assert code == 0 and not errors, (verb, captured.err)
    assert codes[0] == codes[1]


def test_external_storage_never_reads_the_other_file(tmp_path, monkeypatch):
    from support.hostile_recordings import _external_storage  # noqa: PLC2701 - the corpus's own builder

    path = write_raw_recording(tmp_path / "passwd.h5", edit=_external_storage)
    opened = []
    real_open = os.open

    def spy(name, *args, **kwargs):
        opened.append(os.fspath(name))
        return real_open(name, *args, **kwargs)

    monkeypatch.setattr(os, "open", spy)
    with pytest.raises(RecordingError, match="external file"):
        read_recording(path)
    assert "/etc/passwd" not in opened


def test_declared_sizes_are_checked_before_reading(tmp_path):
    import h5py

    path = write_raw_recording(tmp_path / "ok.h5")
    with h5py.File(path, "a") as h5:
        del h5["waveforms"]
        dset = h5.create_dataset("waveforms", shape=(4, 3, 300_000), dtype=np.int16, chunks=(1, 3, 300_000),
                                 compression="gzip")
        dset[...] = 1  # constant: compresses about 1000 times
        dset.attrs["volts_per_code"] = 1e-3
        del h5["clipped"]
    with pytest.raises(RecordingError, match="declares .* bytes but stores"):
        read_recording(path)
    # The same file is read when the user allows that expansion.
    assert read_recording(path, limits=ReadLimits(max_expansion=1e6)).n_pings == 4
    with pytest.raises(RecordingError, match="samples per channel"):
        read_recording(path, limits=ReadLimits(max_samples_per_channel=1000, max_expansion=1e6))


def test_a_python_call_with_a_wrong_type_names_the_argument():
    with pytest.raises(InputTypeError, match="read_recording: path must be a file path.*int 123"):
        read_recording(123)
    with pytest.raises(InputTypeError, match="open_recording: path"):
        open_recording(None)


def test_int32_codes_are_refused_by_both_commands_with_the_same_line(tmp_path, capsys):
    path = write_raw_recording(tmp_path / "int32.h5", codes=np.full((1, 3, 64), 40000, dtype=np.int32))
    lines = []
    for verb in ("detect", "localize"):
        assert main([verb, str(path)]) == 2
        lines.append(capsys.readouterr().err)
    assert lines[0] == lines[1] and "int16" in lines[0]
