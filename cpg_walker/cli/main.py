"""`cpg-walker`: one command for the project's experiments and tools.

Each sub-command lives in its own module of this package and exposes `register(subparsers)`, which adds
its parser and sets `func`; heavy imports happen inside `func`, so `cpg-walker --help` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import NoReturn

from cpg_walker.errors import InputError


def command_modules() -> list[str]:
    """Every module of this package that defines `register` is a sub-command (listed alphabetically)."""
    import pkgutil

    import cpg_walker.cli as package

    return sorted(m.name for m in pkgutil.iter_modules(package.__path__) if m.name not in _NOT_COMMANDS)


_NOT_COMMANDS = {"main", "outcome", "progress", "checks", "study_args"}

#: The old name of the input-error exception (cpg_walker.errors.InputError).
UserError = InputError


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr (``PROG: error: ...``, no usage), status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {one_line(message)}\n")


def one_line(text: str) -> str:
    """``text``'s lines joined by '; ' (an error message is one line)."""
    return "; ".join(line.strip() for line in str(text).splitlines() if line.strip()) or "(no message)"


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="cpg-walker",
        description="Programmable CPGs (Righetti & Ijspeert) driving a simulated HOAP-2 humanoid.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in command_modules():
        module = importlib.import_module(f"cpg_walker.cli.{name}")
        if hasattr(module, "register"):
            module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one sub-command; returns its exit status. Bad input (argparse's checks, InputError) is one line
    on stderr and status 2; any other exception is a bug and propagates with its traceback."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a bad argument (2, its one line printed)
        return exc.code if isinstance(exc.code, int) else 2
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"cpg-walker {args.command}: error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
