"""Fixtures of the multi-process ROS tests (test_ros_*.py, marker ``ros``): every such test gets a DDS
domain of its own (``ros_domain``: reserved machine-wide with a lock file, so test runs side by side never
share one; localhost discovery) on which every graph it starts runs, a node graph whose processes are all
stopped at teardown even when the test fails (``graph``), and a probe node on that domain (``probe``).
Helpers and the deadlines: ros_helpers.py."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def ros_domain(request, monkeypatch):
    """For a ``ros`` test: the reserved domain, in ROS_DOMAIN_ID for the processes (and the CLI tools) it
    starts, and the one ``Graph`` picks (``graph.quiet_domain_id``) for the graphs the code under test
    starts itself; at teardown no node of this run may be left on it. None for other tests."""
    if request.node.get_closest_marker("ros") is None:
        yield None
        return
    from ros_helpers import kill_nodes, reserve_domain

    import cpg_walker.graph.processes as graph_module

    domain, lock = reserve_domain()
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    monkeypatch.setattr(graph_module, "quiet_domain_id", lambda attempts=5: domain)
    try:
        yield domain
        left = kill_nodes(domain)
        assert not left, f"node processes left running on domain {domain} (killed): {left}"
    finally:
        kill_nodes(domain)
        lock.close()


@pytest.fixture
def graph(tmp_path, ros_domain):
    from cpg_walker.graph.processes import Graph

    g = Graph(tmp_path / "logs", domain_id=ros_domain)
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
