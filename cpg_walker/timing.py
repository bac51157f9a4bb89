"""Time stamps and timing of a control loop, free of ROS: the sim-time guards every node applies to its
incoming stamps (a restarted sim, a stray stamp) and the wall-clock statistics of its ticks."""

from __future__ import annotations

#: Sim s a /clock or state stamp may lie before the newest one seen before a node takes it for a restarted
#: (reset) sim and starts its own state over (docs/ROS_INTERFACE.md, "Faults"); smaller steps back are
#: stale or re-sent messages.
CLOCK_RESET_S = 1.0


#: A stamp more than this past the newest one taken is taken only once the next confirms it (a stray
#: far-future stamp would otherwise make every real message after it look old: StampGuard).
CLOCK_JUMP_NS = 1_000_000_000


def clock_went_back(newest_ns: int | None, t_ns: int) -> bool:
    """True when ``t_ns`` lies more than CLOCK_RESET_S before ``newest_ns``: the sim has restarted."""
    return newest_ns is not None and newest_ns - t_ns > CLOCK_RESET_S * 1e9


class StampGuard:
    """Judges each stamp against the newest one taken: a jump (more than CLOCK_JUMP_NS ahead, or more
    than CLOCK_RESET_S back) is a stray until the next stamp confirms it by continuing from it within
    CLOCK_JUMP_NS (going back, the same stamp again confirms it too: a restarted lockstep sim re-sends
    its first state). One stray message (a corrupt stamp, a second publisher) neither freezes a node nor
    restarts it; a real jump (a stall, a restarted sim) is taken one message later."""

    TAKE, DROP, RESET = "take", "drop", "reset"

    def __init__(self) -> None:
        self.pending: int | None = None
        self.dropped = 0

    def judge(self, newest_ns: int | None, t_ns: int) -> str:
        """TAKE (no jump, or a confirmed one ahead), RESET (a confirmed jump back) or DROP."""
        ahead = newest_ns is not None and t_ns - newest_ns > CLOCK_JUMP_NS
        if not ahead and not clock_went_back(newest_ns, t_ns):
            self.pending = None
            return self.TAKE
        seen, self.pending = self.pending, t_ns
        if seen is not None and (0 < t_ns - seen <= CLOCK_JUMP_NS or (not ahead and t_ns == seen)):
            self.pending = None
            return self.TAKE if ahead else self.RESET
        self.dropped += 1
        return self.DROP

class ActivityStats:
    """CPU and wall time of a node from its first handled message to exit (excludes start-up imports)."""

    def __init__(self) -> None:
        self.count = 0
        self.cpu0 = self.wall0 = 0.0

    def tick(self) -> None:
        import time

        if self.count == 0:
            self.cpu0, self.wall0 = time.process_time(), time.monotonic()
        self.count += 1

    def summary(self) -> dict:
        import time

        if self.count == 0:
            return {"messages": 0}
        cpu, wall = time.process_time() - self.cpu0, time.monotonic() - self.wall0
        return {"messages": self.count, "active_wall_s": round(wall, 3), "active_cpu_s": round(cpu, 3),
                "cpu_fraction": round(cpu / wall, 3) if wall > 0 else None}


class TickStats:
    """Wall-clock timing of a node's ticks (one per new ``/clock`` sample): the period between consecutive
    ticks against the nominal one (the sim-time step between them, i.e. the wall period at real-time
    factor 1), the work time per tick, and overruns (work longer than the nominal period). Keeps the
    last ``window`` ticks (bounded memory); the summary is over them."""

    def __init__(self, window: int = 200_000) -> None:
        from collections import deque

        self.period_s: deque[float] = deque(maxlen=window)
        self.nominal_s: deque[float] = deque(maxlen=window)
        self.work_s: deque[float] = deque(maxlen=window)
        self.ticks = 0
        self.repeats = 0
        self.overruns = 0
        self._last: tuple[float, int] | None = None  # (wall start, sim ns) of the previous tick

    def tick(self, wall_start: float, sim_ns: int, work_s: float) -> None:
        """A tick at sim time ``sim_ns`` began at ``wall_start`` (perf_counter) and took ``work_s``."""
        if self._last is not None and sim_ns <= self._last[1]:
            self.repeats += 1  # a re-sent (or old) clock sample: not a new tick of the loop
            return
        self.ticks += 1
        if self._last is not None:
            nominal = (sim_ns - self._last[1]) / 1e9
            self.period_s.append(wall_start - self._last[0])
            self.nominal_s.append(nominal)
            if work_s > nominal:
                self.overruns += 1
        self.work_s.append(work_s)
        self._last = (wall_start, sim_ns)

    def summary(self) -> dict:
        """Milliseconds: wall period (and the nominal one), jitter = period - nominal, work per tick
        (mean/std/p50/p99/max each; jitter also p50/p99/max of its magnitude); counts."""
        import numpy as np

        def stats(a) -> dict:
            a = np.asarray(a) * 1e3
            return {"mean": round(float(a.mean()), 4), "std": round(float(a.std()), 4),
                    "p50": round(float(np.median(a)), 4), "p99": round(float(np.percentile(a, 99)), 4),
                    "max": round(float(a.max()), 4)}

        out: dict = {"ticks": self.ticks, "repeated_clock": self.repeats, "overruns": self.overruns}
        if self.work_s:
            out["work_ms"] = stats(self.work_s)
        if self.period_s:
            period, nominal = np.asarray(self.period_s), np.asarray(self.nominal_s)
            out["period_ms"] = {"nominal": round(float(np.median(nominal)) * 1e3, 4), **stats(period),
                                "count": int(period.size)}
            jitter = period - nominal
            absj = stats(np.abs(jitter))
            out["jitter_ms"] = {**stats(jitter), "abs_p50": absj["p50"], "abs_p99": absj["p99"],
                                "abs_max": absj["max"]}
        return out


def latency_summary(samples_s: list[float]) -> dict:
    """p50/p99/max of latencies (s) in milliseconds, with the count."""
    if not samples_s:
        return {"count": 0}
    import numpy as np

    a = np.asarray(samples_s) * 1e3
    return {"count": int(a.size), "p50_ms": round(float(np.percentile(a, 50)), 4),
            "p99_ms": round(float(np.percentile(a, 99)), 4), "max_ms": round(float(a.max()), 4)}
