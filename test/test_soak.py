"""The soak's bookkeeping (experiments/soak.py) without running it: counters from /diagnostics, the
overrun trend, memory from /proc, the plan's descriptions and the summary table."""

from __future__ import annotations

import os

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from cpg_walker.experiments.soak import PLAN, Counters, _trend, describe, markdown, rss_mib


def test_counters_follow_the_sim_and_cpg_diagnostics():
    c = Counters()
    msg = DiagnosticArray(status=[
        DiagnosticStatus(name="cpg_walker/sim", values=[KeyValue(key="late_commands", value="12")]),
        DiagnosticStatus(name="cpg_walker/cpg", values=[KeyValue(key="overruns", value="3")]),
        DiagnosticStatus(name="someone/else", values=[KeyValue(key="overruns", value="99")])])
    c.on_diagnostics(msg)
    assert (c.late, c.overruns) == (12, 3)


def test_trend_compares_the_first_and_last_third_of_the_increments():
    series = [0, 1, 2, 3, 13, 23, 33]  # increments 1, 1, 1, 10, 10, 10
    assert _trend(series) == {"per_window_first_third": 1.0, "per_window_last_third": 10.0}
    assert _trend([5]) == {"per_window_first_third": None, "per_window_last_third": None}


def test_rss_of_this_process_and_of_none():
    mine = rss_mib(os.getpid())
    assert mine is not None and mine > 1.0
    assert rss_mib(2**22 + 12345) is None  # beyond pid_max's default: no such process


def test_every_change_is_described_and_the_table_says_whether_it_fell():
    assert len({describe(c) for c in PLAN}) == len(PLAN)
    report = {"rss_mib": {"sim_node": {"first_window": 100.0, "last_window": 101.0, "max": 101.5}},
              "late_commands": {"per_window_first_third": 1.0, "per_window_last_third": 1.5},
              "cpg_overruns": {"per_window_first_third": 0.0, "per_window_last_third": 0.0},
              "windows_run": 30, "period_s": 20.0, "fell": True, "fell_at_s": 123.456}
    table = markdown(report)
    assert "| sim_node | 100.0 | 101.0 | 101.5 |" in table and "fell: at 123.46 s" in table
