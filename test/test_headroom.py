"""The sim/controller nodes' cheaper per-period work computes and publishes exactly what it did: the
serialized message builders against messages built field by field, the sole wrenches against the numpy
loop they replaced (on a walk's contact states), and the scheduling helper's fallback."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from cpg_walker.robot.joints import JOINT_NAMES


def _flat(msg, prefix: str = "") -> dict[str, object]:
    """Every leaf field of a ROS message by path; floats as their 8 bytes (bit-exact, -0.0 != 0.0)."""
    out: dict[str, object] = {}
    for name in msg.get_fields_and_field_types():
        value = getattr(msg, name)
        path = f"{prefix}{name}"
        if hasattr(value, "get_fields_and_field_types"):
            out.update(_flat(value, path + "."))
        elif isinstance(value, float):
            out[path] = struct.pack("<d", value)
        elif isinstance(value, str | int | bool):
            out[path] = value
        else:  # a sequence or array
            items = list(value)
            out[path] = [struct.pack("<d", v) if isinstance(v, float) else v for v in items]
    return out


def _same(raw: bytes, reference) -> None:
    from rclpy.serialization import deserialize_message

    got = deserialize_message(raw, type(reference))
    assert _flat(got) == _flat(reference)


def _values(rng, n: int) -> np.ndarray:
    """Random doubles with the awkward ones in: -0.0, 0.0, huge, tiny, negative."""
    v = rng.normal(size=n) * 10.0 ** rng.integers(-300, 300, size=n)
    v[: min(n, 2)] = (-0.0, 0.0)[: min(n, 2)]
    return rng.permutation(v)


STAMPS = [0, 1, 999_999_999, 1_234_567_891_011, 2**31 * 1_000_000_000 - 1]


FIELD_SETS = [("position", "velocity", "effort"), ("position", "velocity"), ("effort",)]


@pytest.mark.parametrize("fields", FIELD_SETS)
def test_serialized_joint_states_equal_messages_built_field_by_field(fields):
    from sensor_msgs.msg import JointState

    from cpg_walker.nodes.messages import JointStateBuilder

    rng = np.random.default_rng(len(fields))
    b = JointStateBuilder(JOINT_NAMES, fields=fields)
    ref = JointState(name=list(JOINT_NAMES))
    for k, ns in enumerate(STAMPS):
        given = {f: _values(rng, len(JOINT_NAMES)) for f in fields if k == 0 or rng.random() < 0.6}
        raw = b.fill(ns, **given)
        ref.header.stamp.sec, ref.header.stamp.nanosec = divmod(ns, 1_000_000_000)
        for f, v in given.items():  # arrays not given keep their last values
            setattr(ref, f, v.tolist())
        _same(raw, ref)
        assert b.msg == raw
    with pytest.raises(ValueError, match="has 3 values, expected 25"):
        b.fill(0, **{fields[0]: np.zeros(3)})
    if "position" not in fields:
        with pytest.raises(ValueError, match="not position"):
            b.fill(0, position=np.zeros(len(JOINT_NAMES)))


def test_serialized_sensor_messages_equal_messages_built_field_by_field():
    from geometry_msgs.msg import WrenchStamped
    from nav_msgs.msg import Odometry
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Imu

    from cpg_walker.nodes.messages import ClockBuilder, ImuBuilder, OdometryBuilder, WrenchBuilder

    rng = np.random.default_rng(7)
    clock, imu = ClockBuilder(), ImuBuilder("imu", 1e-9, 2e-6, 3e-4)
    wrench, odom = WrenchBuilder("l_sole"), OdometryBuilder()
    for ns in STAMPS:
        sec, nsec = divmod(ns, 1_000_000_000)
        c = Clock()
        c.clock.sec, c.clock.nanosec = sec, nsec
        _same(clock.fill(ns), c)

        g, a, q = _values(rng, 3), _values(rng, 3), rng.normal(size=4)
        m = Imu()
        m.header.frame_id = "imu"
        m.header.stamp.sec, m.header.stamp.nanosec = sec, nsec
        m.orientation_covariance = [1e-9, 0.0, 0.0, 0.0, 1e-9, 0.0, 0.0, 0.0, 1e-9]
        m.angular_velocity_covariance = [2e-6, 0.0, 0.0, 0.0, 2e-6, 0.0, 0.0, 0.0, 2e-6]
        m.linear_acceleration_covariance = [3e-4, 0.0, 0.0, 0.0, 3e-4, 0.0, 0.0, 0.0, 3e-4]
        m.orientation.w, m.orientation.x, m.orientation.y, m.orientation.z = q.tolist()
        m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = g.tolist()
        m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z = a.tolist()
        _same(imu.fill(ns, g, a, q), m)

        f, t = _values(rng, 3), _values(rng, 3)
        w = WrenchStamped()
        w.header.frame_id = "l_sole"
        w.header.stamp.sec, w.header.stamp.nanosec = sec, nsec
        (w.wrench.force.x, w.wrench.force.y, w.wrench.force.z) = f.tolist()
        (w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z) = t.tolist()
        _same(wrench.fill(ns, f, t), w)

        pos, lin, ang = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat)
        o = Odometry()
        o.header.frame_id, o.child_frame_id = "odom", "base_link"
        o.header.stamp.sec, o.header.stamp.nanosec = sec, nsec
        pp, po = o.pose.pose.position, o.pose.pose.orientation
        pp.x, pp.y, pp.z = pos.tolist()
        po.w, po.x, po.y, po.z = quat.tolist()
        wq, xq, yq, zq = quat.tolist()
        R = np.array([[1 - 2 * (yq * yq + zq * zq), 2 * (xq * yq - wq * zq), 2 * (xq * zq + wq * yq)],
                      [2 * (xq * yq + wq * zq), 1 - 2 * (xq * xq + zq * zq), 2 * (yq * zq - wq * xq)],
                      [2 * (xq * zq - wq * yq), 2 * (yq * zq + wq * xq), 1 - 2 * (xq * xq + yq * yq)]])
        tl, ta = o.twist.twist.linear, o.twist.twist.angular
        tl.x, tl.y, tl.z = (R.T @ lin).tolist()  # twist in the base frame
        ta.x, ta.y, ta.z = (R.T @ ang).tolist()
        _same(odom.fill(ns, pos, quat, lin, ang), o)


def _sole_wrenches_numpy(sim) -> list[tuple[np.ndarray, np.ndarray]]:
    """The sole wrenches as sim_node computed them before (numpy per contact struct): the reference."""
    import mujoco

    from cpg_walker.robot.hoap2 import SOLES

    m, d = sim.model, sim.data
    out = []
    f6 = np.zeros(6)
    for name in SOLES:
        g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)
        force, torque = np.zeros(3), np.zeros(3)
        centre = d.geom_xpos[g]
        for i in range(d.ncon):
            c = d.contact[i]
            if c.geom1 != g and c.geom2 != g:
                continue
            mujoco.mj_contactForce(m, d, i, f6)
            fw = c.frame.reshape(3, 3).T @ f6[:3]
            if c.geom1 == g:
                fw = -fw
            force += fw
            r = c.pos - centre
            torque += (r[1] * fw[2] - r[2] * fw[1], r[2] * fw[0] - r[0] * fw[2], r[0] * fw[1] - r[1] * fw[0])
        R = d.geom_xmat[g].reshape(3, 3)
        out.append((R.T @ force, R.T @ torque))
    return out


def test_sole_wrenches_equal_the_numpy_loop_on_a_walks_contacts():
    from cpg_walker.robot.contact import sole_wrenches
    from cpg_walker.robot.gait_data import GaitPlayback, find_steady_cycle, load_gait
    from cpg_walker.robot.hoap2 import Hoap2Sim
    from cpg_walker.robot.pid import PidLaw

    sim, pid = Hoap2Sim(), PidLaw.from_config()
    gait = load_gait("walk")
    playback = GaitPlayback(gait, cycle=find_steady_cycle(gait))
    dt = 0.002
    contacts: set[tuple[int, int]] = set()  # (contacts on the left sole, on the right) seen
    for k in range(int(8.0 / dt)):  # the recorded walk's opening steps and two strides
        q, qd = playback.targets(k * dt)
        sim.step(pid.step(q, qd, sim.joint_positions(), sim.joint_velocities(), dt), round(dt / sim.dt))
        if k % 2:
            continue
        new, ref = sole_wrenches(sim), _sole_wrenches_numpy(sim)
        for (f, t), (fr, tr) in zip(new, ref, strict=True):
            assert f.tobytes() == fr.tobytes() and t.tobytes() == tr.tobytes(), f"at {k * dt:.3f} s"
        g1, g2 = sim.data.contact.geom1, sim.data.contact.geom2
        contacts.add(tuple(int(np.sum((g1 == g) | (g2 == g))) for g in sim._sole_geoms))
    assert not sim.has_fallen()
    # the comparison covered double support, single support on each foot, and several contact counts
    assert any(a == 0 < b for a, b in contacts) and any(b == 0 < a for a, b in contacts)
    assert any(a > 0 and b > 0 for a, b in contacts) and len(contacts) >= 5


def test_a_command_of_every_joint_in_order_is_read_like_any_other():
    """The fast path (all joints in JOINT_NAMES order) gives what the per-name mapping gives, and still
    rejects non-finite values and wrong lengths."""
    from cpg_walker.nodes.validation import validate_joint_command

    rng = np.random.default_rng(3)
    pos, eff = rng.normal(size=len(JOINT_NAMES)), rng.normal(size=len(JOINT_NAMES))
    fast = validate_joint_command(JOINT_NAMES, pos, (), eff)
    perm = rng.permutation(len(JOINT_NAMES))
    slow = validate_joint_command([JOINT_NAMES[i] for i in perm], pos[perm], (), eff[perm])
    a, b = np.zeros(len(JOINT_NAMES)), np.zeros(len(JOINT_NAMES))
    a[fast.index], b[slow.index] = fast.position, slow.position
    np.testing.assert_array_equal(a, b)
    a[fast.index], b[slow.index] = fast.effort, slow.effort
    np.testing.assert_array_equal(a, b)
    assert fast.velocity is None and fast.index.tolist() == list(range(len(JOINT_NAMES)))
    bad = pos.copy()
    bad[4] = math.nan
    with pytest.raises(ValueError, match=f"non-finite position for joint\\(s\\) \\['{JOINT_NAMES[4]}'\\]"):
        validate_joint_command(JOINT_NAMES, bad)
    with pytest.raises(ValueError, match="effort has 3 values for 25 joint names"):
        validate_joint_command(JOINT_NAMES, pos, (), eff[:3])


class _Logger:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def info(self, text: str) -> None:
        self.lines.append(text)


class _Node:
    def __init__(self) -> None:
        self.logger = _Logger()

    def get_logger(self) -> _Logger:
        return self.logger


def test_scheduling_not_permitted_falls_back_to_normal_with_one_info_line(monkeypatch):
    import os

    from cpg_walker.nodes.runtime import apply_scheduling

    def refuse(*_args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    monkeypatch.setattr(os, "setpriority", refuse)
    monkeypatch.setattr(os, "sched_setaffinity", refuse)
    node = _Node()
    text = apply_scheduling(node, {"realtime_priority": 20, "nice": -10, "cpu_affinity": [0]})
    assert node.logger.lines == [text]
    assert text.startswith("scheduling: normal (SCHED_FIFO not permitted (PermissionError); "
                           "nice -10 not permitted (PermissionError); CPU affinity [0] not applied")


def test_scheduling_off_changes_nothing(monkeypatch):
    import os

    from cpg_walker.nodes.runtime import apply_scheduling

    def forbidden(*_args):
        raise AssertionError("must not be called")

    for name in ("sched_setscheduler", "setpriority", "sched_setaffinity"):
        monkeypatch.setattr(os, name, forbidden)
    node = _Node()
    assert apply_scheduling(node, {"realtime_priority": 0, "nice": 0, "cpu_affinity": []}) == \
        "scheduling: normal"


@pytest.mark.parametrize("mask, cpus", [(0, []), (1, [0]), (2, [1]), (3, [0, 1]), (0b10100, [2, 4])])
def test_cpu_affinity_mask(mask, cpus):
    from cpg_walker.nodes.runtime import cpus_of_mask

    assert cpus_of_mask(mask) == cpus


def _wait_for(predicate, timeout: float) -> bool:
    import time

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.1)
    return False


def _policy(pid: int) -> tuple[int, int]:
    """(scheduling policy, real-time priority) of a thread, from /proc/<pid>/stat."""
    from pathlib import Path

    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return int(fields[38]), int(fields[37])  # policy, rt_priority (fields 41 and 40 of stat)


def test_live_nodes_apply_their_scheduling_or_say_why_not(graph):
    """pid_node with a real-time priority and a CPU: its loop thread runs SCHED_FIFO at that priority on
    that CPU, or its one info line says it was not permitted; sim_node in fast pacing keeps normal
    scheduling (no wall-clock schedule to keep) but still takes the affinity."""
    import os
    from pathlib import Path

    pid = graph.start("pid_node", realtime_priority=7, nice=0, cpu_affinity=1)
    sim = graph.start("sim_node", pacing="fast", realtime_priority=7, nice=0, cpu_affinity=1)
    for proc in (pid, sim):
        assert _wait_for(lambda p=proc: "scheduling:" in p.log(), 60.0), proc.log()[-2000:]
    line = next(x for x in pid.log().splitlines() if "scheduling:" in x)
    if "SCHED_FIFO priority 7" in line:
        assert _policy(pid.pid) == (os.SCHED_FIFO, 7)
    else:
        assert "SCHED_FIFO not permitted" in line
    line = next(x for x in sim.log().splitlines() if "scheduling:" in x)
    assert "SCHED_FIFO" not in line and _policy(sim.pid) == (os.SCHED_OTHER, 0)
    for proc in (pid, sim):
        status = Path(f"/proc/{proc.pid}/status").read_text()
        allowed = next(x for x in status.splitlines() if x.startswith("Cpus_allowed_list"))
        assert allowed.split()[-1] == "0" or "not applied" in proc.log()
        assert proc.popen.poll() is None
