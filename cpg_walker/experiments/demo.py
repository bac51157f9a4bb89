"""``cpg-walker demo``: the main job through the ROS graph.

The learned CPG walks the simulated HOAP-2 through sim_node + pid_node + cpg_node (three processes,
``cpg-walker walk``'s experiments/walk_graph.py) while every topic is recorded (recorder_node, one rosbag2
MCAP). Mid-run, ``DEMO_SCHEDULE`` changes ζ and α (paper eq. 10: frequency ratio, amplitude) through
cpg_node's SetParameters service: faster, shorter steps, stopped (α 0), forward again, backwards. A
one-line status (``GraphStatus``) follows the run from its topics; afterwards the recording is turned into
the plots (experiments/plot_bag.py), a video (experiments/render.py) and ``summary.json``
(``summarize_recording``).

The schedule's times are fixed sim times (the full demo needs ``FULL_DEMO_S``; a shorter run shows the
changes that fit, a longer one walks backwards longer), so every run of it steps through the same
phases. Reversals and restarts from alpha 0 fall at some phases of the stride (in-process, our feedback):
the whole schedule shifted by 0 to 2.5 s in 0.25 s steps, a direct reversal fell at 2 of 10 shifts, one
through a stop at 4 of 10, one at alpha 0.5 at 9 of 21; with the other changes fixed, a reversal 0.4 s
before to 0.05 s after 41.75 s walked, 0.1 s after fell. Through the graph a change lands 15-40 ms after
it is due (once 240 ms, on a loaded machine), so the reversal is due at 41.55 s, in the middle of the
window that walks: with every change landing 0-0.25 s late (20 random draws) 0 of 20 fell. Making every
reversal safe at any phase is the "every command walks" issue.
"""

from __future__ import annotations

import contextlib
import json
import math
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from cpg_walker.errors import InputError
from cpg_walker.nodes import interface as ifc

#: (sim s, zeta, alpha, what the robot does) - the run starts at zeta = alpha = 1 (module docstring).
DEMO_SCHEDULE: tuple[tuple[float, float, float, str], ...] = (
    (11.75, 1.4, 1.0, "faster (zeta 1.4)"),
    (17.75, 1.0, 0.5, "shorter steps (alpha 0.5)"),
    (23.75, 1.0, 0.0, "stopped, standing (alpha 0)"),
    (29.75, 1.0, 1.0, "walking forward again (alpha 1)"),
    (41.55, -1.0, 1.0, "backwards (zeta -1)"),
)
FIRST_SEGMENT = "walking forward (zeta 1, alpha 1)"
#: Sim s after the last change that show it: the full demo (the default --duration 60 is longer).
FULL_DEMO_S = DEMO_SCHEDULE[-1][0] + 8.0
#: Sim s of walking (after walk_start_s) the shortest demo needs.
MIN_WALK_S = 3.0
VIDEO_NAME = "walk.mp4"
#: The video plays at sim speed with frames every 1/VIDEO_FPS s, up to VIDEO_MAX_FRAMES (then faster).
VIDEO_FPS, VIDEO_MAX_FRAMES = 12.5, 600


def walk_start_s(cpg_file: str | None = None) -> float:
    """Sim s at which cpg_node's CPG has taken over from the recorded opening steps (hand-over + blend,
    walker/gait_source.py); zeta/alpha commands apply from then on."""
    from cpg_walker.walker.gait_source import CPGGaitSource
    from cpg_walker.walker.learning import cpg_defaults, load_controller

    ctrl, _, _ = load_controller(cpg_defaults()["cpg_file"] if cpg_file is None else cpg_file)
    source = CPGGaitSource(ctrl)  # cpg_node's FeedbackGaitSource: the same start-up
    return float(source.handover + source.blend)


def demo_schedule(duration: float, start_s: float) -> list[tuple[float, float, float]]:
    """``DEMO_SCHEDULE``'s changes that fall within a run of ``duration`` whose CPG walks from
    ``start_s``; ValueError if the run leaves less than MIN_WALK_S of walking."""
    walking = duration - start_s
    if not walking >= MIN_WALK_S - 1e-9:
        raise InputError(f"--duration {duration:g} s is too short: the CPG walks from {start_s:.2f} sim s "
                         f"(after the recorded opening steps); use at least "
                         f"{math.ceil((start_s + MIN_WALK_S) * 10) / 10:g} s")
    return [(t, z, a) for t, z, a, _ in DEMO_SCHEDULE if t < duration]


# ----------------------------------------------------------------------------------------- live status

