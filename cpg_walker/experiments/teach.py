"""Teaching the running graph a gait (``cpg-walker teach``): start the graph as ``cpg-walker graph`` does
(walking its network, or standing with ``-p cpg:alpha=0.0``), or join one already running (``--attach``),
stream a teacher's joint angles
on /cpg/teach at ``rate`` teacher s per wall s (stamps in the teacher's time), follow cpg_node's
``cpg_walker/teaching`` status until the learning converges or is refused, then optionally save the
taught network (~/save_taught) and take over (~/take_over) and walk it for ``duration`` sim s at
``alpha`` (TAUGHT_ALPHA),
watching /odom/ground_truth and /sim/fallen. DIR/teach.json.

Teachers (walker/teaching_stream.py ``TeachingStream``): a packaged gait (walk, slow), a CSV in the walk
data format or a bag's JointState topic (``bag_gait``), played from its start and then its steady stride
repeated, optionally time-scaled (``speed``: the gait at that many times its frequency).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from cpg_walker.errors import InputError
from cpg_walker.nodes import interface as ifc
from cpg_walker.robot.gait_data import Gait

#: Teacher s between the samples streamed (100 Hz of the teacher's time).
SAMPLE_DT = 0.01
#: Wall s without a teaching status from cpg_node after which the teaching gives up (no graph there).
NO_STATUS_S = 60.0
#: α the taught network walks at after a take-over (``--alpha``): the slow walk taught live, taking over
#: through standing in-process at 8 phases of the walk and walking 60 s open loop, fell in 2 of 8 at α 1
#: (20 s after stepping off, once the steps had grown to full length), in 0 of 8 at α 0.8.
TAUGHT_ALPHA = 0.8
#: Sim s the walk is watched after a refused teaching (it goes on with its network untouched).
AFTER_REFUSAL_S = 10.0
#: Sim s of a started graph (it is stopped once the teaching and the walk are over).
GRAPH_DURATION_S = 100_000.0


def bag_gait(bag: str | Path, topic: str = ifc.JOINT_STATES) -> Gait:
    """A rosbag2 recording's sensor_msgs/JointState ``topic`` as a Gait: the first message's joints, by
    their header stamps (from the first), resampled to their median step."""
    from cpg_walker.nodes.recording import read_topics

    msgs = read_topics(Path(bag), [topic]).get(topic) or []
    if len(msgs) < 4:
        raise InputError(f"{bag}: {len(msgs)} {topic} messages, too few to teach from")
    names = tuple(msgs[0][1].name)
    t, q = [], []
    for _, m in msgs:
        if tuple(m.name) != names or len(m.position) != len(names):
            raise InputError(f"{bag}: {topic}'s joints change between messages")
        stamp = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        if t and stamp <= t[-1]:
            continue  # a re-sent (lockstep) or out-of-order state: the first of a stamp counts
        t.append(stamp)
        q.append(np.asarray(m.position, dtype=float))
    if len(t) < 4:
        raise InputError(f"{bag}: {len(t)} {topic} stamps, too few to teach from")
    t = np.asarray(t) - t[0]
    dt = float(np.median(np.diff(t)))
    tu = np.arange(0.0, t[-1] + 1e-9, dt)
    q = np.asarray(q)
    qu = np.stack([np.interp(tu, t, q[:, j]) for j in range(q.shape[1])], axis=1)
    return Gait(Path(bag).name, names, tu, qu, f"{bag} {topic}")


class StreamTeacher:
    """A TeachingStream sampled every SAMPLE_DT teacher s."""

    def __init__(self, gait: str | Gait, speed: float) -> None:
        from cpg_walker.walker.teaching_stream import TeachingStream

        self.stream = TeachingStream(gait, speed)
        self.frequency_hz = self.stream.frequency_hz if self.stream.periodic else None
        self.source = (gait.source if isinstance(gait, Gait) else str(gait)) + (
            f" at {speed:g} x its frequency" if speed != 1.0 else "")
        self.k = 0

    def until(self, t: float):
        while self.k * SAMPLE_DT <= t:
            tk = self.k * SAMPLE_DT
            self.k += 1
            yield tk, list(self.stream.names), self.stream.at(tk).tolist()


def teach_graph(out: str | Path, teacher, rate: float = 10.0, take_over: bool = False,
                save: str | Path | None = None, duration: float = 60.0, domain_id: int | None = None,
                attach: bool = False, pacing: str = "lockstep", params: list[str] | None = None,
                wall_limit_s: float = 3600.0, progress=print, after_s: float = AFTER_REFUSAL_S,
                alpha: float = TAUGHT_ALPHA) -> dict:
    """``_teach`` and, for a graph it started, the nodes' own timing once they stopped (``node_timing``).
    ``after_s``: sim s the walk is watched after a refusal; ``alpha``: the taught walk's after a take-over."""
    res = _teach(Path(out), teacher, rate, take_over, save, duration, domain_id, attach, pacing, params,
                 wall_limit_s, progress, after_s, alpha)
    if not attach:
        res["node_timing"] = node_timing(Path(out) / "logs")
        _write(Path(out), res)
    return res


