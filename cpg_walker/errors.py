"""The package's exceptions the user can act on.

``InputError``: bad user input (an argument, an environment variable, a file's content). The command line
prints its message as one line and exits with status 2, no traceback; any other exception is a bug and
keeps its traceback. ``ToolError``: a run-time failure of a graph tool (``cpg-walker param|topic|node``: a
node or topic not found, a rejected value, a message type not installed), reported by the tool as one
line."""

from __future__ import annotations


class InputError(ValueError):
    """Bad input from the user; the message names it (the option, the file and line where known).

    A ValueError, so that code catching ValueError around the core's validation keeps working."""


class ToolError(RuntimeError):
    """A run-time failure the user can act on (node or topic not found, a rejected value): one line."""
