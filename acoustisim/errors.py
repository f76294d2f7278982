"""Errors a user can cause. Their message names the file, the field and the value."""


class InputError(ValueError):
    """Bad user input (scene file, option, parameter). The command line prints it on one line
    and exits with code 2."""