def node_timing(logs: Path) -> dict:
    """Did learning delay the control ticks? cpg_node's tick work and period (its learning runs after a
    tick's targets, timed apart) and its learning's wall time per call; the sim's round trip (state out
    to torque back) and its torques that came late. From the nodes' exit statistics."""
    out: dict = {}
    cpg, sim = logs / "cpg_node.stats.json", logs / "sim_node.stats.json"
    if cpg.exists():
        d = json.loads(cpg.read_text())
        tick = d.get("tick", {})
        out["cpg_node"] = {"ticks": tick.get("ticks"), "overruns": tick.get("overruns"),
                           "tick_work_ms": tick.get("work_ms"), "tick_period_ms": tick.get("period_ms"),
                           "learning_ms_per_call": d.get("teaching", {}).get("work_ms"),
                           "learning_calls": d.get("teaching", {}).get("calls")}
    if sim.exists():
        d = json.loads(sim.read_text())
        out["sim_node"] = {k: d.get(k) for k in ("sim_s", "real_time_factor", "latency", "late_commands",
                                                  "late_held", "torque_age_s")}
    return out


def _teach(out: Path, teacher, rate: float, take_over: bool, save: str | Path | None, duration: float,
           domain_id: int | None, attach: bool, pacing: str, params: list[str] | None, wall_limit_s: float,
           progress, after_s: float, alpha: float) -> dict:
    """Teach a graph (started with ``pacing`` and ``cpg-walker graph -p`` ``params``; or attached to) from
    ``teacher`` at ``rate``; write and return teach.json's contents (``fell``: during the teaching or the
    taught walk)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry
    from rcl_interfaces.msg import ParameterType, ParameterValue
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Bool
    from std_srvs.srv import Trigger

    from cpg_walker.graph.probe import Probe
    from cpg_walker.graph.processes import env_domain_id, interrupt_group, isolated_env, quiet_domain_id
    from cpg_walker.graph.runner import resolve_domain

    if not (rate > 0 and np.isfinite(rate)):
        raise InputError(f"--rate must be a positive number, got {rate}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if attach and domain_id is None:
        env = env_domain_id()
        domain_id = 0 if env is None else env
    domain = quiet_domain_id() if domain_id is None else resolve_domain(int(domain_id))[0]
    proc = None
    if not attach:
        cmd = [sys.executable, "-m", "cpg_walker.cli.main", "graph", "--pacing", pacing, "--duration",
               str(GRAPH_DURATION_S), "--domain-id", str(domain), "--log-dir", str(out / "logs"),
               *(a for p in params or () for a in ("-p", p))]
        proc = subprocess.Popen(cmd, env=isolated_env(domain), stdout=open(out / "graph.log", "w"),
                                stderr=subprocess.STDOUT, start_new_session=True)
    probe = Probe(domain, "teacher", diagnostics=True)
    odom: list[tuple[float, float, float]] = []
    fallen: list[float] = []

    def on_odom(m: Odometry) -> None:
        p = m.pose.pose.position
        odom.append((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, p.x, p.y))

    def on_fallen(m: Bool) -> None:
        if m.data and not fallen:
            fallen.append(odom[-1][0] if odom else float("nan"))

    probe.subscribe(ifc.ODOM_GROUND_TRUTH, Odometry, on_odom, 200)
    probe.subscribe(ifc.SIM_FALLEN, Bool, on_fallen, ifc.latched_qos())
    del DiagnosticArray  # the probe watches /diagnostics itself
    pub = probe.node.create_publisher(JointState, ifc.CPG_TEACH, 1000)
    res: dict = {"teacher": teacher.source, "teacher_frequency_hz": teacher.frequency_hz, "rate": rate,
                 "domain_id": domain, "attached": attach, "pacing": None if attach else pacing,
                 "params": None if attach else list(params or ()), "converged": False,
                 "converged_after_s": None, "learned_frequency_hz": None, "took_over": False,
                 "fell": False, "distance_m": None, "saved": None}

    def status() -> dict[str, str]:
        return probe.statuses.get("cpg_walker/teaching", {})

    where = f"see {out}/graph.log" if proc is not None else "is a graph running there?"
    try:
        probe.wait(lambda: bool(status()) and probe.node.count_subscribers(ifc.CPG_TEACH) > 0,
                   f"cpg_node's teaching on DDS domain {domain} ({where})", NO_STATUS_S)
        streams = int(status().get("teaching_streams", "0"))  # this teaching is the next stream
        wall0 = time.monotonic()
        t_taught = odom[-1][0] if odom else 0.0
        end = wall0 + wall_limit_s
        sent, last_report = 0, 0.0
        while time.monotonic() < end:
            if proc is not None and proc.poll() is not None:
                raise InputError(f"the graph stopped while teaching ({where})")
            now = time.monotonic()
            msg = JointState()
            for t, names, positions in teacher.until(rate * (now - wall0)):
                msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), round((t % 1.0) * 1e9) % 10**9
                msg.name, msg.position = names, positions
                pub.publish(msg)
                sent += 1
            probe.spin_for(0.005)
            st = status()
            ours = int(st.get("teaching_streams", "0")) > streams
            if ours and st.get("teaching") in ("converged", "refused"):
                break
            if now - last_report > 5.0:
                progress(f"teach: {st.get('teaching', '?')}, teacher {st.get('teaching_teacher_s', '0')} s, "
                         f"{float(st.get('teaching_strides', 0)):.0f} strides ({sent} samples sent)")
                last_report = now
        st = status()
        res.update(samples_sent=sent, teaching_wall_s=round(time.monotonic() - wall0, 2),
                   state=st.get("teaching"), reason=st.get("teaching_reason", ""),
                   during_teaching=_walked(odom, t_taught))
        if fallen:  # while being taught: the walking network untouched, but on the ground
            res.update(fell=True, fell_at_s=round(fallen[0], 2))
        if st.get("teaching") != "converged":
            res["reason"] = res["reason"] or f"not converged within {wall_limit_s:g} wall s"
            if odom and not fallen:  # the walk goes on, its network untouched: watch it a while
                t_end = odom[-1][0]
                probe.wait(lambda: odom[-1][0] >= t_end + after_s or bool(fallen),
                           f"{after_s:g} sim s of walking after the refusal", 10 * NO_STATUS_S)
                cpg = probe.status("cpg_walker/cpg")
                res["after"] = {**_walked(odom, t_end), "fell": bool(fallen), "cpg_state": cpg.get("state"),
                                "took_over": status().get("teaching_took_over")}
                res.update(fell=bool(fallen), fell_at_s=round(fallen[0], 2) if fallen else None)
            return _write(out, res)
        res.update(converged=True, converged_after_s=float(st["taught_converged_after_s"]),
                   learned_frequency_hz=float(st["taught_learned_frequency_hz"]),
                   stream_frequency_hz=float(st["taught_teacher_frequency_hz"]),
                   strides=int(float(st["taught_strides"])))
        progress(f"teach: converged after {res['converged_after_s']:.1f} teacher s, "
                 f"{res['learned_frequency_hz']:.4f} Hz learned")
        if save is not None:
            path = str(Path(save).resolve())
            value = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=path)
            result = probe.set_param("cpg", "teach_file", value)
            if not result.successful:
                raise InputError(f"cpg_node refused teach_file {path}: {result.reason}")
            answer = probe.call(Trigger, "/cpg/save_taught")
            if not answer.success:
                raise InputError(f"cpg_node could not save the taught network: {answer.message}")
            res["saved"] = path
        if take_over and not fallen:
            taken = int(status().get("teaching_took_over", "0"))
            answer = probe.call(Trigger, "/cpg/take_over")
            res["take_over_message"] = answer.message
            if not answer.success:
                raise InputError(f"cpg_node refused the take-over: {answer.message}")
            result = probe.set_param("cpg", "alpha", alpha)  # applies once the taught network has taken over
            if not result.successful:
                raise InputError(f"cpg_node refused alpha {alpha:g}: {result.reason}")
            res["alpha"] = alpha
            progress("teach: the robot stops; the taught network takes over standing")
            probe.wait(lambda: int(status().get("teaching_took_over", "0")) > taken or bool(fallen),
                       "the take-over (the robot standing)", 10 * NO_STATUS_S)
            res["took_over"] = not fallen
            if fallen:
                res.update(fell=True, fell_at_s=round(fallen[0], 2))
                return _write(out, res)
            res["took_over_at_s"] = float(status()["teaching_took_over_at_s"])
            probe.wait(lambda: bool(odom), "/odom/ground_truth", NO_STATUS_S)
            t_start = odom[-1][0]
            res["walk_from_s"] = round(t_start, 3)
            next_report = time.monotonic() + 5.0
            while odom[-1][0] < t_start + duration and not fallen and time.monotonic() < end:
                if proc is not None and proc.poll() is not None:
                    raise InputError(f"the graph stopped during the walk ({where})")
                probe.spin_for(0.05)
                if time.monotonic() > next_report:
                    progress(f"teach: walking the taught gait, sim {odom[-1][0] - t_start:.0f} / "
                             f"{duration:g} s")
                    next_report = time.monotonic() + 5.0
            track = np.array([o for o in odom if o[0] >= t_start])
            res.update(fell=bool(fallen), fell_at_s=round(fallen[0], 2) if fallen else None,
                       walked_s=round(float(track[-1, 0] - t_start), 3),
                       distance_m=round(float(np.linalg.norm(track[-1, 1:] - track[0, 1:])), 4))
        return _write(out, res)
    finally:
        probe.close()
        if proc is not None:
            interrupt_group(proc)


def _walked(odom: list[tuple[float, float, float]], since: float) -> dict:
    """From sim s ``since`` to the newest odometry: the time and the straight-line distance walked."""
    track = [o for o in odom if o[0] >= since]
    if len(track) < 2:
        return {"from_s": since, "walked_s": 0.0, "distance_m": 0.0}
    (t0, x0, y0), (t1, x1, y1) = track[0], track[-1]
    return {"from_s": round(t0, 3), "walked_s": round(t1 - t0, 3),
            "distance_m": round(float(np.hypot(x1 - x0, y1 - y0)), 4)}


def markdown(res: dict) -> str:
    """teach.md: what was taught, learned, and walked."""
    rows = [("teacher", f"{res['teacher']} at {res['rate']:g} teacher s per wall s"),
            ("teacher's frequency", _hz(res.get("teacher_frequency_hz") or res.get("stream_frequency_hz")))]
    if res["converged"]:
        rows += [("learned frequency", _hz(res["learned_frequency_hz"])),
                 ("converged after", f"{res['converged_after_s']:.1f} teacher s ({res['strides']} strides, "
                                     f"{res['teaching_wall_s']:.1f} wall s)")]
    else:
        rows.append(("refused", res.get("reason") or ""))
    walk = res.get("during_teaching")
    if walk:
        rows.append(("the walk while taught", f"{walk['distance_m']:.2f} m in {walk['walked_s']:.1f} sim s"))
    if res.get("after"):
        a = res["after"]
        rows.append(("the walk after the refusal", f"{a['distance_m']:.2f} m in {a['walked_s']:.1f} sim s, "
                                                   f"cpg_node {a['cpg_state']}, took over {a['took_over']}"))
    if res["took_over"]:
        rows.append(("the taught gait, after taking over",
                     f"{res['distance_m']:.2f} m in {res['walked_s']:.1f} sim s"))
    rows.append(("fell", "yes, at sim " + f"{res['fell_at_s']} s" if res["fell"] else "no"))
    timing = res.get("node_timing", {})
    if timing.get("cpg_node", {}).get("learning_ms_per_call"):
        c, s = timing["cpg_node"], timing.get("sim_node", {})
        learn, work = c["learning_ms_per_call"], c["tick_work_ms"]
        rows.append(("learning per call (after a tick's targets)",
                     f"mean {learn['mean']:.3f} ms, p99 {learn['p99']:.3f}, max {learn['max']:.3f}"))
        rows.append(("cpg_node's tick work", f"p99 {work['p99']:.3f} ms, max {work['max']:.3f} "
                                             f"({c['overruns']} of {c['ticks']} over the period)"))
        if s.get("latency"):
            rows.append(("the sim's state-to-torque round trip",
                         f"p99 {s['latency']['p99_ms']:.3f} ms, max {s['latency']['max_ms']:.3f}; late "
                         f"torques held: {s['late_held']}"))
    return "| | |\n|---|---|\n" + "".join(f"| {k} | {v} |\n" for k, v in rows)


def _hz(x: float | None) -> str:
    return "unknown" if x is None else f"{x:.4f} Hz"


def _write(out: Path, res: dict) -> dict:
    (out / "teach.json").write_text(json.dumps(res, indent=2) + "\n")
    (out / "teach.md").write_text(markdown(res))
    return res
