"""The horizon of future targets and riding out a gap in the live ones (no ROS): the CPG's forecast
(CPGNetwork / HumanoidCPG / CPGGaitSource.forecast) against the future it then has, its validation as a
trajectory, robot/trajectory.py's GapBridge (live -> horizon -> standing crouch -> live, C¹), and the
walking HOAP-2 through a gap in the in-process loop."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from cpg_walker.cpg.network import CPGNetwork, CPGParams
from cpg_walker.nodes.validation import validate_joint_trajectory
from cpg_walker.paths import ros_parameters
from cpg_walker.robot.joints import JOINT_NAMES
from cpg_walker.robot.trajectory import HORIZON, LIVE, SAFE, GapBridge, OffsetBlend, Trajectory, hermite
from cpg_walker.walker.gait_source import CPGGaitSource
from cpg_walker.walker.learning import load_controller

_CPG = ros_parameters("cpg.yaml", "cpg")
H_S, STEP_S = _CPG["horizon"], _CPG["horizon_step"]  # cpg_node's horizon
OFFSETS = np.round(np.arange(0.0, H_S + 1e-9, STEP_S), 9)


def _copy(obj, net):
    """A deep copy of a controller/source (the network's compiled-kernel module is shared, not copied)."""
    return copy.deepcopy(obj, {id(net._kern): net._kern})


@pytest.fixture
def source() -> CPGGaitSource:
    ctrl, _, _ = load_controller("cpg_humanoid.yaml")
    return CPGGaitSource(ctrl)


# ------------------------------------------------------------------------------------------ forecast
@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_network_forecast_is_the_future_the_network_then_has(backend):
    """On the stepping grid the forecast is the stepped network (same RK4 steps); on a coarse grid it is
    within RK4's error at the coarser step (split to the guard: here 20 ms, ω·h up to 0.32)."""
    if backend == "numba":
        pytest.importorskip("numba")
    rng = np.random.default_rng(1)
    net = CPGNetwork(rng.uniform(5, 40, (3, 2)), CPGParams(), x0=1.0, alpha0=rng.uniform(0.2, 1, (3, 2)),
                     time_scale=0.5, offset=[0.1, -0.2, 0.3], gain=[1.0, 2.0, 0.5], backend=backend)
    net.couple_cpgs(1, 0, phase_offset=0.7)
    net.freeze()
    net.set_frequency_scale(0.8)
    h = 0.002
    for _ in range(200):  # onto the limit cycle
        net.step(h)
    before = net.state.copy()
    n, every = round(H_S / h), round(STEP_S / h)
    fine = net.forecast(np.arange(n + 1) * h)
    coarse = net.forecast(OFFSETS)
    np.testing.assert_array_equal(net.state, before)  # the network is not changed
    deriv = np.empty((2, net.B, net.N))
    for k in range(n + 1):
        if k:
            net.step(h)
        net.playback_derivative(deriv)
        qd = net.gain * np.einsum("bi,bi->b", net.alpha, deriv[0])
        np.testing.assert_allclose(fine[0][k], net.output(), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(fine[1][k], qd, rtol=1e-12, atol=1e-12)
        if k % every == 0:
            swing = np.abs(fine[1]).max()
            np.testing.assert_allclose(coarse[0][k // every], net.output(), atol=5e-4 * swing * H_S)
            np.testing.assert_allclose(coarse[1][k // every], qd, atol=1e-3 * swing)


def test_network_forecast_rejects_bad_offsets():
    net = CPGNetwork(np.array([[10.0, 20.0]]), CPGParams())
    with pytest.raises(ValueError, match="frozen"):
        net.forecast([0.0, 0.1])
    net.freeze()
    for bad in ([], [0.1, 0.05], [-0.1, 0.0], [0.0, np.nan]):
        with pytest.raises(ValueError, match="offsets"):
            net.forecast(bad)
    with pytest.raises(ValueError, match="zeta"):
        net.forecast([0.0, 0.1], zeta=[1.0])


@pytest.mark.parametrize("t0", [2.0, 5.4, 6.0, 9.0])  # recording, recording -> CPG, cross-fade, CPG
def test_source_forecast_matches_the_targets_it_then_gives(source, t0):
    """The forecast from t0 is the targets the source gives later (the recording exactly; the CPG up to
    RK4 at the horizon's step)."""
    source.targets(t0)
    times = t0 + OFFSETS
    q, qd = source.forecast(times)
    ahead = _copy(source, source.ctrl.net)
    exact = [ahead.targets(t) for t in times]
    np.testing.assert_allclose(q, [e[0] for e in exact], atol=1e-4)
    np.testing.assert_allclose(qd, [e[1] for e in exact], atol=1e-3)
    assert np.ptp(q[:, JOINT_NAMES.index("lleg_joint_4")]) > 0.02  # the knee moves over the horizon


def test_a_foreseen_stop_fades_the_steps_to_the_standing_posture(source):
    """``stop_fade`` is 1 up to the stop, then falls C² to 0 (and stays); a forecast with it equals the
    plain one where the fade is 1, ends in the gait's mean posture (α = 0: the offsets, velocity 0) where
    it is 0, and scales only the oscillating part in between; bad fades are refused."""
    from cpg_walker.walker.gait_source import stop_fade

    h_s, stop_s = 1.0, 3.0
    offs = np.round(np.arange(0.0, h_s + stop_s + 1e-9, STEP_S), 9)
    fade = stop_fade(offs, h_s, stop_s)
    assert np.all(fade[offs <= h_s] == 1.0) and fade[-1] == 0.0 and np.all(np.diff(fade) <= 0)
    np.testing.assert_allclose(stop_fade([h_s + 0.5 * stop_s], h_s, stop_s), [0.5])
    source.targets(9.0)
    times = 9.0 + offs
    q0, _ = source.forecast(times)
    q, qd = source.forecast(times, fade)
    ones = fade == 1.0
    np.testing.assert_allclose(q[ones], q0[ones], atol=1e-12)
    dofs = source._idx
    offset = source.ctrl.net.offset
    np.testing.assert_allclose(q[-1, dofs], offset, atol=1e-12)
    np.testing.assert_allclose(qd[-1, dofs], 0.0, atol=1e-12)
    mid = np.flatnonzero((fade > 0.2) & (fade < 0.8))
    np.testing.assert_allclose(q[mid][:, dofs] - offset, (q0[mid][:, dofs] - offset) * fade[mid, None],
                               atol=1e-9)
    with pytest.raises(ValueError, match="fade"):
        source.ctrl.forecast(offs, fade[:-1])
    with pytest.raises(ValueError, match="fade"):
        source.ctrl.forecast(offs, fade + 0.5)
    with pytest.raises(ValueError, match="stop_fade"):
        stop_fade(offs, h_s, -1.0)


def test_source_forecast_follows_a_modulation_command(source):
    """With ζ/α commands being reached, the forecast advances the command filters too."""
    source.targets(9.0)
    source.ctrl.set_zeta(0.8)
    source.ctrl.set_alpha(1.2)
    source.targets(9.002)
    times = 9.002 + OFFSETS
    q, _ = source.forecast(times)
    ahead = _copy(source, source.ctrl.net)
    exact = np.array([ahead.targets(t)[0] for t in times])
    err = np.abs(q - exact).max()
    assert err < 2e-3  # ζ held per 40 ms interval (at its middle) instead of moving per 2 ms step
    frozen = _copy(source, source.ctrl.net)  # without the filters' future the error is far larger
    frozen.ctrl.zeta_command, frozen.ctrl.alpha_command = frozen.ctrl.zeta, frozen.ctrl.alpha
    assert np.abs(frozen.forecast(times)[0] - exact).max() > 10 * err


def test_forecasts_leave_the_targets_bit_identical(source):
    """Forecasting (as cpg_node does every horizon_step) never changes the live targets: lockstep runs
    stay bit-identical with the horizon published."""
    plain = _copy(source, source.ctrl.net)
    for k in range(4000):  # 0 .. 8 s: the recording, the hand-over, the CPG
        t = k * 0.002
        a, b = source.targets(t), plain.targets(t)
        if k % 20 == 0:
            source.forecast(t + OFFSETS)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])


# ---------------------------------------------------------------------------------------- trajectory
def _traj(start_ns=1_000_000_000, n=11, step_ns=40_000_000, w=3.0):
    offs = np.arange(n, dtype=np.int64) * step_ns
    t = (start_ns + offs) * 1e-9
    q = np.sin(w * t)[:, None] * np.ones((1, 2))
    qd = w * np.cos(w * t)[:, None] * np.ones((1, 2))
    return validate_joint_trajectory(["lleg_joint_4", "head_joint_1"], start_ns, offs, q, qd)


def test_trajectory_validation_rejects_bad_horizons():
    names = ["lleg_joint_4", "head_joint_1"]
    good = dict(start_ns=0, offsets_ns=[0, 10], positions=[[0, 0], [1, 1]], velocities=[[], []])
    traj = validate_joint_trajectory(names, **good)
    np.testing.assert_allclose(traj.qd, [[1e8, 1e8], [1e8, 1e8]])  # finite differences without velocities
    np.testing.assert_array_equal(traj.index, [JOINT_NAMES.index(n) for n in names])
    for change, reason in (({"offsets_ns": []}, "no trajectory points"),
                           ({"offsets_ns": [10, 10]}, "strictly increasing"),
                           ({"offsets_ns": [-1, 10]}, "strictly increasing"),
                           ({"positions": [[0, 0], [1]]}, "positions"),
                           ({"positions": [[0, 0], [1, np.inf]]}, "non-finite positions"),
                           ({"velocities": [[0, 0], []]}, "velocities")):
        with pytest.raises(ValueError, match=reason):
            validate_joint_trajectory(names, **{**good, **change})
    with pytest.raises(ValueError, match="unknown joint"):
        validate_joint_trajectory(["knee"], 0, [0], [[0.0]], [[]])


def test_hermite_and_trajectory_sampling():
    ends = [np.array([x]) for x in (1.0, -2.0, 3.0, 0.5)]
    for s, expected in ((0.0, (1.0, -2.0)), (2.0, (3.0, 0.5))):  # the end points and their slopes
        assert tuple(float(x[0]) for x in hermite(s, 2.0, *ends)) == pytest.approx(expected)
    cubic = lambda s: (s**3 - s, 3 * s**2 - 1)  # noqa: E731  Hermite is exact for a cubic
    qh, vh = hermite(0.3, 1.0, *(np.array([x]) for x in (*cubic(0.0), *cubic(1.0))))
    assert (qh[0], vh[0]) == pytest.approx(cubic(0.3))
    traj = _traj()
    for t_ns in range(traj.first_ns, traj.end_ns, 7_000_001):
        q, v = traj.sample(t_ns)
        assert q == pytest.approx(np.sin(3 * t_ns * 1e-9), abs=2e-6)  # 40 ms points, 3 rad/s
        assert v == pytest.approx(3 * np.cos(3 * t_ns * 1e-9), abs=1e-4)
    assert traj.covers(traj.end_ns) and not traj.covers(traj.end_ns + 1)
    np.testing.assert_array_equal(traj.sample(traj.first_ns - 5)[0], traj.q[0])
    q_after, _ = traj.sample(traj.end_ns + 2_000_000)
    np.testing.assert_allclose(q_after, traj.q[-1] + 0.002 * traj.qd[-1])


def test_offset_blend_is_c1_and_ends_at_zero():
    d, dv = np.array([0.3, -0.1]), np.array([2.0, 0.0])
    blend = OffsetBlend(1_000, d, dv, 0.5)
    q0, v0 = blend.at(1_000)
    np.testing.assert_allclose(q0, d)
    np.testing.assert_allclose(v0, dv)
    ts = np.arange(1_000, blend.end_ns, 1_000_000)
    qs = np.array([blend.at(int(t))[0] for t in ts])
    vs = np.array([blend.at(int(t))[1] for t in ts])
    np.testing.assert_allclose(np.gradient(qs, 1e-3, axis=0)[1:-1], vs[1:-1], atol=2e-3)  # v = dq/dt
    q_end, v_end = blend.at(blend.end_ns - 1)  # 1 ns before the end: at rest at 0
    np.testing.assert_allclose(q_end, 0, atol=1e-9)
    np.testing.assert_allclose(v_end, 0, atol=1e-7)
    assert blend.at(blend.end_ns) is None


def _run_bridge(bridge, live_until_ns, resume_ns, end_ns, period_ns=2_000_000, w=3.0):
    """Drive a GapBridge with live targets sin(w t) (all 25 joints) that stop at live_until and come
    back at resume; return times, references, velocities and modes."""
    rows = []
    live_ns = None
    for t_ns in range(0, end_ns, period_ns):
        if t_ns <= live_until_ns or t_ns >= resume_ns:
            t = t_ns * 1e-9
            live_q, live_v, live_ns = np.full(25, np.sin(w * t)), np.full(25, w * np.cos(w * t)), t_ns
            if t_ns % 40_000_000 == 0:  # the source's horizon, every 40 ms
                offs = np.arange(11, dtype=np.int64) * 40_000_000
                tt = (t_ns + offs) * 1e-9
                bridge.offer(validate_joint_trajectory(
                    JOINT_NAMES, t_ns, offs, np.sin(w * tt)[:, None] * np.ones(25),
                    (w * np.cos(w * tt))[:, None] * np.ones(25)))
        q, v = bridge.reference(t_ns, live_q, live_v, live_ns)
        rows.append((t_ns, q.copy(), v.copy(), bridge.mode))
    return rows


def test_gap_bridge_rides_a_short_gap_on_the_horizon():
    bridge = GapBridge(np.zeros(25), safe_blend_s=0.5, resume_blend_s=0.2)
    rows = _run_bridge(bridge, live_until_ns=1_002_000_000, resume_ns=1_302_000_000, end_ns=2_000_000_000)
    modes = [m for *_, m in rows]
    assert modes.count(HORIZON) == 149 and SAFE not in modes  # the 0.3 s gap, all on the horizon
    for t_ns, q, v, _ in rows:  # the reference is the signal itself, through the gap and after it
        assert q[0] == pytest.approx(np.sin(3 * t_ns * 1e-9), abs=1e-5)  # (Hermite between 40 ms points)
        assert v[0] == pytest.approx(3 * np.cos(3 * t_ns * 1e-9), abs=1e-4)
    assert rows[-1][3] == LIVE


def test_gap_bridge_ends_a_long_gap_in_the_safe_posture_and_resumes_c1():
    safe = np.full(25, -0.5)
    bridge = GapBridge(safe, safe_blend_s=0.5, resume_blend_s=0.3)
    period = 2_000_000
    rows = _run_bridge(bridge, live_until_ns=1_000_000_000, resume_ns=3_000_000_000, end_ns=4_000_000_000)
    t = np.array([r[0] for r in rows]) * 1e-9
    q = np.array([r[1][0] for r in rows])
    v = np.array([r[2][0] for r in rows])
    modes = [r[3] for r in rows]
    first_safe = modes.index(SAFE)
    assert t[first_safe] == pytest.approx(1.0 + 0.4 + 0.002)  # the 0.4 s horizon ran out at 1.4 s
    at_rest = (t >= t[first_safe] + 0.5) & (t < 3.0)
    np.testing.assert_allclose(q[at_rest], -0.5)  # the standing posture, reached in safe_blend
    np.testing.assert_allclose(v[at_rest], 0.0, atol=1e-12)
    back = t >= 3.0 + 0.3
    np.testing.assert_allclose(q[back], np.sin(3 * t[back]))  # the live targets again after resume_blend
    assert modes[-1] == LIVE
    # C¹: the reference's velocity is its derivative everywhere (no jump in q or in v at the switches)
    dq = np.diff(q) / (period * 1e-9)
    np.testing.assert_allclose(dq, 0.5 * (v[1:] + v[:-1]), atol=0.05)
    assert np.abs(np.diff(v)).max() < 0.3  # 2 ms apart: no velocity step (without the blends: 1.5, 2.7)


def test_gap_bridge_is_inactive_without_a_trajectory():
    bridge = GapBridge(np.zeros(25), 0.5, 0.2)
    live_q, live_v = np.ones(25), np.zeros(25)
    q, v = bridge.reference(5_000_000_000, live_q, live_v, 1_000_000_000)  # stale, but nothing to follow
    assert q is live_q and v is live_v and not bridge.active and bridge.mode == LIVE


def test_gap_bridge_moves_onto_a_newer_horizon_smoothly():
    bridge = GapBridge(np.zeros(25), 0.5, 0.2)
    idx = np.arange(25)
    old = Trajectory(0, np.array([0, 400_000_000]), idx, np.zeros((2, 25)), np.zeros((2, 25)))
    bridge.offer(old)
    live = (np.zeros(25), np.zeros(25))
    bridge.reference(10_000_000, *live, 0)
    assert bridge.mode == HORIZON and bridge.trajectory is old
    new = Trajectory(12_000_000, np.array([0, 400_000_000]), idx, np.ones((2, 25)) * 0.1, np.zeros((2, 25)))
    bridge.offer(new)
    bridge.offer(old)  # an older one arriving late is ignored
    q, _ = bridge.reference(12_000_000, *live, 0)
    assert bridge.trajectory is new and bridge.switched == (HORIZON, HORIZON)
    assert q[0] == pytest.approx(0.0)  # starts where the old horizon was, then blends onto the new one
    q, _ = bridge.reference(12_000_000 + 200_000_000, *live, 0)
    assert q[0] == pytest.approx(0.1)


# -------------------------------------------------------------------------- the robot through a gap
class _GappedSource:
    """The CPG source as pid_node sees it through a gap [t0, t1) in the live targets: the live targets
    freeze, the horizon published every STEP_S before it is all there is (the in-process loop)."""

    names = JOINT_NAMES

    def __init__(self, source: CPGGaitSource, gap: tuple[float, float], bridge: GapBridge | None):
        self.source, self.gap, self.bridge = source, gap, bridge
        self.live = None
        self.next_horizon = 0.0
        self.modes: set[str] = set()

    def targets(self, t: float):
        t_ns = round(t * 1e9)
        in_gap = self.gap[0] <= t < self.gap[1]
        if not in_gap:
            q, v = self.source.targets(t)
            self.live = (q, v, t_ns)
            if self.bridge is not None and t >= self.next_horizon - 1e-9:
                q_h, v_h = self.source.forecast(t + OFFSETS)
                offs = np.round(OFFSETS * 1e9).astype(np.int64)
                self.bridge.offer(validate_joint_trajectory(JOINT_NAMES, t_ns, offs, q_h, v_h))
                self.next_horizon = t + STEP_S
        q, v, live_ns = self.live
        if self.bridge is None:  # the former watchdog: hold the last target posture
            return q, (np.zeros_like(v) if in_gap else v)
        out = self.bridge.reference(t_ns, q, v, live_ns)
        self.modes.add(self.bridge.mode)
        return out


@pytest.mark.slow
@pytest.mark.parametrize(("gap_at", "horizon"), [(8.75, True), (10.0, True), (10.0, False)])
def test_the_walking_robot_rides_out_a_gap_on_the_horizon(gap_at, horizon):
    """A 0.3 s gap in the live CPG targets mid-stride: on the horizon the robot walks on (and after the
    gap); holding the last target instead (the former watchdog) fells it at these two phases of the
    stride (of 11 start times 8.0, 8.25, ..., 10.5 s a 0.2 s hold felled it at 4, the horizon at none)."""
    from cpg_walker.robot.hoap2 import Hoap2Sim, default_standing_posture
    from cpg_walker.robot.pid import PidLaw, load_pid_config
    from cpg_walker.walker.loop import run_replay

    ctrl, _, _ = load_controller("cpg_humanoid.yaml")
    cfg = load_pid_config()
    bridge = None
    if horizon:
        bridge = GapBridge(default_standing_posture(), cfg["safe_blend"], cfg["resume_blend"])
    gap_s = 0.3
    gapped = _GappedSource(CPGGaitSource(ctrl), (gap_at, gap_at + gap_s), bridge)
    sim = Hoap2Sim()
    sim.reset()
    run = run_replay(sim, gapped, PidLaw.from_config(config=cfg), duration=gap_at + gap_s + 6.0)
    if not horizon:
        assert run.fell, "the control case: without the horizon this gap fells the robot"
        return
    assert not run.fell, run.fall_time_s
    assert gapped.modes == {LIVE, HORIZON}
    after = run.base_xy[run.t > gap_at + gap_s + 2.0]
    assert np.linalg.norm(after[-1] - after[0]) > 0.2  # walking on after the gap (0.075 m/s)


@pytest.mark.slow
@pytest.mark.parametrize("horizon_stop", [None, 0.0])
def test_a_lost_cpg_node_stops_the_robot_on_the_horizon_then_crouches(horizon_stop):
    """cpg_node lost for good at 9.0 s (the moment a fresh-clone CI run's graph fell; in-process it
    falls at the same 11.37 s): pid_node follows its last horizon to the end, then blends to the crouch.
    With the horizon's foreseen stop (config/cpg.yaml's horizon_stop) the robot stands through it all;
    the control case without one (the crouch from the horizon's mid-stride end) falls."""
    from cpg_walker.experiments.fault_phases import run_cpg_loss_one

    run = run_cpg_loss_one(9.0, horizon_stop)
    if horizon_stop == 0.0:
        assert run["fell"], "the control case: without the foreseen stop this loss fells the robot"
    else:
        assert run["horizon_stop_s"] > 0 and not run["fell"], run