class GraphStatus:
    """The run's one-line status, from the graph's topics, in a thread with its own probe (graph/probe.py)
    on the graph's domain: sim time (/clock), real-time factor (sim s per wall s over the last ~5 wall s),
    forward speed and heading (/odom/ground_truth, over the last 2 sim s), the ζ and α the oscillators use
    (cpg_node's /diagnostics) and whether the robot has fallen (/sim/fallen). ``show(line, sim_s)`` is
    called every ``every_s`` wall s."""

    def __init__(self, show: Callable[[str, float], None], every_s: float = 0.5):
        self.show, self.every_s = show, every_s
        self.sim_s = 0.0
        self.fallen = False
        self.cpg: dict[str, str] = {}
        self.odom: deque[tuple[float, float, float, float]] = deque()  # (t, x, y, yaw)
        self.rtf_window: deque[tuple[float, float]] = deque()  # (wall, sim)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: str | None = None

    def start(self, domain_id: int) -> None:
        self._thread = threading.Thread(target=self._run, args=(domain_id,), name="demo-status", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30.0)

    def line(self) -> str:
        """The status line of what has been received so far."""
        speed = heading = None
        if len(self.odom) >= 2:
            (t0, x0, y0, _), (t1, x1, y1, yaw) = self.odom[0], self.odom[-1]
            if t1 > t0:
                speed = ((x1 - x0) * math.cos(yaw) + (y1 - y0) * math.sin(yaw)) / (t1 - t0)
            heading = math.degrees(yaw)
        rtf = None
        if len(self.rtf_window) >= 2 and self.rtf_window[-1][0] > self.rtf_window[0][0]:
            (w0, s0), (w1, s1) = self.rtf_window[0], self.rtf_window[-1]
            rtf = (s1 - s0) / (w1 - w0)

        def num(x: float | None, fmt: str) -> str:
            return "-" if x is None else format(x, fmt)

        zeta, alpha = self.cpg.get("zeta"), self.cpg.get("alpha")
        return (f"sim {self.sim_s:6.1f} s | RTF {num(rtf, '.2f')} | speed {num(speed, '+.3f')} m/s | "
                f"zeta {num(None if zeta is None else float(zeta), '+.2f')} "
                f"alpha {num(None if alpha is None else float(alpha), '.2f')} | "
                f"heading {num(heading, '+.0f')} deg | cpg {self.cpg.get('state', '-')} | "
                f"{'FALLEN' if self.fallen else 'upright'}")

    def _on_clock(self, msg: Any) -> None:
        self.sim_s = msg.clock.sec + msg.clock.nanosec * 1e-9
        now = time.monotonic()
        self.rtf_window.append((now, self.sim_s))
        while len(self.rtf_window) > 2 and now - self.rtf_window[0][0] > 5.0:
            self.rtf_window.popleft()

    def _on_odom(self, msg: Any) -> None:
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        self.odom.append((t, p.x, p.y, yaw))
        while len(self.odom) > 2 and t - self.odom[0][0] > 2.0:
            self.odom.popleft()

    def _on_diagnostics(self, msg: Any) -> None:
        for st in msg.status:
            if st.name == "cpg_walker/cpg":
                self.cpg = {kv.key: kv.value for kv in st.values}

    def _run(self, domain_id: int) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from nav_msgs.msg import Odometry
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import Bool

        from cpg_walker.graph.probe import Probe

        probe = Probe(domain_id, "demo_status", parameter_services=False)
        probe.subscribe(ifc.CLOCK, Clock, self._on_clock, 10)
        probe.subscribe(ifc.ODOM_GROUND_TRUTH, Odometry, self._on_odom, 10)
        probe.subscribe(ifc.DIAGNOSTICS, DiagnosticArray, self._on_diagnostics, 10)
        probe.subscribe(ifc.SIM_FALLEN, Bool, lambda m: setattr(self, "fallen", bool(m.data)),
                        ifc.latched_qos())
        shown = 0.0
        try:
            while not self._stop.is_set():
                probe.executor.spin_once(timeout_sec=0.05)
                if time.monotonic() - shown >= self.every_s:
                    shown = time.monotonic()
                    self.show(self.line(), self.sim_s)
        except Exception as exc:  # the status is a view: the run goes on without it
            self.error = f"{type(exc).__name__}: {exc}"
        finally:
            probe.close()


