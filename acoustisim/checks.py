"""Argument checks for the public descriptors: types, finiteness and physical ranges.

Each check returns the canonical value (a Python ``float``, ``int``, ``str`` or tuple) or
raises one of the project's input errors with a one-line message ``owner.key = value: problem``:
:class:`~acoustisim.errors.InputTypeError` for a value of the wrong type (a string where a
number is expected), :class:`~acoustisim.errors.InputError` for a value out of range. The
value is quoted with a bounded ``repr`` (:func:`shown`), so a megabyte string or a list nested
ten thousand deep gives a short message, never a ``RecursionError``.
"""

from __future__ import annotations

import math
import numbers
import reprlib
from typing import Any, Iterable

import numpy as np

from acoustisim.errors import InputError, InputTypeError
from acoustisim.ranges import PhysicalRange

class _ShortRepr(reprlib.Repr):
    """``repr`` bounded in depth, string length, digits and items."""

    def __init__(self) -> None:
        super().__init__()
        self.maxlevel = 3
        self.maxstring = 60
        self.maxother = 60
        self.maxlong = 40
        self.maxlist = self.maxtuple = 8
        self.maxdict = 6


def shown(value: Any) -> str:
    """A short, one-line ``repr`` of ``value`` for messages (floats keep full precision)."""
    if isinstance(value, float):
        return repr(value)
    try:
        text = _ShortRepr().repr(value)
    except Exception:  # noqa: BLE001 - a hostile __repr__ must not hide the real error
        text = f"<{type(value).__name__}>"
    return " ".join(text.split())


def where(owner: str, key: str) -> str:
    """``owner.key``, or ``key`` alone when there is no owner."""
    return f"{owner}.{key}" if owner else key


def type_error(owner: str, key: str, value: Any, expected: str) -> InputTypeError:
    """The error for a value of the wrong type."""
    return InputTypeError(f"{where(owner, key)} = {shown(value)}: expected {expected}, got {type(value).__name__}")


def value_error(owner: str, key: str, value: Any, problem: str) -> InputError:
    """The error for a value of the right type that cannot be used."""
    return InputError(f"{where(owner, key)} = {shown(value)}: {problem}")


def is_number(value: Any) -> bool:
    """A real number (int, float, numpy scalar), not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def real(owner: str, key: str, value: Any, allowed: PhysicalRange | None = None, *,
         positive: bool = False) -> float:
    """A finite real number, inside ``allowed`` when given (and > 0 with ``positive``)."""
    if not is_number(value):
        raise type_error(owner, key, value, "a number")
    try:
        x = float(value)
    except OverflowError:
        raise value_error(owner, key, value, "too large for a floating-point number") from None
    if not math.isfinite(x):
        raise value_error(owner, key, value, "must be finite")
    if positive and not x > 0.0:
        raise value_error(owner, key, value, "must be > 0")
    if allowed is not None and not allowed.contains(x):
        raise value_error(owner, key, value, allowed.describe())
    return x


def integer(owner: str, key: str, value: Any, *, minimum: int | None = None, maximum: int | None = None) -> int:
    """An integer (not a bool, not a float) in [minimum, maximum]."""
    if not isinstance(value, numbers.Integral) or isinstance(value, (bool, np.bool_)):
        raise type_error(owner, key, value, "an integer")
    n = int(value)
    if (minimum is not None and n < minimum) or (maximum is not None and n > maximum):
        low = "" if minimum is None else f">= {minimum}"
        high = "" if maximum is None else f"<= {maximum}"
        raise value_error(owner, key, value, "must be " + " and ".join(p for p in (low, high) if p))
    return n


def vector(owner: str, key: str, value: Any, n: int, allowed: PhysicalRange | None = None, *,
           nonzero: bool = False) -> tuple[float, ...]:
    """``n`` finite numbers (a list, tuple or 1-D array), each inside ``allowed`` when given."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "iuf" or value.ndim != 1:
            raise type_error(owner, key, value, f"{n} numbers")
        items: Iterable[Any] = value.tolist()
    elif isinstance(value, (list, tuple)):
        items = value
    else:
        raise type_error(owner, key, value, f"a list of {n} numbers")
    items = list(items)
    if len(items) != n:
        raise value_error(owner, key, value, f"expected {n} numbers, got {len(items)}")
    if not all(is_number(v) for v in items):
        raise type_error(owner, key, value, f"a list of {n} numbers")
    try:
        numbers_ = tuple(float(v) for v in items)
    except OverflowError:
        raise value_error(owner, key, value, "too large for floating-point numbers") from None
    if not all(math.isfinite(v) for v in numbers_):
        raise value_error(owner, key, value, "must be finite")
    if allowed is not None and not all(allowed.contains(v) for v in numbers_):
        raise value_error(owner, key, value, "each number " + allowed.describe())
    if nonzero and all(v == 0.0 for v in numbers_):
        raise value_error(owner, key, value, "must be a non-zero vector")
    return numbers_


def direction(owner: str, key: str, value: Any, n: int = 3) -> tuple[float, ...]:
    """The unit vector along ``n`` finite numbers (any length, even 1e300 or 1e-300: scaled by
    the largest component before the norm, so nothing overflows or underflows)."""
    raw = vector(owner, key, value, n, nonzero=True)
    scale = max(abs(v) for v in raw)
    scaled = [v / scale for v in raw]
    norm = math.sqrt(sum(v * v for v in scaled))
    return tuple(v / norm for v in scaled)


def text(owner: str, key: str, value: Any) -> str:
    """A non-empty string."""
    if not isinstance(value, str):
        raise type_error(owner, key, value, "a string")
    if not value.strip():
        raise value_error(owner, key, value, "must not be empty")
    return value


def choice(owner: str, key: str, value: Any, options: tuple[str, ...]) -> str:
    """One of ``options``."""
    if not isinstance(value, str):
        raise type_error(owner, key, value, "one of " + ", ".join(map(repr, options)))
    if value not in options:
        raise value_error(owner, key, value, "expected one of " + ", ".join(map(repr, options)))
    return value


def instance(owner: str, key: str, value: Any, kind: type | tuple[type, ...], expected: str) -> Any:
    """``value`` itself, if it is an instance of ``kind``."""
    if not isinstance(value, kind):
        raise type_error(owner, key, value, expected)
    return value


__all__ = ("choice", "direction", "instance", "integer", "is_number", "real", "shown", "text", "type_error", "value_error",
           "vector", "where")
