"""Smoke checks of the package layout and the console scripts."""

import shutil
import subprocess
import sys

import pytest


@pytest.mark.parametrize("command", ["acoustisim", "binsonar"])
def test_console_scripts_answer_help(command: str) -> None:
    exe = shutil.which(command) or str(__import__("pathlib").Path(sys.executable).with_name(command))
    out = subprocess.run([exe, "--help"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert command in out.stdout
    assert out.stderr == ""
