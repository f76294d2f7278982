"""The project's input errors: what a user can cause, with a message naming file, field and value.

Defined in binsonar, the lowest layer (the simulator imports binsonar, never the reverse), so
that every package shares one hierarchy: :class:`InputError` (a ``ValueError``) for bad values,
files and options, and :class:`InputTypeError` (also a ``TypeError``) for arguments of the
wrong type. The command lines print either on one line and exit with code 2.
"""


class InputError(ValueError):
    """Bad user input (a file, an option, a parameter). The command line prints it on one line
    and exits with code 2."""


class InputTypeError(InputError, TypeError):
    """An argument of the wrong type (a string where a number is expected, say)."""


__all__ = ("InputError", "InputTypeError")
