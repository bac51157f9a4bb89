"""`cpg-walker`: one command for the project's experiments and tools.

Each sub-command lives in its own module of this package and exposes `register(subparsers)`, which adds
its parser and sets `func`; heavy imports happen inside `func`, so `cpg-walker --help` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys


def command_modules() -> list[str]:
    """Every module of this package that defines `register` is a sub-command (listed alphabetically)."""
    import pkgutil

    import cpg_walker.cli as package

    return sorted(m.name for m in pkgutil.iter_modules(package.__path__) if m.name not in _NOT_COMMANDS)


_NOT_COMMANDS = {"main", "outcome", "progress"}


class UserError(Exception):
    """A problem with the user's input: printed as one clear line, exit status 2, no traceback."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
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
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except UserError as exc:
        print(f"cpg-walker {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except ValueError as exc:  # the core's validation errors (bad data, bad parameters) are user errors
        print(f"cpg-walker {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"cpg-walker {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
