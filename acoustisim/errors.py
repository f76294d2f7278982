"""Errors a user can cause. Their message names the file, the field and the value.

One hierarchy for the whole project, defined in :mod:`binsonar.errors` (the lowest layer).
"""

from binsonar.errors import InputError, InputTypeError


class ResourceLimitError(InputError):
    """A simulation that would need more memory, triangles, rays or reflector sequences than the
    limits in force (:mod:`acoustisim.resources`); the message gives the estimate, the limit and
    how to raise it."""


__all__ = ("InputError", "InputTypeError", "ResourceLimitError")
