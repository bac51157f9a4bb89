"""Up-front checks of the command line's values, shared by the sub-commands: argparse ``type=`` functions
(a bad value is argparse's one-line error, before any work starts) and checks raising InputError.

Numbers must be finite; paths must not be empty; an output directory must be a directory or creatable;
an input file must exist and be readable (and, for text, be UTF-8)."""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable
from pathlib import Path

from cpg_walker.errors import InputError
from cpg_walker.graph.processes import DOMAIN_RANGE


def _path(text: str) -> Path:
    if not text or not text.strip():
        raise argparse.ArgumentTypeError("expected a path, got an empty string")
    if "\x00" in text:
        raise argparse.ArgumentTypeError(f"{text!r}: a path cannot contain a NUL character")
    return Path(text)


def _exists(p: Path) -> bool:
    try:
        return p.exists()
    except OSError as exc:  # e.g. a parent without search permission, a name too long
        raise argparse.ArgumentTypeError(f"{p}: {exc.strerror or exc}") from None


def _creatable_dir(p: Path, text: str) -> None:
    """``p`` is an existing writable directory, or its first existing ancestor is one."""
    if _exists(p):
        if not p.is_dir():
            raise argparse.ArgumentTypeError(f"{text}: exists and is not a directory")
        if not os.access(p, os.W_OK | os.X_OK):
            raise argparse.ArgumentTypeError(f"{text}: directory not writable")
        return
    up = p.absolute().parent
    while not _exists(up):
        up = up.parent
    if not up.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: cannot be created, {up} is not a directory")
    if not os.access(up, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"{text}: cannot be created, {up} is not writable")


def out_dir(text: str) -> str:
    """An output directory: an existing writable directory, or one that can be created."""
    _creatable_dir(_path(text), text)
    return text


def out_file(text: str) -> str:
    """An output file ('-': standard output): not a directory, in a directory that exists or can be made."""
    if text == "-":
        return text
    p = _path(text)
    if _exists(p) and p.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: is a directory, expected a file")
    if _exists(p) and not os.access(p, os.W_OK):
        raise argparse.ArgumentTypeError(f"{text}: file not writable")
    _creatable_dir(p.absolute().parent, text)
    return text


def in_path(text: str) -> str:
    """An existing file or directory."""
    if not _exists(_path(text)):
        raise argparse.ArgumentTypeError(f"{text}: no such file or directory")
    return text


def in_file(text: str) -> str:
    """An existing, readable regular file."""
    p = _path(text)
    if not _exists(p):
        raise argparse.ArgumentTypeError(f"{text}: no such file")
    if not p.is_file():
        raise argparse.ArgumentTypeError(f"{text}: not a regular file")
    try:
        with open(p, "rb"):
            pass
    except OSError as exc:
        raise argparse.ArgumentTypeError(f"{text}: cannot be read ({exc.strerror or exc})") from None
    return text


def in_text_file(text: str) -> str:
    """An existing, readable UTF-8 text file (YAML, CSV, JSON, XML)."""
    in_file(text)
    data = Path(text).read_bytes()
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise argparse.ArgumentTypeError(f"{text}:{line}: not a UTF-8 text file (byte {data[exc.start]:#04x} "
                                         f"at offset {exc.start})") from None
    if "\x00" in data.decode("utf-8"):
        line = data[: data.index(b"\x00")].count(b"\n") + 1
        raise argparse.ArgumentTypeError(f"{text}:{line}: not a text file (a NUL byte)")
    return text


def config_or_file(text: str) -> str:
    """A readable text file, or a bare file name in the package's config/ (the loaders accept both)."""
    from cpg_walker.paths import share_dir

    p = _path(text)
    if not _exists(p) and len(p.parts) == 1 and (share_dir() / "config" / text).is_file():
        return text
    return in_text_file(text)


def number(text: str, kind: type = float) -> float:
    """``text`` as a finite number of ``kind`` (float or int)."""
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected {'an integer' if kind is int else 'a number'}, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def at_least(low: float, kind: type = float, strict: bool = False) -> Callable[[str], float]:
    """A type: a finite number of ``kind`` >= ``low`` (> ``low`` if ``strict``)."""
    def check(text: str) -> float:
        value = number(text, kind)
        if value < low or (strict and value == low):
            raise argparse.ArgumentTypeError(f"must be {'>' if strict else '>='} {low:g}, got {text}")
        return value

    check.__name__ = "number"
    return check


def within(low: float, high: float, kind: type = float) -> Callable[[str], float]:
    """A type: a finite number of ``kind`` in [low, high]."""
    def check(text: str) -> float:
        value = number(text, kind)
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be in [{low:g}, {high:g}], got {text}")
        return value

    check.__name__ = "number"
    return check


positive = at_least(0.0, strict=True)
"""A type: a finite number > 0 (seconds, rates)."""
non_negative = at_least(0.0)
"""A type: a finite number >= 0."""
count = at_least(1, int)
"""A type: an integer >= 1 (jobs, oscillators, generations)."""
domain_id = within(*DOMAIN_RANGE, kind=int)
"""A type: a DDS domain, 0..232."""


def user_error(option: str, exc: argparse.ArgumentTypeError) -> InputError:
    """An argparse type's complaint as an InputError naming ``option`` (for values checked in ``_run``)."""
    return InputError(f"{option}: {exc}")
