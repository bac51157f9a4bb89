"""The exit status of every `cpg-walker` command, one rule (README, "Exit status"):

- ``OK`` (0): the command did what was asked;
- ``FELL`` (1): the robot fell in a run whose purpose is to walk (walk, cpg-walk, demo, replay, graph,
  soak, faults, drive-check, two-hosts, teach); the fall — sim time and where — is the last line printed;
- ``BAD_INPUT`` (2): bad input, one line naming it (raised as ``UserError``, printed by cli/main.py; a
  teaching stream cpg_node refused, with its reason).

Experiments whose falls are data (sweep, envelope, feedback-search, transport, margins, cmd-vel-map) exit
``OK`` and count the falls in their summary.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Mapping
from typing import Any

OK, FELL, BAD_INPUT = 0, 1, 2


def where(report: Mapping[str, Any]) -> str:
    """Where a walk report's robot ended, relative to its start: forward along the starting heading and
    to the left of it (walk.json's ``distance_m`` and ``lateral_drift_m``; a walk that stops on the fall
    ends where it fell). Empty when the report has neither."""
    forward, left = report.get("distance_m"), report.get("lateral_drift_m")
    parts = []
    if forward is not None:
        parts.append(f"{forward:+.2f} m forward")
    if left is not None:
        parts.append(f"{left:+.2f} m left")
    return (", " + " and ".join(parts) + " of the start") if parts else ""


def fall_line(command: str, fall_time_s: float | None, place: str = "", what: str = "") -> str:
    """``cpg-walker CMD: FELL at T sim s[, where][ (what)]``: the last line of a walk that fell."""
    when = "at an unknown time" if fall_time_s is None else f"at {fall_time_s:.2f} sim s"
    return f"cpg-walker {command}: FELL {when}{place}" + (f" ({what})" if what else "")


def report_fall(command: str, falls: Iterable[str]) -> int:
    """Print each fall line last (stdout flushed first, the lines on stderr) and return the exit status:
    ``FELL`` if there is any, else ``OK``."""
    lines = list(falls)
    if not lines:
        return OK
    sys.stdout.flush()
    for line in lines:
        print(line if line.startswith("cpg-walker ") else f"cpg-walker {command}: FELL {line}",
              file=sys.stderr, flush=True)
    return FELL


def walk_status(command: str, report: Mapping[str, Any], what: str = "") -> int:
    """The exit status of a command whose purpose is one walk summarised by ``report`` (walk.json,
    replay.json: ``fell``, ``fall_time_s``, ``distance_m``, ``lateral_drift_m``)."""
    if not report.get("fell"):
        return OK
    return report_fall(command, [fall_line(command, report.get("fall_time_s"), where(report), what)])
