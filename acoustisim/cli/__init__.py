"""The ``acoustisim`` command line; each verb lives in a ``cmd_*.py`` module of this package."""

from acoustisim.cli.main import main

__all__ = ["main"]
