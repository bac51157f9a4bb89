"""The package's one exception for bad user input (an argument, an environment variable, a file's
content). The command line prints its message as one line and exits with status 2, no traceback; any
other exception is a bug and keeps its traceback."""

from __future__ import annotations


class InputError(ValueError):
    """Bad input from the user; the message names it (the option, the file and line where known).

    A ValueError, so that code catching ValueError around the core's validation keeps working."""
