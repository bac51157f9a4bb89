"""cpg_node through real processes over DDS: parameter validation through the parameter service, the
/joint_targets, /cpg/state and /diagnostics it publishes, the 60 s lockstep walk through the three-node
graph (deterministic), and runtime zeta/alpha changes through the parameter service changing the gait.
Each test on a DDS domain of its own, localhost discovery; every process stopped by the fixtures
(conftest.py) even on failure. Waits are for conditions, with hang-guard deadlines (ros_helpers.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from ros_helpers import ANSWER_S, START_S, SimWatchdog, double, sim_deadline, string

from cpg_walker.graph.processes import read_stats, stats_path
from cpg_walker.nodes import interface as ifc
from cpg_walker.walker.controller import DOFS

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_modulation_parameters_validated_through_the_service(graph, probe):
    graph.start("cpg_node")
    for name, bad in (("zeta", math.nan), ("alpha", math.nan), ("zeta", 2.5), ("zeta", -3.0),
                      ("alpha", -0.1), ("alpha", 2.01)):
        result = probe.set_param("cpg", name, double(bad))
        assert not result.successful and name in result.reason, (name, bad, result.reason)
    wrong = probe.set_param("cpg", "zeta", string("fast"))
    assert not wrong.successful and wrong.reason
    # the range tells the truth: a step longer than any that walked is refused, with the reason
    from cpg_walker.walker.governor import GovernorConfig

    top = GovernorConfig.load().alpha_limit  # 1.4: the ankle envelope's fast corner
    longer = probe.set_param("cpg", "alpha", double(top + 0.1))
    assert not longer.successful and f"alpha must be in [0, {top:g}]" in longer.reason, longer.reason
    assert "longer steps fell at every zeta" in longer.reason
    assert probe.set_param("cpg", "zeta", double(0.8)).successful
    assert probe.set_param("cpg", "alpha", double(0.7)).successful
    assert [v.double_value for v in probe.get_params("cpg", ["zeta", "alpha"])] == [0.8, 0.7]
    assert "commanded zeta=0.8" in graph.procs["cpg_node"].log()


def test_without_the_governor_the_raw_cpg_takes_longer_steps(graph, probe):
    graph.start("cpg_node", governor=False, alpha=1.5)
    assert probe.set_param("cpg", "alpha", double(1.8)).successful
    refused = probe.set_param("cpg", "alpha", double(2.01))
    assert not refused.successful and "alpha must be in [0, 2]" in refused.reason, refused.reason
    assert [v.double_value for v in probe.get_params("cpg", ["alpha"])] == [1.8]


def test_corrupt_cpg_file_is_a_clear_error(graph, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("schema_version: 1\ndofs: [\n")
    graph.start("cpg_node", cpg_file=str(bad))
    assert graph.wait("cpg_node", START_S) == 2
    log = graph.procs["cpg_node"].log()
    assert "bad.yaml" in log and "Traceback" not in log


@pytest.mark.parametrize("params", [{"zeta": 3.0}, {"alpha": -0.5}, {"zeta": math.nan}, {"alpha": 1.5}])
def test_bad_start_up_modulation_is_a_clear_error(graph, params):
    graph.start("cpg_node", **params)
    assert graph.wait("cpg_node", START_S) == 2
    log = graph.procs["cpg_node"].log()
    assert "error" in log and next(iter(params)) in log and "Traceback" not in log, log


def test_targets_state_and_diagnostics_published(graph, probe):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    for topic, kind in ((ifc.JOINT_TARGETS, JointState), (ifc.CPG_STATE, Float64MultiArray),
                        (ifc.DIAGNOSTICS, DiagnosticArray)):
        probe.listen(topic, kind, 200)
    graph.start("pid_node", lockstep=True, wait_for_targets=True)
    cpg = graph.start("cpg_node")
    probe.wait_endpoints(ifc.JOINT_TARGETS, 1, 2)  # cpg -> pid (and the probe) before the clock starts
    probe.wait_endpoints(ifc.CLOCK, 0, 1)
    graph.start("sim_node", pacing="lockstep", duration=30.0)
    got = probe.received
    probe.wait(lambda: len(got[ifc.CPG_STATE]) >= 3 and sum(
        s.name == "cpg_walker/cpg" for _, m in got[ifc.DIAGNOSTICS] for s in m.status) >= 3,
        lambda: f"3 x /cpg/state and cpg diagnostics: {cpg.log()}", sim_deadline(0.5))
    target = got[ifc.JOINT_TARGETS][-1][1]
    assert set(DOFS) <= set(target.name)
    assert len(target.position) == len(target.velocity) == len(target.name)
    assert all(math.isfinite(x) for x in target.position)
    state = got[ifc.CPG_STATE][-1][1]
    sizes = [d.size for d in state.layout.dim]
    assert sizes[0] == len(DOFS) and sizes[2] == 3 and len(state.data) == sizes[0] * sizes[1] * 3
    assert state.layout.dim[0].label == "dof:" + ",".join(DOFS)
    status = [s for _, m in got[ifc.DIAGNOSTICS] for s in m.status if s.name == "cpg_walker/cpg"][-1]
    values = {kv.key: kv.value for kv in status.values}
    assert values["state"] in ("starting", "walking") and float(values["zeta"]) == 1.0
    assert int(values["n_oscillators"]) == sizes[1] - 1


def test_60s_lockstep_walk_is_deterministic(tmp_path, ros_domain):
    """60 s through sim_node + pid_node + cpg_node (feedback off: the open-loop CPG; with feedback:
    test_ros_feedback.py) without a fall; a second, 10 s run reproduces the first 10 s of it bit for bit
    (lockstep: every period's inputs are fixed by the stamps). However slowly the machine runs it: the
    watchdog only ends a run whose sim time stops advancing."""
    from cpg_walker.experiments.odometry import OdomWatcher
    from cpg_walker.experiments.walk_graph import run_graph_walk

    odom = OdomWatcher()  # odom_node's /odom beside /odom/ground_truth (test_odometry.py: in-process)
    with SimWatchdog(ros_domain):
        report = run_graph_walk(tmp_path / "walk60", duration=60.0, feedback=False,
                                timeout=sim_deadline(60.0), watchers=[odom])
    assert not report["fell"] and report["duration_s"] == pytest.approx(60.0, abs=0.02), report
    # 4.981 m measured (cpg-walker walk --duration 60 --feedback off; lockstep: the same every run), held
    # within the headline walks' 10 % (experiments/headline.py MARGINS)
    assert report["distance_m"] == pytest.approx(4.981, rel=0.1), report
    assert report["steps"] >= 40, report  # ~2 steps per 2.51 s stride
    assert report["zeta"] == 1.0 and report["feedback"] is False
    assert report["graph"]["torque_age_s"]["max"] == 0.0  # every period used its own command
    assert (tmp_path / "walk60" / "walk.json").exists()
    stats = read_stats(stats_path(tmp_path / "walk60" / "graph_logs", "cpg_node"))["tick"]
    assert stats["ticks"] == 30000  # one per control period (its wall timing: the benchmark's graph section)
    # odom_node, started by the graph: /odom every 10 ms in odom -> base_link, every sensor sample taken,
    # within 1 % of the distance (in-process walks measured 0.5-0.85 %, docs/odometry.md)
    odom_stats = read_stats(stats_path(tmp_path / "walk60" / "graph_logs", "odom_node"))
    assert odom_stats["samples"] == 30000 and odom_stats["published"] == 6000, odom_stats
    assert odom.frames == ("odom", "base_link") and odom.covariance[0] > 0
    drift = odom.compare(report["touchdowns_s"]["left"])
    assert drift["samples"] > 5000 and drift["start_offset_m"] < 0.001, drift
    assert drift["position_error_max_pct"] < 1.0 and drift["yaw_error_max_deg"] < 0.2, drift
    with SimWatchdog(ros_domain):
        run_graph_walk(tmp_path / "walk10", duration=10.0, feedback=False, timeout=sim_deadline(10.0))
    long, short = (json.loads((tmp_path / d / "graph_record.json").read_text()) for d in ("walk60", "walk10"))
    n = len(short["t"])
    assert n >= 1000 and short["t"] == long["t"][:n]  # 10 s of the 10 ms record
    np.testing.assert_array_equal(np.array(short["q"]), np.array(long["q"][:n]))  # bit-identical
    np.testing.assert_array_equal(np.array(short["base_xy"]), np.array(long["base_xy"][:n]))


def _diag(msg) -> tuple[float, dict] | None:
    """(stamp s, values) of a cpg_walker/cpg status in a DiagnosticArray, else None."""
    for s in msg.status:
        if s.name == "cpg_walker/cpg":
            t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            return t, {kv.key: kv.value for kv in s.values}
    return None


def test_runtime_zeta_and_alpha_change_the_gait(graph, probe, tmp_path):
    """zeta = 0.8 set through the parameter service mid-walk slows the stepping to the learned stride
    period / 0.8 (foot touchdowns in the sim's record, oscillator frequencies on /cpg/state); alpha = 0
    then collapses the CPG's oscillation: its joint targets settle on the offsets and the stepping stops.
    The sim runs on while the test reacts, so each phase is timed from the sim time at which the node's
    diagnostics show the command in effect, not from when it was sent."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64MultiArray

    from cpg_walker.experiments.replay_graph import record_to_result
    from cpg_walker.paths import config_path
    from cpg_walker.robot.run_record import RunRecord
    from cpg_walker.walker import storage

    period = storage.load(config_path("cpg_humanoid.yaml")).period  # learned stride period (2.513 s)
    t_zeta, settle, strides, settle_alpha = 7.0, 2.5, 4, 5.0  # sim s (the CPG has taken over at 6.6 s)
    probe.listen(ifc.CPG_STATE, Float64MultiArray, 500)
    probe.listen(ifc.DIAGNOSTICS, DiagnosticArray, 500)
    record = tmp_path / "record.json"
    graph.start("pid_node", lockstep=True, wait_for_targets=True, target_wait=ANSWER_S)
    cpg = graph.start("cpg_node")
    probe.wait_endpoints(ifc.JOINT_TARGETS)  # cpg -> pid before the clock starts
    probe.wait_endpoints(ifc.CLOCK, 0, 1)
    # ended by SIGINT once the test has seen enough (the sim writes its record at exit); 120 s: a cap
    graph.start("sim_node", pacing="lockstep", duration=120.0, record_path=str(record))
    diags = lambda: [d for _, m in probe.received[ifc.DIAGNOSTICS] if (d := _diag(m))]  # noqa: E731
    state = probe.received[ifc.CPG_STATE]

    def state_now() -> np.ndarray:
        m = state[-1][1]
        return np.array(m.data).reshape([d.size for d in m.layout.dim])

    def reach(t: float) -> None:
        probe.wait(lambda: bool(diags()) and diags()[-1][0] >= t,
                   lambda: f"sim time {t:.2f} s: {cpg.log()[-1500:]}", sim_deadline(t))

    def in_effect(key: str, value: str) -> float:
        """The sim time of the first diagnostics showing ``key`` = ``value``."""
        probe.wait(lambda: any(v[key] == value for _, v in diags()), f"{key} = {value} in the diagnostics")
        return min(t for t, v in diags() if v[key] == value)  # ± the 0.1 s monitor period

    reach(t_zeta)
    before = state_now()  # ζ = 1, α = 1: CPG walking
    assert probe.set_param("cpg", "zeta", 0.8).successful
    t_slow = in_effect("zeta_command", "0.8")
    reach(t_slow + settle + strides * period / 0.8)
    slowed = state_now()
    assert probe.set_param("cpg", "alpha", 0.0).successful
    t_stop = in_effect("alpha_requested", "0")  # the governor then brings the α command down (fall_rate)
    t_alpha = in_effect("alpha_command", "0")
    reach(t_alpha + settle_alpha)
    end = state_now()
    assert graph.stop("sim_node", timeout=ANSWER_S) == 0, graph.procs["sim_node"].log()[-1500:]
    n = end.shape[1] - 1
    # /cpg/state: every oscillator's frequency scaled by 0.8, the fundamental is 1 / stride period
    np.testing.assert_allclose(slowed[:, :n, 1] / before[:, :n, 1], 0.8, rtol=1e-3)
    # the lowest learned ω is the stride frequency (intrinsic ω: 0.3974 Hz vs 1 / 2.513 s = 0.3979 Hz)
    assert before[:, :n, 1].min() == pytest.approx(1.0 / period, rel=5e-3)
    # the sim's foot touchdowns: one per foot every period / 0.8 once the ζ filter has settled
    run = record_to_result(RunRecord.load(record))
    assert not run.fell
    for foot, times in run.touchdowns.items():
        t = np.array(times)
        intervals = np.diff(t[(t > t_slow + settle) & (t < t_stop)])
        assert len(intervals) >= 2, (foot, times)
        np.testing.assert_allclose(intervals, period / 0.8, rtol=0.03, err_msg=f"{foot}: {times}")
        assert not any(t > t_alpha + 3.0), (foot, times)  # α = 0: no more steps
    # α = 0: oscillator amplitudes and the targets' oscillating part gone, targets on the offsets
    amp_before = before[:, :n, 2].max()
    assert amp_before > 0.05 and end[:, :n, 2].max() < 1e-3 * amp_before
    swing_before = np.abs(before[:, n, 0] - before[:, n, 2]).max()
    assert swing_before > 0.05
    np.testing.assert_allclose(end[:, n, 0], end[:, n, 2], atol=1e-3 * swing_before)
    assert np.abs(end[:, n, 1]).max() < 1e-3  # target velocities ~ 0
