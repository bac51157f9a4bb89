"""Are two runs the same run? Compares the JSON results of two output directories (``cpg-walker walk`` /
``cpg-walk`` / ``replay --out``: walk.json, graph_record.json, ...) value for value, except the wall-clock
measurements (real-time factor, wall and CPU seconds, latencies, lockstep re-sends, GC pauses), which
differ between any two runs. A lockstep graph walk and an in-process walk are deterministic: the same
command on code that behaves the same gives no difference.

    python tools/same_run.py BEFORE_DIR AFTER_DIR     # exit 0: the same; 1: the differences, listed
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

#: Keys whose values are wall-clock measurements (anywhere in the JSON tree).
WALL_CLOCK = {"real_time_factor", "wall_s", "wall_s_total", "sim_wall_s", "cpu_s", "latency",
              "latency_state_to_torque", "resends", "gc"}


def differences(a: object, b: object, path: str = "") -> list[str]:
    """Paths where ``a`` and ``b`` differ, wall-clock keys left out."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            if k in WALL_CLOCK:
                continue
            if k not in a or k not in b:
                out.append(f"{path}.{k}: only in {'the second' if k in b else 'the first'}")
            else:
                out += differences(a[k], b[k], f"{path}.{k}")
        return out
    return [] if a == b else [f"{path}: {str(a)[:60]} != {str(b)[:60]}"]


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    first, second = (Path(d) for d in argv)
    names = sorted(p.name for p in first.glob("*.json"))
    if not names:
        print(f"same_run: no JSON files in {first}", file=sys.stderr)
        return 2
    found = []
    for name in names:
        other = second / name
        if not other.exists():
            found.append(f"{name}: missing in {second}")
            continue
        found += [f"{name}{d}" for d in differences(json.loads((first / name).read_text()),
                                                    json.loads(other.read_text()))]
    for line in found:
        print(line)
    verdict = "the same run" if not found else f"{len(found)} differences"
    print(f"{len(names)} JSON files compared: {verdict}")
    return 1 if found else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
