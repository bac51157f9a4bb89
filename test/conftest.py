"""Fixtures of the multi-process ROS tests (test_ros_*.py): a node graph on its own random quiet DDS
domain (1..101, localhost discovery) whose processes are all stopped at teardown even when the test
fails, and a probe node on that domain (ros_helpers.Probe)."""

from __future__ import annotations

import pytest


@pytest.fixture
def graph(tmp_path, monkeypatch):
    from cpg_walker.nodes.graph import Graph

    g = Graph(tmp_path / "logs")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(g.domain_id))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    yield g
    g.stop_all(timeout=5.0)
    for proc in g.procs.values():
        assert proc.popen.poll() is not None, f"{proc.name} survived the teardown"


@pytest.fixture
def probe(graph):
    from ros_helpers import Probe

    p = Probe(graph.domain_id)
    yield p
    p.close()
