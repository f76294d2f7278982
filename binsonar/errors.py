"""The project's input errors: what a user can cause, with a message naming file, field and value.

Defined in binsonar, the lowest layer (the simulator imports binsonar, never the reverse), so
that every package shares one hierarchy: :class:`InputError` (a ``ValueError``) for bad values,
files and options, and :class:`InputTypeError` (also a ``TypeError``) for arguments of the
wrong type. The command lines print either on one line and exit with code 2.

Messages show the offending value with :func:`short_repr`; :func:`checked_number` is the one
check of a finite real number in a range, raising the caller's error class.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


class InputError(ValueError):
    """Bad user input (a file, an option, a parameter). The command line prints it on one line
    and exits with code 2."""


class InputTypeError(InputError, TypeError):
    """An argument of the wrong type (a string where a number is expected, say)."""


def short_repr(value: Any, limit: int = 60) -> str:
    """``repr(value)`` on one line, cut to ``limit`` characters (a value in a message stays short)."""
    text = repr(value).replace("\n", " ")
    return text if len(text) <= limit else text[: limit - 3] + "..."


def checked_number(value: Any, where: str, *, error: type[InputError] = InputError, low: float | None = None,
                   high: float | None = None, low_open: bool = False) -> float:
    """``value`` as a finite float within [low, high] (``low_open``: > low).

    Raises
    ------
    InputError (``error``)
        Not a real number (booleans included), not finite, or out of the range; the message
        starts with ``where`` and shows the value.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise error(f"{where} must be a number, got {short_repr(value)}")
    number = float(value)
    if not math.isfinite(number):
        raise error(f"{where} must be finite, got {short_repr(value)}")
    if low is not None and (number <= low if low_open else number < low):
        raise error(f"{where} must be {'>' if low_open else '>='} {low:g}, got {short_repr(value)}")
    if high is not None and number > high:
        raise error(f"{where} must be <= {high:g}, got {short_repr(value)}")
    return number


__all__ = ("InputError", "InputTypeError", "checked_number", "short_repr")
