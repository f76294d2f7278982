"""Errors a user can cause. Their message names the file, the field and the value.

One hierarchy for the whole project, defined in :mod:`binsonar.errors` (the lowest layer).
"""

from binsonar.errors import InputError, InputTypeError

__all__ = ("InputError", "InputTypeError")
