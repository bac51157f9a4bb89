"""Live teaching through the graph (experiments/teach.py, what `cpg-walker teach --attach` runs): one
lockstep graph walking the recorded walk open loop (feedback false); a drifting stream on /cpg/teach is
refused with the reason on /diagnostics while the walk goes on untouched; after a pause the slow walk
streamed at 30 teacher s per wall s is learned by cpg_node at the recording's frequency, saved, takes over
through standing and steps off. Measured at rate 30 (`cpg-walker teach --gait slow --rate 30 --take-over
-p cpg:teach_steps=8`): 0.3907 Hz learned against 0.3906 in 13 wall s; learning took at most 4 ms per
call, after the tick's targets."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np
import pytest

from cpg_walker.walker.controller import DOFS

RATE = 30.0  # teacher s per wall s


class Drift:
    """A teacher whose joints wander (a smooth random walk): no period."""

    source, frequency_hz = "a drifting stream", None

    def __init__(self) -> None:
        rng = np.random.default_rng(11)
        self.knots = np.cumsum(rng.normal(0.0, 0.05, size=(400, len(DOFS))), axis=0)
        self.k = 0

    def until(self, t: float):
        while self.k * 0.01 <= t:
            tk = self.k * 0.01
            self.k += 1
            yield tk, list(DOFS), [float(np.interp(tk, np.arange(400) * 0.5, c)) for c in self.knots.T]


@pytest.mark.ros
@pytest.mark.slow
def test_a_graph_refuses_a_drifting_stream_then_learns_the_slow_walk_and_walks_it(tmp_path):
    from ros_helpers import START_S, kill_nodes, reserve_domain

    from cpg_walker.experiments.teach import StreamTeacher, teach_graph
    from cpg_walker.graph.processes import interrupt_group, isolated_env
    from cpg_walker.walker import storage
    from cpg_walker.walker.learning import live_teaching_config

    domain, lock = reserve_domain()
    log = open(tmp_path / "graph.log", "wb")
    graph = subprocess.Popen(
        [sys.executable, "-m", "cpg_walker.cli.main", "graph", "--pacing", "lockstep", "--duration", "3000",
         "--domain-id", str(domain), "--log-dir", str(tmp_path / "logs"), "-p", "cpg:feedback=false",
         "-p", "cpg:teach_steps=8"],
        env=isolated_env(domain), stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        bad = teach_graph(tmp_path / "drift", Drift(), rate=RATE, domain_id=domain, attach=True,
                          wall_limit_s=START_S, progress=lambda s: None, after_s=3.0)
        assert not bad["converged"] and "not periodic" in bad["reason"], bad
        assert bad["state"] == "refused" and not bad["took_over"] and not bad["fell"]
        after = bad["after"]  # the walk goes on with its network (the recording's steps, then the CPG's)
        assert after["walked_s"] >= 3.0 and after["distance_m"] > 0.05, after  # ~0.25 m per 3 s
        assert after["cpg_state"] in ("starting", "walking") and after["took_over"] == "0"
        time.sleep(live_teaching_config().stall_s + 0.5)  # a pause: the next stream starts a new teaching
        stream = StreamTeacher("slow", 1.0)
        res = teach_graph(tmp_path / "slow", stream, rate=RATE, take_over=True, save=tmp_path / "slow.yaml",
                          duration=6.0, domain_id=domain, attach=True, wall_limit_s=10 * START_S,
                          progress=lambda s: None)
        assert res["converged"] and res["learned_frequency_hz"] == pytest.approx(stream.frequency_hz,
                                                                                 rel=0.01), res
        # it stood to take over, then steps off (the steps grow from α 0 at the governor's 0.05/s after a
        # stop: 0.046 m in 10 s measured; test_live_teaching.py walks 60 s of it in-process)
        assert res["took_over"] and not res["fell"] and res["walked_s"] >= 6.0, res
        saved = storage.load(tmp_path / "slow.yaml")
        assert saved.gait_frequency_hz() == pytest.approx(res["learned_frequency_hz"], rel=1e-5)
    finally:
        interrupt_group(graph)
        kill_nodes(domain)
        lock.close()
        log.close()
    stats = json.loads((tmp_path / "logs" / "cpg_node.stats.json").read_text())["teaching"]
    assert stats["took_over"] == 1 and stats["received"] > 10_000 and stats["result"]["teaching"] == 2
