"""A detection method's options: name, default, and the check of a value a user gives.

Each method (``methods``) declares its options as a tuple of ``Option``; ``prepare`` checks
the options it is given against them once, before any planning, so that a wrong name or value
is reported as a ``RecordingError`` naming the method, the option and the value. The checks
here are those that need no data (types and domains); what depends on the record (a window
outside it, a decomposition deeper than it allows) is checked by the method when it runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from binsonar.recording import RecordingError

Check = Callable[[str, Any], None]
"""``check(label, value)`` raises ``RecordingError`` (naming ``label``) for a value it refuses."""


@dataclass(frozen=True)
class Option:
    """One option of a detection method.

    Attributes
    ----------
    name : str
        The keyword argument (``detect(..., name=value)``, ``--option name=value``).
    default : object
        The value used when the option is not given (what ``method_options`` lists).
    check : callable
        ``check(label, value)``: raises ``RecordingError`` for a value the method refuses.
    doc : str
        One line: what the option sets, with its unit.
    """

    name: str
    default: Any
    check: Check
    doc: str


def _is_real(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def probability(label: str, value: Any) -> None:
    """A probability strictly between 0 and 1 (a design false-alarm probability)."""
    if not (_is_real(value) and 0.0 < value < 1.0):
        raise RecordingError(f"{label}: pfa must be in (0, 1), got {value!r}")


def positive(label: str, value: Any) -> None:
    """A finite number > 0."""
    if not (_is_real(value) and math.isfinite(value) and value > 0):
        raise RecordingError(f"{label} must be a finite number > 0, got {value!r}")


def non_negative(label: str, value: Any) -> None:
    """A finite number >= 0."""
    if not (_is_real(value) and math.isfinite(value) and value >= 0):
        raise RecordingError(f"{label} must be a finite number >= 0, got {value!r}")


def finite(label: str, value: Any) -> None:
    """Any finite number."""
    if not (_is_real(value) and math.isfinite(value)):
        raise RecordingError(f"{label} must be a finite number, got {value!r}")


def flag(label: str, value: Any) -> None:
    """True or False (or 1 or 0)."""
    if not (isinstance(value, (bool, np.bool_)) or (isinstance(value, (int, np.integer)) and value in (0, 1))):
        raise RecordingError(f"{label} must be true or false, got {value!r}")


def text(label: str, value: Any) -> None:
    """A non-empty string."""
    if not (isinstance(value, str) and value):
        raise RecordingError(f"{label} must be a name, got {value!r}")


def time_window(label: str, value: Any) -> None:
    """(start_s, stop_s): two numbers (s after the trigger; +/-inf for an open end)."""
    try:
        start, stop = (float(v) for v in value)
    except (TypeError, ValueError):
        raise RecordingError(f"{label} must be (start_s, stop_s), got {value!r}") from None
    if math.isnan(start) or math.isnan(stop):
        raise RecordingError(f"{label} must be (start_s, stop_s) without NaN, got {value!r}")


def integer_in(low: int, high: int | None = None) -> Check:
    """An integer in [low, high] (no upper bound for None)."""
    span = f"[{low}, {high}]" if high is not None else f">= {low}"

    def check(label: str, value: Any) -> None:
        if not (isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
                and low <= value and (high is None or value <= high)):
            raise RecordingError(f"{label} must be an integer {'in ' if high is not None else ''}{span}, got {value!r}")

    return check


def even_integer_from(low: int) -> Check:
    """An even integer >= low."""

    def check(label: str, value: Any) -> None:
        if not (isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
                and value >= low and value % 2 == 0):
            raise RecordingError(f"{label} must be an even integer >= {low}, got {value!r}")

    return check


def one_of(*choices: str) -> Check:
    """One of the given names."""

    def check(label: str, value: Any) -> None:
        if value not in choices:
            raise RecordingError(f"{label} must be one of {', '.join(repr(c) for c in choices)}, got {value!r}")

    return check


def optional(check: Check) -> Check:
    """None, or a value ``check`` accepts."""

    def check_optional(label: str, value: Any) -> None:
        if value is not None:
            check(label, value)

    return check_optional