class StatusDisplay:
    """Shows GraphStatus lines: on a terminal a rich progress bar (sim time of the run) with the status
    beside it; otherwise (CI, a pipe) a plain line every ``plain_every_s`` wall s."""

    def __init__(self, duration: float, plain_every_s: float = 10.0, stream: Any = None):
        from rich.console import Console

        self.console = Console(file=stream or sys.stderr)
        self.duration, self.plain_every_s = duration, plain_every_s
        self.progress: Any = None
        self._last_plain = -math.inf
        self.last = self._printed = ""

    def __enter__(self) -> StatusDisplay:
        if self.console.is_terminal:
            from rich.progress import BarColumn, Progress, TextColumn

            self.progress = Progress(TextColumn("walk"), BarColumn(bar_width=20),
                                     TextColumn("{task.fields[status]}"), console=self.console,
                                     refresh_per_second=4)
            self.progress.start()
            self.task = self.progress.add_task("walk", total=self.duration, status="starting the graph")
        return self

    def __call__(self, line: str, sim_s: float) -> None:
        self.last = line
        if self.progress is not None:
            self.progress.update(self.task, completed=min(sim_s, self.duration), status=line)
        elif time.monotonic() - self._last_plain >= self.plain_every_s:
            self._last_plain = time.monotonic()
            self._plain(line)

    def _plain(self, line: str) -> None:
        if line != self._printed:
            print(line, file=self.console.file, flush=True)
            self._printed = line

    def __exit__(self, *exc: object) -> None:
        if self.progress is not None:
            self.progress.stop()
        elif self.last:
            self._plain(self.last)  # the final status


