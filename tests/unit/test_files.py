"""``binsonar.files``: inputs that cannot hang, outputs that cannot clobber."""

from __future__ import annotations

import os
import stat
import subprocess
import sys

import pytest

from binsonar.errors import InputError, InputTypeError
from binsonar.files import (
    atomic_output,
    check_input_file,
    check_output_file,
    check_output_folder,
    note_created_folder,
    open_input_file,
    read_toml,
    write_bytes_atomic,
)

IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


def _one_line(exc: pytest.ExceptionInfo) -> str:
    text = str(exc.value)
    assert "\n" not in text
    return text


# ---------------------------------------------------------------------------------------- inputs
def test_a_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "pipe.h5"
    os.mkfifo(fifo)
    # Nobody writes to the FIFO: an open() without O_NONBLOCK would wait forever.
    with pytest.raises(InputError, match="FIFO") as exc:
        with open_input_file(fifo, "recording"):
            pass
    assert str(fifo) in _one_line(exc)


@pytest.mark.parametrize("path, kind", [("/dev/zero", "device"), ("/dev/null", "device")])
def test_devices_and_folders_are_refused(tmp_path, path, kind):
    with pytest.raises(InputError, match=kind):
        check_input_file(path, "scene file")
    with pytest.raises(InputError, match="folder"):
        check_input_file(tmp_path, "scene file")


def test_missing_empty_and_oversized_inputs(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        check_input_file(tmp_path / "absent.h5")
    (tmp_path / "empty.h5").write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        check_input_file(tmp_path / "empty.h5")
    (tmp_path / "big.toml").write_bytes(b"a = 1\n" * 100)
    with pytest.raises(InputError, match="more than the 100"):
        check_input_file(tmp_path / "big.toml", max_bytes=100)


@pytest.mark.parametrize("value", [123, None, b"ping.h5", 1.5])
def test_paths_of_the_wrong_type_are_typed_errors(value):
    with pytest.raises(InputTypeError, match="file path"):
        check_input_file(value, "recording")


def test_toml_nested_thousands_deep_is_one_line(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text("a = " + "[" * 10000 + "]" * 10000 + "\n")
    with pytest.raises(InputError, match="too deeply|invalid TOML") as exc:
        read_toml(path)
    _one_line(exc)


def test_toml_errors_name_the_line(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("a = 1\nb = = 2\n")
    with pytest.raises(InputError, match="line 2"):
        read_toml(path)
    path.write_bytes(b"a = '\xff'\n")
    with pytest.raises(InputError, match="UTF-8"):
        read_toml(path)


# --------------------------------------------------------------------------------------- outputs
def test_atomic_output_gets_the_umask_mode_and_leaves_no_temporary(tmp_path):
    # In a child process: the umask is process-wide state this test must not change.
    code = (
        "import os, sys; os.umask(0o027); from binsonar.files import write_bytes_atomic; "
        "p = write_bytes_atomic(sys.argv[1], b'data'); print(oct(os.stat(p).st_mode & 0o777))"
    )
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "out.bin")], capture_output=True, text=True,
                         check=True, env={**os.environ, "PYTHONPATH": os.getcwd()})
    assert out.stdout.strip() == "0o640"  # 0666 & ~0027
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bin"]


def test_a_failed_write_keeps_the_old_file_and_removes_the_temporary(tmp_path):
    target = tmp_path / "ping.h5"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with atomic_output(target) as temporary:
            temporary.write_bytes(b"half")
            raise RuntimeError("writer failed")
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ping.h5"]


def test_an_oserror_of_the_writer_names_the_users_path(tmp_path):
    target = tmp_path / "ping.h5"
    with pytest.raises(InputError) as exc:
        with atomic_output(target, "-o") as temporary:
            raise OSError(28, "No space left on device", str(temporary))
    message = _one_line(exc)
    assert message.startswith(f"-o {target}:") and "No space left" in message and ".tmp" not in message


def test_symlinks_and_devices_are_refused_not_replaced(tmp_path):
    real = tmp_path / "real.h5"
    real.write_bytes(b"keep")
    link = tmp_path / "link.h5"
    link.symlink_to(real)
    with pytest.raises(InputError, match="symbolic link") as exc:
        write_bytes_atomic(link, b"new", "-o")
    assert str(link) in _one_line(exc)
    assert link.is_symlink() and real.read_bytes() == b"keep"
    with pytest.raises(InputError, match="device"):
        check_output_file("/dev/null", "-o")
    fifo = tmp_path / "fifo.h5"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="FIFO"):
        check_output_file(fifo, "-o")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    with pytest.raises(InputError, match="names a folder|not a regular file|folder"):
        check_output_file(tmp_path, "-o")


def test_missing_folders_empty_and_long_names_are_refused(tmp_path):
    with pytest.raises(InputError, match="does not exist") as exc:
        check_output_file(tmp_path / "no" / "such" / "ping.h5", "-o")
    assert "-o " in _one_line(exc)
    assert not (tmp_path / "no").exists()
    with pytest.raises(InputError, match="empty"):
        check_output_file("", "-o")
    with pytest.raises(InputError, match="too long|longer than"):
        check_output_file(tmp_path / ("x" * 300 + ".h5"), "-o")
    with pytest.raises(InputTypeError):
        check_output_file(5, "-o")


def test_a_long_but_valid_name_still_gets_a_temporary(tmp_path):
    target = tmp_path / ("p" * 250 + ".h5")
    write_bytes_atomic(target, b"x")
    assert target.read_bytes() == b"x"


@pytest.mark.skipif(IS_ROOT, reason="root writes into read-only folders")
def test_a_read_only_folder_is_refused_before_the_work(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        with pytest.raises(InputError, match="cannot write"):
            check_output_file(folder / "ping.h5", "-o")
    finally:
        folder.chmod(0o700)


def test_output_folders_are_checked_not_created(tmp_path, capsys):
    target = tmp_path / "new" / "deeper"
    assert check_output_folder(target, "--out") == target
    assert not (tmp_path / "new").exists()  # nothing made before the work
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="not a folder"):
        check_output_folder(tmp_path / "file", "--out")
    with pytest.raises(InputError, match="not a folder"):
        check_output_folder(tmp_path / "file" / "sub", "--out")
    target.mkdir(parents=True)
    note_created_folder(target, existed=False, prog="acoustisim")
    note_created_folder(tmp_path, existed=True, prog="acoustisim")
    assert capsys.readouterr().err == f"acoustisim: note: created folder {target}\n"
