"""Smoke checks of the package layout."""

import subprocess
import sys


def test_acoustisim_help_exits_zero():
    out = subprocess.run([sys.executable, "-m", "acoustisim.cli.main", "--help"], capture_output=True, text=True)
    assert out.returncode == 0
    assert "acoustisim" in out.stdout
