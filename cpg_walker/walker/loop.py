"""In-process replay: a target source drives the PID servos of the simulated HOAP-2 (no ROS).

The PID runs as an explicit torque law at ``rate_hz`` on joint state that is ``delay_s`` old, and its
torque is held between ticks - the way it runs as a ROS node. By default the rate is the sim node's (one
``control_period``, config/sim.yaml) and the delay one such period (the graph's round trip in real time).
The target source is pluggable: any object with ``names`` and ``targets(t) -> (q, qd)`` (the recorded
gait, a CPG). A source that also has ``observe(t, quat_wxyz, gyro, loads)`` gets, at every control tick
before ``targets(t)``, the chest IMU orientation quaternion (w, x, y, z) and angular velocity (rad/s) and
the (left, right) sole loads in N — the readings a ROS node gets from /imu and /foot_load (sensory
feedback, walker/feedback.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from cpg_walker.errors import InputError
from cpg_walker.paths import ros_parameters
from cpg_walker.robot.contact import TouchdownDetector
from cpg_walker.robot.hoap2 import Hoap2Sim
from cpg_walker.robot.joints import JOINT_NAMES
from cpg_walker.robot.pid import PidLaw

#: The sim node's name: its parameters file (config/sim.yaml) holds the control period this loop shares.
SIM_NODE = "sim"


def control_period() -> float:
    """s between PID ticks: sim_node's ``control_period`` (config/sim.yaml), the in-process loop's too."""
    return float(ros_parameters("sim.yaml", SIM_NODE)["control_period"])


class TargetSource(Protocol):
    names: tuple[str, ...]

    def targets(self, t: float) -> tuple[np.ndarray, np.ndarray]: ...


@dataclass
class ReplayResult:
    """Time series (every ``log_dt``) and contact events of one replay, plus the summary metrics."""

    t: np.ndarray
    base_xy: np.ndarray
    base_z: np.ndarray
    heading: np.ndarray
    loads: np.ndarray
    touchdowns: dict[str, list[float]]
    fell: bool
    fall_time_s: float | None
    duration_s: float
    metrics: dict = field(default_factory=dict)


def run_replay(
    sim: Hoap2Sim,
    source: TargetSource,
    pid: PidLaw,
    duration: float,
    rate_hz: float | None = None,
    delay_s: float | None = None,
    log_dt: float = 0.01,
    stop_on_fall: bool = True,
    progress=None,
    on_log=None,
) -> ReplayResult:
    """Run ``duration`` s from the current sim state (call ``sim.reset()`` first); see module docstring.

    ``on_log(sim)`` is called every ``log_dt`` (e.g. to render frames). ``rate_hz`` None: 1 /
    ``control_period()``; ``delay_s`` None: one control period."""
    if rate_hz is None or delay_s is None:
        period = control_period()
        rate_hz = 1.0 / period if rate_hz is None else rate_hz
        delay_s = period if delay_s is None else delay_s
    if not (duration > 0 and rate_hz > 0 and delay_s >= 0):
        raise ValueError("replay: duration and rate must be positive, delay non-negative")
    if tuple(source.names) != tuple(pid.names):
        raise ValueError("replay: the target source and the PID must cover the same joints in the same order")
    sel = np.array([JOINT_NAMES.index(n) for n in pid.names], dtype=int)
    all_joints = tuple(pid.names) == JOINT_NAMES
    qadr, dadr = sim._qadr[sel], sim._dadr[sel]
    dt = sim.dt
    per_tick = max(1, round(1.0 / (rate_hz * dt)))
    delay_steps = round(delay_s / dt)
    n_steps = round(duration / dt)
    log_every = max(1, round(log_dt / dt))
    t0 = sim.time
    rows_t, rows_xy, rows_z, rows_h, rows_l = [], [], [], [], []
    touch = TouchdownDetector()
    touch.update(0.0, sim.sole_loads())
    fell, fall_time = False, None
    tau_full = np.zeros(len(JOINT_NAMES))
    pid.reset()
    law = pid.stepper(per_tick * dt)  # checked once here; it refuses non-finite inputs by itself
    within = bool(np.all(pid.max_torque <= sim.max_torque[sel]))  # the law's clamp implies the motors'
    observe = getattr(source, "observe", None)
    targets = source.targets
    data, step, set_torque = sim.data, sim.step, sim.set_torque_unchecked
    qpos, qvel = data.qpos, data.qvel  # views of MuJoCo's buffers (fixed for the life of `data`)
    # Events happen at boundaries b (b physics steps done), in this order: a log sample (b > 0, a multiple
    # of log_every; it stops a fallen run), keeping the state (b = 0, or a state a later tick will see),
    # a control tick (b a multiple of per_tick, acting on the state of step max(0, b - delay_steps)).
    # Between boundaries the physics runs with the torque held, in one `sim.step` call.
    record_phase = -delay_steps % per_tick  # (b + delay_steps) % per_tick == 0: a tick will see b
    kept: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    b = 0
    while True:
        if b and b % log_every == 0:
            t = data.time - t0
            loads = sim.sole_loads()
            touch.update(t, loads)
            pos, _ = sim.base_pose()
            rows_t.append(t)
            rows_xy.append(pos[:2])
            rows_z.append(pos[2])
            rows_h.append(sim.heading())
            rows_l.append(loads)
            if on_log is not None:
                on_log(sim)
            if progress is not None:
                progress.update(t)
            if not fell and sim.has_fallen():
                fell, fall_time = True, t
                if stop_on_fall:
                    break
        if b >= n_steps:
            break
        if b == 0 or b % per_tick == record_phase:
            kept[b] = (qpos[qadr], qvel[dadr])  # fancy indexing copies
        if b % per_tick == 0:
            j = b - delay_steps
            q, v = kept.pop(j) if j > 0 else kept[0]
            if observe is not None:
                imu = sim.imu()
                observe(data.time - t0, imu.quat, imu.gyro, sim.sole_loads())
            qt, vt = targets(data.time - t0)
            if all_joints:
                set_torque(law(qt, vt, q, v), within)
            else:
                tau_full[sel] = law(qt, vt, q, v)
                set_torque(tau_full, within)
        nxt = min(b + per_tick - b % per_tick,  # next tick
                  b + (record_phase - b - 1) % per_tick + 1,  # next kept state
                  b + log_every - b % log_every,  # next log sample
                  n_steps)
        step(None, nxt - b)
        b = nxt
    result = ReplayResult(
        t=np.array(rows_t), base_xy=np.array(rows_xy), base_z=np.array(rows_z),
        heading=np.unwrap(np.array(rows_h)), loads=np.array(rows_l), touchdowns=touch.events,
        fell=fell, fall_time_s=fall_time, duration_s=float(rows_t[-1]) if rows_t else 0.0,
    )
    result.metrics = summarize(result, start_xy=None)
    return result


def measured_stride(r: ReplayResult, t: float) -> float | None:
    """The stride period (s) walked just before sim time ``t``: the median of the last two intervals
    between right touchdowns at or before ``t``, if the robot is still stepping then (the last touchdown
    within two intervals of ``t``); None otherwise (standing, or too few steps)."""
    td = [x for x in r.touchdowns["right"] if x <= t]
    if len(td) < 3:
        return None
    stride = float(np.median(np.diff(td[-3:])))
    return stride if t - td[-1] <= 2.0 * stride else None


def heading_at(r: ReplayResult, t: float, stride_s: float | None = None) -> float:
    """The walk's heading (rad) at sim time ``t``: the torso yaw averaged over the stride that ends at
    ``t`` (the torso yaws several degrees each way within a stride, so one sample says little about
    where the walk goes); ``stride_s`` None: ``measured_stride``. Without a stride (standing, first
    steps) or a full stride of samples before ``t``, the yaw sampled at ``t``."""
    i = max(1, int(np.searchsorted(r.t, t, side="right")))
    stride = measured_stride(r, t) if stride_s is None else stride_s
    if stride is None or r.t[0] > t - stride:
        return float(r.heading[i - 1])
    return float(np.mean(r.heading[(r.t > t - stride) & (r.t <= t)]))


def summarize(r: ReplayResult, start_xy: np.ndarray | None = None, period_s: float | None = None) -> dict:
    """Distance along the starting heading, lateral drift, heading change, speed, steps, contact timing."""
    if len(r.t) == 0:
        raise ValueError("replay produced no samples")
    h0 = float(r.heading[0])
    p0 = r.base_xy[0] if start_xy is None else np.asarray(start_xy)
    d = r.base_xy[-1] - p0
    fwd = np.array([math.cos(h0), math.sin(h0)])
    left = np.array([-math.sin(h0), math.cos(h0)])
    distance = float(d @ fwd)
    right_td = np.array(r.touchdowns["right"])
    left_td = np.array(r.touchdowns["left"])
    steps = len(right_td) + len(left_td)
    m = {
        "fell": bool(r.fell),
        "fall_time_s": None if r.fall_time_s is None else round(float(r.fall_time_s), 3),
        "duration_s": round(float(r.duration_s), 3),
        "distance_m": round(distance, 4),
        "lateral_drift_m": round(float(d @ left), 4),
        # from the standing yaw to the heading over the last stride (heading_at); the torso's yaw at the
        # last sample, which includes the within-stride sway, beside it
        "heading_change_deg": round(math.degrees(heading_at(r, float(r.t[-1]), _stride_or(r, period_s))
                                                 - h0), 2),
        "yaw_change_final_sample_deg": round(math.degrees(float(r.heading[-1] - h0)), 2),
        "mean_speed_mps": round(distance / r.duration_s, 4) if r.duration_s > 0 else 0.0,
        "steps": int(steps),
        "min_torso_height_m": round(float(r.base_z.min()), 4),
    }
    if len(right_td) > 2:
        m["right_touchdown_interval_s"] = round(float(np.median(np.diff(right_td))), 3)
    if len(left_td) > 2:
        m["left_touchdown_interval_s"] = round(float(np.median(np.diff(left_td))), 3)
    if period_s is not None:
        m["gait_period_s"] = round(float(period_s), 3)
    return m


def _stride_or(r: ReplayResult, period_s: float | None) -> float | None:
    """The stride measured at the end of ``r``, else ``period_s`` (e.g. the recording's cycle)."""
    measured = measured_stride(r, float(r.t[-1]))
    return measured if measured is not None else period_s


def recording_setup(gait: str = "walk", data: str | None = None, duration: float | None = None,
                    need_cycle: bool = True):
    """The recording (``data`` CSV, else the packaged ``gait``), the run's duration (default: the
    recording, at least 30 s) and its steady cycle. Without a steady cycle the recording plays once (a
    cycle longer than it); with ``need_cycle`` that is an error when ``duration`` runs past its end."""
    from cpg_walker.robot.gait_data import Cycle, find_steady_cycle, load_gait

    recording = load_gait(data if data is not None else gait)
    if duration is None:
        duration = max(30.0, recording.duration)
    if not (duration > 0):
        raise InputError(f"--duration must be positive, got {duration}")
    try:
        cycle = find_steady_cycle(recording)
    except ValueError as exc:
        if need_cycle and duration > recording.duration:
            raise InputError(f"cannot continue past the recording's end: {exc}") from None
        cycle = Cycle(start=0.0, period=recording.duration + 1.0, mismatch_rad=float("nan"))
    return recording, duration, cycle