@contextlib.contextmanager
def interrupt_once(say: Callable[[str], None]) -> Iterator[None]:
    """While the graph runs: the first SIGINT (Ctrl-C) or SIGTERM raises KeyboardInterrupt (the graph is
    then stopped, the recorder last so the bag is complete); further ones are ignored until every node
    has stopped (a second Ctrl-C must not abort the clean stop). The handlers are restored after."""
    def first(signum: int, _frame: object) -> None:
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, lambda *_: say("stopping the graph, please wait"))
        say(f"{signal.Signals(signum).name}: stopping the graph (the recorder last)")
        raise KeyboardInterrupt

    saved = {s: signal.signal(s, first) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in saved.items():
            signal.signal(s, h)


# -------------------------------------------------------------------------------------------- summary

def segments(schedule: list[dict] | list[tuple[float, float, float]], end_s: float) -> list[dict]:
    """The run's segments of constant command: [{from_s, to_s, zeta, alpha, label}], the first one
    zeta = alpha = 1 from 0; a change starts at the sim time cpg_node applied it (walk.json's
    ``applied_after_sim_s``), else when it was due."""
    out = [{"from_s": 0.0, "zeta": 1.0, "alpha": 1.0, "label": FIRST_SEGMENT}]
    for k, item in enumerate(schedule):
        if isinstance(item, dict):
            if not item.get("accepted", True):
                continue
            t, z, a = item.get("applied_after_sim_s", item["t_s"]), item["zeta"], item["alpha"]
        else:
            t, z, a = item
        if t < end_s:
            ours = k < len(DEMO_SCHEDULE) and DEMO_SCHEDULE[k][1:3] == (z, a)
            label = DEMO_SCHEDULE[k][3] if ours else ""
            out.append({"from_s": float(t), "zeta": z, "alpha": a, "label": label})
    for seg, nxt in zip(out, [*out[1:], None], strict=True):
        seg["to_s"] = float(end_s) if nxt is None else nxt["from_s"]
    return out


def summarize_recording(bag: str | Path, schedule: list, walk_report: dict | None = None) -> dict:
    """summary.json's content from the recording: distance along the starting heading (walk.json's
    definition, walker/loop.py), net displacement, heading change, fall
    (/sim/fallen), and per segment of the schedule its forward speed - the displacement along the mean
    heading over the segment's second half (after the smooth ζ/α transition), per sim s."""
    import numpy as np

    from cpg_walker.experiments.plot_bag import odometry_series
    from cpg_walker.nodes.recording import ODOM_TOPIC, read_topics

    topics = read_topics(bag, [ODOM_TOPIC, ifc.SIM_FALLEN])
    odom = topics.get(ODOM_TOPIC, [])
    if len(odom) < 2:
        raise ValueError(f"{bag}: fewer than two /odom/ground_truth messages; nothing to summarise")
    s = odometry_series(odom)
    t, x, y, heading = s["t"], s["x"], s["y"], s["heading"]
    fall = [ns / 1e9 for ns, m in topics.get(ifc.SIM_FALLEN, []) if m.data]
    out_segments = []
    for seg in segments(schedule, float(t[-1])):
        mid = 0.5 * (seg["from_s"] + seg["to_s"])
        i, j = np.searchsorted(t, mid), np.searchsorted(t, seg["to_s"], side="right") - 1
        speed = None
        if j > i and t[j] > t[i]:
            h = float(np.mean(heading[i:j + 1]))
            speed = round(((x[j] - x[i]) * math.cos(h) + (y[j] - y[i]) * math.sin(h)) / (t[j] - t[i]), 4)
        out_segments.append({**{k: (round(v, 3) if isinstance(v, float) else v) for k, v in seg.items()},
                             "speed_mps": speed})
    dx, dy = x[-1] - x[0], y[-1] - y[0]
    summary = {
        "duration_s": round(float(t[-1]), 3),
        "distance_m": round(float(dx * math.cos(heading[0]) + dy * math.sin(heading[0])), 4),
        "net_displacement_m": round(float(math.hypot(dx, dy)), 4),
        "heading_change_deg": round(math.degrees(float(heading[-1] - heading[0])), 2),
        "fell": bool(fall), "fall_time_s": round(fall[0], 3) if fall else None,
        "segments": out_segments,
    }
    if walk_report is not None:
        summary["walk"] = {k: walk_report.get(k) for k in (
            "distance_m", "mean_speed_mps", "steps", "lateral_drift_m", "heading_change_deg",
            "real_time_factor", "feedback")}
    return summary


# ------------------------------------------------------------------------------------------------ run

def run_demo(out_dir: str | Path, duration: float, pacing: str = "lockstep", domain_id: int | None = None,
             stream: Any = None, foxglove: str | None = None) -> dict:
    """The demo into ``out_dir``: the graph walk with the schedule, live status and the recording, then
    the plots, the video and summary.json (also after Ctrl-C: ``interrupted`` in the summary).
    ``foxglove``: ``[HOST:]PORT`` of a Foxglove live view of the walk (run_graph_walk's)."""
    from cpg_walker.experiments.walk_graph import run_graph_walk
    from cpg_walker.nodes.recording import BAG_NAME

    stream = stream or sys.stderr
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    schedule = demo_schedule(duration, walk_start_s())
    say = lambda text: print(text, file=stream, flush=True)  # noqa: E731
    say(f"== the HOAP-2 walks {duration:g} sim s through the ROS graph (sim, pid, cpg; {pacing} pacing), "
        "every topic recorded; zeta/alpha changes at sim s: "
        + ", ".join(f"{t:g} -> ({z:g}, {a:g})" for t, z, a in schedule))
    report, interrupted = None, False
    with StatusDisplay(duration, stream=stream) as display, interrupt_once(say):
        status = GraphStatus(display)
        try:
            report = run_graph_walk(out, duration=duration, schedule=schedule, pacing=pacing, record=True,
                                    domain_id=domain_id, watchers=[status], foxglove=foxglove)
        except KeyboardInterrupt:
            interrupted = True
    if interrupted:
        say("interrupted: every node has stopped; writing what was recorded (Ctrl-C again to give up)")
    bag = out / f"{BAG_NAME}.mcap"
    if not bag.exists():
        if interrupted:  # before the recorder had started: nothing to write
            raise KeyboardInterrupt
        raise RuntimeError(f"no recording was written ({bag})")
    files = [bag.name]
    say("== plots from the recording (cpg-walker plot)")
    from cpg_walker.experiments.plot_bag import plot_bag

    files += plot_bag(bag, out)["files"]
    say("== video of the recording (offscreen MuJoCo)")
    from cpg_walker.experiments.render import render_recording

    segs_for_caption = segments(report["schedule"] if report else schedule, duration)
    every = max(1.0 / VIDEO_FPS, duration / VIDEO_MAX_FRAMES)

    def caption(t: float) -> str:
        seg = next((s for s in reversed(segs_for_caption) if s["from_s"] <= t), segs_for_caption[0])
        return f"t = {t:5.1f} s   zeta {seg['zeta']:g}  alpha {seg['alpha']:g}   {seg['label']}"

    render_recording(bag, out / VIDEO_NAME, fps=VIDEO_FPS, every_s=every, caption=caption)
    files.append(VIDEO_NAME)
    summary = summarize_recording(bag, report["schedule"] if report else schedule, report)
    summary.update({"interrupted": interrupted, "pacing": pacing,
                    "schedule": report["schedule"] if report else [list(s) for s in schedule],
                    "video_speedup": round(every * VIDEO_FPS, 3) if every > 1.0 / VIDEO_FPS else 1.0,
                    "files": sorted([*files, "summary.json"] + (["walk.json"] if report else []))})
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
