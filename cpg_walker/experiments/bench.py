"""Benchmark driver: runs each registered section and merges the results into one JSON and markdown.

A section is a function `run(quick: bool) -> dict` in its own module; it measures in-process with
`time.perf_counter`, repeats, and reports medians together with its baseline measured in the same run
(so ratios hold when the machine's speed drifts). Timing targets live here, never in unit tests.
"""

from __future__ import annotations

import importlib
import json
import platform
import sys
import time
from pathlib import Path

from cpg_walker.experiments import bench_report
from cpg_walker.experiments.bench_sections import SECTIONS


def _load() -> dict:
    """The machine's load averages (other processes share it: absolute timings are noisy)."""
    import os

    one, five, fifteen = os.getloadavg()
    return {"1min": round(one, 2), "5min": round(five, 2), "15min": round(fifteen, 2)}


def median_us(fn, n: int, repeats: int) -> float:
    """Median over ``repeats`` of the mean wall time (us) of ``n`` calls of ``fn``."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        times.append((time.perf_counter() - t0) / n * 1e6)
    import numpy as np

    return float(np.median(times))


def _machine() -> dict:
    import os

    import numpy

    return {
        "python": sys.version.split()[0],
        "numpy": numpy.__version__,
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "load_start": _load(),
    }


def _to_markdown(results: dict, prefix: str = "") -> list[str]:
    lines: list[str] = []
    for key, value in results.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            lines.extend(_to_markdown(value, name + "."))
        elif isinstance(value, float):
            lines.append(f"| `{name}` | {value:.6g} |")
        else:
            lines.append(f"| `{name}` | {value} |")
    return lines


def run_benchmarks(out_dir: str | Path, only: list[str] | None = None, quick: bool = False,
                   readme: str | Path | None = None) -> dict:
    """Run the sections (``only``: these), write bench.json, bench.md (every figure), bench_table.md (the
    summary tables, experiments/bench_report.py) and the scaling plots into ``out_dir``; with ``readme``,
    replace that file's generated benchmark block by the summary tables too."""
    unknown = sorted(set(only or []) - set(SECTIONS))
    if unknown:
        raise ValueError(f"unknown benchmark section(s) {unknown}; known: {sorted(SECTIONS)}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results: dict = {"machine": _machine(), "quick": quick}
    t_start = time.perf_counter()
    for name, target in SECTIONS.items():
        if only and name not in only:
            continue
        module_name, func_name = target.split(":")
        print(f"bench: {name} ...", file=sys.stderr, flush=True)
        started = time.perf_counter()
        results[name] = getattr(importlib.import_module(module_name), func_name)(quick=quick)
        results[name]["section_wall_s"] = round(time.perf_counter() - started, 2)
        print(f"bench: {name} done in {results[name]['section_wall_s']:.0f} s", file=sys.stderr, flush=True)
    results["machine"]["load_end"] = _load()
    results["machine"]["wall_s"] = round(time.perf_counter() - t_start, 1)
    (out / "bench.json").write_text(json.dumps(results, indent=2) + "\n")
    md = ["# cpg_walker benchmarks", "", "| figure | value |", "|---|---|", *_to_markdown(results), ""]
    (out / "bench.md").write_text("\n".join(md))
    files = bench_report.write(results, out, readme)
    print(f"bench: wrote bench.json, bench.md{''.join(', ' + p.name for p in files)} in {out}"
          + (f"; updated {readme}" if readme is not None else ""), file=sys.stderr)
    return results


def headline_status(results: dict) -> int:
    """0 if every headline figure's runs are valid (bench_validity.HEADLINE), else 1, after printing why
    to stderr; the last line says which headline run is invalid and why."""
    from cpg_walker.experiments.bench_validity import headline_problems

    problems = headline_problems(results)
    if not problems:
        return 0
    for line in problems[1:]:
        print(f"bench: headline run invalid: {line}", file=sys.stderr)
    print(f"cpg-walker bench: headline run invalid ({len(problems)} in all): {problems[0]}", file=sys.stderr)
    return 1
