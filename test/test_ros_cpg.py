"""cpg_node through real processes over DDS: parameter validation through the parameter service, the
/joint_targets, /cpg/state and /diagnostics it publishes, and a short lockstep walk through the three-node
graph. Each test on its own random domain (1..101), localhost discovery; every process stopped by the
fixture even on failure."""

from __future__ import annotations

import math

import pytest

from cpg_walker.cpg.humanoid import DOFS
from cpg_walker.experiments.walk_graph import WalkGraph

pytestmark = [pytest.mark.ros, pytest.mark.slow]


@pytest.fixture
def graph(tmp_path, monkeypatch):
    g = WalkGraph(tmp_path / "logs")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(g.domain_id))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    yield g
    g.stop_all(timeout=5.0)
    for proc in g.procs.values():
        assert proc.popen.poll() is not None, f"{proc.name} survived the teardown"


@pytest.fixture
def probe(graph):
    from test_ros_graph import Probe

    p = Probe(graph.domain_id)
    yield p
    p.close()


def test_modulation_parameters_validated_through_the_service(graph, probe):
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import GetParameters, SetParameters

    graph.start("cpg_node")
    client = probe.node.create_client(SetParameters, "/cpg/set_parameters")
    assert client.wait_for_service(timeout_sec=30.0), graph.procs["cpg_node"].log()

    def set_param(name: str, value: ParameterValue):
        future = client.call_async(SetParameters.Request(parameters=[Parameter(name=name, value=value)]))
        assert probe.spin_for(10.0, until=future.done)
        return future.result().results[0]

    def double(x: float) -> ParameterValue:
        return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=x)

    for name, bad in (("zeta", math.nan), ("alpha", math.nan), ("zeta", 2.5), ("zeta", -3.0),
                      ("alpha", -0.1), ("alpha", 2.01)):
        result = set_param(name, double(bad))
        assert not result.successful and name in result.reason, (name, bad, result.reason)
    wrong = set_param("zeta", ParameterValue(type=ParameterType.PARAMETER_STRING, string_value="fast"))
    assert not wrong.successful and wrong.reason
    assert set_param("zeta", double(0.8)).successful
    assert set_param("alpha", double(1.2)).successful
    get = probe.node.create_client(GetParameters, "/cpg/get_parameters")
    assert get.wait_for_service(timeout_sec=10.0)
    future = get.call_async(GetParameters.Request(names=["zeta", "alpha"]))
    assert probe.spin_for(10.0, until=future.done)
    assert [v.double_value for v in future.result().values] == [0.8, 1.2]
    assert "commanded zeta=0.8" in graph.procs["cpg_node"].log()


def test_corrupt_cpg_file_is_a_clear_error(graph, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("schema_version: 1\ndofs: [\n")
    graph.start("cpg_node", cpg_file=str(bad))
    assert graph.wait("cpg_node", 60) == 2
    log = graph.procs["cpg_node"].log()
    assert "bad.yaml" in log and "Traceback" not in log


def test_targets_state_and_diagnostics_published(graph, probe):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    for topic, kind in (("/joint_targets", JointState), ("/cpg/state", Float64MultiArray),
                        ("/diagnostics", DiagnosticArray)):
        probe.listen(topic, kind, 200)
    graph.start("pid_node", lockstep=True, wait_for_targets=True)
    cpg = graph.start("cpg_node")
    pubs = lambda: probe.node.count_publishers("/cpg/state") > 0  # noqa: E731
    assert probe.spin_for(30.0, until=pubs), cpg.log()  # matched before the clock starts
    graph.start("sim_node", pacing="lockstep", duration=30.0)
    got = probe.received
    assert probe.spin_for(60.0, until=lambda: len(got["/cpg/state"]) >= 3 and sum(
        s.name == "cpg_walker/cpg" for _, m in got["/diagnostics"] for s in m.status) >= 3), \
        graph.procs["cpg_node"].log()
    target = got["/joint_targets"][-1][1]
    assert set(DOFS) <= set(target.name)
    assert len(target.position) == len(target.velocity) == len(target.name)
    assert all(math.isfinite(x) for x in target.position)
    state = got["/cpg/state"][-1][1]
    sizes = [d.size for d in state.layout.dim]
    assert sizes[0] == len(DOFS) and sizes[2] == 3 and len(state.data) == sizes[0] * sizes[1] * 3
    assert state.layout.dim[0].label == "dof:" + ",".join(DOFS)
    status = [s for _, m in got["/diagnostics"] for s in m.status if s.name == "cpg_walker/cpg"][-1]
    values = {kv.key: kv.value for kv in status.values}
    assert values["state"] in ("starting", "walking") and float(values["zeta"]) == 1.0
    assert int(values["n_oscillators"]) == sizes[1] - 1


def test_short_lockstep_walk_through_the_graph(tmp_path):
    from cpg_walker.experiments.walk_graph import run_graph_walk

    report = run_graph_walk(tmp_path / "walk", duration=15.0)
    assert not report["fell"], report
    assert report["distance_m"] > 0.5, report  # the opening steps, then ~8 s of CPG walking
    assert report["zeta"] == 1.0 and report["feedback"] is False
    assert (tmp_path / "walk" / "walk.json").exists()
