"""Where a committed result came from: the command, the commit, the date and the machine's load, so every
figure the docs quote can be traced to the run that measured it (docs/results/)."""

from __future__ import annotations

import datetime
import os
import platform
import subprocess
from pathlib import Path


def git_commit(repo: Path | None = None) -> str | None:
    """The checkout's HEAD (with ``+dirty`` when it has uncommitted changes), None outside a git checkout."""
    where = repo or Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(["git", "-C", str(where), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(where), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return head + ("+dirty" if dirty else "")


def load_average() -> list[float]:
    """The 1, 5 and 15 min load averages (other work shares this machine's cores)."""
    return [round(x, 2) for x in os.getloadavg()]


def provenance(command: str) -> dict:
    """The run's command, commit, UTC date, load at the start and machine (cores, Python, platform)."""
    return {"command": command, "commit": git_commit(),
            "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "load_average_start": load_average(), "cpus": os.cpu_count(),
            "python": platform.python_version(), "platform": platform.platform()}
