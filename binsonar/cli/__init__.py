"""The ``binsonar`` command line; each verb lives in a ``cmd_*.py`` module of this package."""

from binsonar.cli.main import main

__all__ = ("main",)
