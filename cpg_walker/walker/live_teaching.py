"""Live teaching: the humanoid CPG learned from a stream of joint angles while it arrives (issue 26).

``LiveTeacher`` is fed samples (teacher time, the ten DOFs) as they come and, in steps the caller bounds
(``advance(max_steps)``, so a control loop decides what a tick can spend), runs the same learning as
``HumanoidCPG.learn`` (eqs 4–13) on the stream itself instead of on a repeated recorded stride:

1. **collecting**: the newest ``window_s`` teacher s are searched for a stride period (normalised
   autocorrelation of the ten DOFs, ``gait_data.autocorrelation_period``, every teacher second). A window
   that correlates at least ``min_correlation`` at a period in [``min_period_s``, ``max_period_s``] gives the
   teaching cycle: its last period seeds the network exactly as offline learning seeds it from the
   recording's steady stride (offset, gain, time scale, harmonic seeds: ``HumanoidCPG.learning_network``).
2. **learning**: from that cycle's start on, the network integrates the stream (linear interpolation
   between samples, the RK4 step of offline learning). Strides are counted in the estimated period; every
   ``chunk_strides`` strides the offline convergence criterion (``controller.stable``) is checked on the
   last stride's error.
3. **converged**: the network is frozen at that chunk's end (its state there is the cycle's phase 0, at
   teacher time ``cycle_start_s``) and kept as ``result`` until a later teaching converges.

A stream that cannot teach is **refused** with a reason, and whatever it was learning is dropped:
missing DOFs, a NaN or infinite angle, stamps going backwards or jumping by more than ``max_gap_s``, no
period after ``give_up_s`` teacher s (not periodic), no convergence within ``max_strides``, or no sample
for ``stall_s`` (the caller's clock, ``stalled``) while collecting or learning. After a refusal samples
are ignored until the stream has paused for ``stall_s``; the next sample then starts a new teaching.
Nothing here touches the network that walks: the caller decides what to do with ``result``.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

from cpg_walker.cpg.network import CPGNetwork, CPGParams
from cpg_walker.errors import InputError
from cpg_walker.robot.gait_data import autocorrelation_period
from cpg_walker.walker.controller import (
    DOFS,
    HumanoidCPG,
    HumanoidSettings,
    cycle_from_samples,
    snapshot,
    stable,
)

IDLE, COLLECTING, LEARNING, CONVERGED, REFUSED = "idle", "collecting", "learning", "converged", "refused"
#: s between the uniform samples the period search and the seeding cycle are resampled to.
RESAMPLE_DT = 0.005
#: A period is a lag past the first at which the stream correlates below this (a drifting signal correlates
#: well at every short lag without repeating).
PERIOD_DIP = 0.5
#: The period is the shortest lag whose peak correlates within this of the best (two strides correlate about
#: as well as one).
PERIOD_NEAR_BEST = 0.02
#: Teacher s between two period searches while collecting.
SEARCH_EVERY_S = 1.0


@dataclass(frozen=True)
class LiveTeachingConfig:
    """How a stream is judged (config/cpg_humanoid_learning.yaml, section ``live``)."""

    window_s: float  # teacher s of stream the stride period is searched on (the newest)
    min_period_s: float
    max_period_s: float
    min_correlation: float  # normalised autocorrelation at the period; below it the window is not periodic
    give_up_s: float  # teacher s of stream without a periodic window: refused as not periodic
    max_gap_s: float  # largest step between two stamps (teacher s)
    stall_s: float  # caller's s without a sample: the stream stopped

    @classmethod
    def from_mapping(cls, d: dict, where: str) -> LiveTeachingConfig:
        known = {f.name for f in fields(cls)}
        if set(d) != known:
            raise InputError(f"{where}: live teaching: unknown key(s) {sorted(set(d) - known)}, "
                             f"missing key(s) {sorted(known - set(d))}")
        try:
            return cls(**{k: float(v) for k, v in d.items()})
        except (TypeError, ValueError) as exc:
            raise InputError(f"{where}: live teaching: {exc}") from None

    def __post_init__(self) -> None:
        if not 0 < self.min_period_s < self.max_period_s:
            raise InputError(f"live teaching: need 0 < min_period_s < max_period_s, got "
                             f"{self.min_period_s:g}, {self.max_period_s:g}")
        if self.window_s < 2 * self.max_period_s:
            raise InputError(f"live teaching: window_s ({self.window_s:g}) must hold two of the longest "
                             f"period ({self.max_period_s:g} s)")
        if self.give_up_s < self.window_s:
            raise InputError(f"live teaching: give_up_s ({self.give_up_s:g}) must be at least window_s")
        if not 0 < self.min_correlation <= 1:
            raise InputError(f"live teaching: min_correlation must be in (0, 1], "
                             f"got {self.min_correlation:g}")


class LiveTeacher:
    """Learns the ten DOFs' CPG from a live stream (module docstring): ``add`` samples, ``advance`` the
    learning, read ``progress()``; ``result`` is the last converged controller (None before)."""

    def __init__(self, settings: HumanoidSettings, params: CPGParams, cfg: LiveTeachingConfig,
                 names: Sequence[str] = DOFS) -> None:
        self.settings, self.params, self.cfg = settings, params, cfg
        self.names = tuple(names)
        self.result: HumanoidCPG | None = None
        self.result_info: dict = {}
        self.teachings = 0  # streams begun (a pause of stall_s after a refusal or convergence ends one)
        self._reset(IDLE, "")

    def warm_up(self) -> None:
        """Load the learning's compiled kernels now (on first use they take about a second)."""
        n = 64
        t = np.arange(n) * (2.5 / n)
        q = np.stack([np.sin(2 * math.pi * t / 2.5 + k) for k in range(len(self.names))], axis=1)
        net, dt, _, _ = HumanoidCPG.learning_network(cycle_from_samples("warm-up", 0.0, q, 2.5 / n),
                                                     self.settings, self.params)
        for _ in range(2):
            net.step(dt, np.stack([q[0], q[0], q[1]]))

    # ------------------------------------------------------------------ input
    def _reset(self, state: str, reason: str) -> None:
        self.state, self.reason = state, reason
        self._t: list[float] = []
        self._q: list[np.ndarray] = []
        self.first_t: float | None = None
        self.last_t: float | None = None
        self.last_arrival: float | None = None
        self._next_search = -math.inf
        self.period_s: float | None = None  # the strides' length (the period found when learning began)
        self.teacher_period_s: float | None = None  # the newest estimate (the window sliding on)
        self.correlation: float | None = None
        self.net: CPGNetwork | None = None
        self.t0 = 0.0  # teacher time of the learning network's t = 0 (the seeding cycle's start)
        self.strides = 0
        self._err_sq = np.zeros(len(self.names))
        self.error_rms = np.full(len(self.names), np.nan)
        self._prev: dict | None = None
        self._good = 0
        self._k = self._lo = self.per_stride = 0
        self.dt = 0.0
        self.teach_rms = np.ones(len(self.names))

    def refuse(self, reason: str) -> None:
        """Drop what is being learned; samples are ignored until the stream pauses for ``stall_s``."""
        last = self.last_arrival
        self._reset(REFUSED, reason)
        self.last_arrival = last

    def reset(self) -> None:
        """Forget the teaching in progress (the last converged ``result`` stays)."""
        self._reset(IDLE, "")

    def add(self, t: float, names: Sequence[str], positions: Sequence[float], now: float) -> None:
        """One sample: teacher time ``t`` (s), joint ``names`` with their ``positions`` (rad; extra joints are
        ignored), received at the caller's time ``now`` (s)."""
        paused = self.last_arrival is not None and now - self.last_arrival >= self.cfg.stall_s
        self.last_arrival = now
        if self.state in (REFUSED, CONVERGED):
            if not paused:
                return
            self._reset(IDLE, "")
            self.last_arrival = now
        if self.state == IDLE:  # a stream begins with this sample
            self.teachings += 1
        index = {n: i for i, n in enumerate(names)}
        missing = [n for n in self.names if n not in index]
        if missing:
            return self.refuse(f"the teaching stream lacks {len(missing)} of the CPG's joints: "
                               f"{', '.join(missing)}")
        if len(positions) != len(names):
            return self.refuse(f"a teaching sample has {len(names)} names but {len(positions)} positions")
        q = np.array([positions[index[n]] for n in self.names], dtype=float)
        if not math.isfinite(t):
            return self.refuse(f"a teaching sample's stamp is {t}")
        bad = [n for n, v in zip(self.names, q, strict=True) if not math.isfinite(v)]
        if bad:
            return self.refuse(f"{', '.join(bad)} {'is' if len(bad) == 1 else 'are'} NaN or infinite "
                               f"at teacher time {t:.3f} s")
        if self.last_t is not None:
            step = t - self.last_t
            if step <= 0:
                return self.refuse(f"teacher time went from {self.last_t:.3f} s back to {t:.3f} s")
            if step > self.cfg.max_gap_s:
                return self.refuse(f"teacher time jumped by {step:.3f} s (from {self.last_t:.3f} s; at most "
                                   f"{self.cfg.max_gap_s:g} s between samples)")
        if self.state == IDLE:
            self.state, self.first_t = COLLECTING, t
        self.last_t = t
        self._t.append(float(t))
        self._q.append(q)

    def stalled(self, now: float) -> bool:
        """Refuse a stream that stopped (no sample for ``stall_s`` while collecting or learning): True if
        it did."""
        if (self.state in (COLLECTING, LEARNING) and self.last_arrival is not None
                and now - self.last_arrival >= self.cfg.stall_s):
            self.refuse(f"the teaching stream stopped at teacher time {self.last_t:.3f} s "
                        f"(nothing for {self.cfg.stall_s:g} s) before the learning converged")
            return True
        return False

    # ------------------------------------------------------------------ learning
    def advance(self, max_steps: int) -> int:
        """Learn as far as the samples reach, at most ``max_steps`` RK4 steps; returns the steps taken."""
        if self.state == COLLECTING:
            self._search()
        if self.state != LEARNING:
            return 0
        net, dt, per = self.net, self.dt, self.per_stride
        s = self.settings
        steps = 0
        while steps < max_steps and self.t0 + net.t + dt <= self._t[-1]:
            k = self._k
            tau = self.t0 + net.t
            P = np.stack([self._at(tau), self._at(tau + dt / 2), self._at(tau + dt)])
            if k >= (s.chunk_strides - 1) * per:  # the chunk's last stride: its error
                self._err_sq += (P[0] - net.output()) ** 2
            net.step(dt, P)
            steps += 1
            self._k = k + 1
            if self._k == s.chunk_strides * per:
                self._end_chunk()
                if self.state != LEARNING:
                    break
        if self.state == LEARNING:  # keep the newest window (the period's estimate) and what is to learn
            self._prune(min(self.t0 + net.t, self._t[-1] - self.cfg.window_s) - 1.0)
        return steps

    def _at(self, tau: float) -> np.ndarray:
        """The stream at teacher time ``tau`` (linear between the samples around it)."""
        t = self._t
        i = bisect.bisect_right(t, tau, lo=self._lo) - 1
        i = min(max(i, 0), len(t) - 2)
        self._lo = max(0, i - 1)
        w = (tau - t[i]) / (t[i + 1] - t[i])
        return self._q[i] + w * (self._q[i + 1] - self._q[i])

    def _prune(self, before: float) -> None:
        """Drop samples older than ``before`` (teacher s), keeping one before it."""
        i = bisect.bisect_left(self._t, before) - 1
        if i > 0:
            del self._t[:i], self._q[:i]
            self._lo = 0

    def _uniform(self, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        tu = np.arange(t0, t1, RESAMPLE_DT)
        t, q = np.asarray(self._t), np.asarray(self._q)
        return tu, np.stack([np.interp(tu, t, q[:, j]) for j in range(q.shape[1])], axis=1)

    def _search(self) -> None:
        """Collecting: look for the stride period in the newest window; seed the learning on it."""
        cfg = self.cfg
        end = self._t[-1]
        if end - self.first_t < cfg.window_s or end < self._next_search:
            return
        self._next_search = end + SEARCH_EVERY_S
        period, corr = self._estimate_period()
        self.correlation = None if period is None else round(corr, 4)  # nan: a drift
        if period is not None and corr >= cfg.min_correlation:
            self._start_learning(period, end)
        elif end - self.first_t >= cfg.give_up_s:
            why = (f"it drifts (its autocorrelation never falls below {PERIOD_DIP:g} within "
                   f"{cfg.max_period_s:g} s)" if np.isnan(corr) else
                   f"no period in {cfg.min_period_s:g}-{cfg.max_period_s:g} s correlates better than "
                   f"{corr:.2f} (at least {cfg.min_correlation:g} needed)")
            self.refuse(f"the teaching stream is not periodic after {end - self.first_t:.1f} s: over its "
                        f"last {cfg.window_s:g} s {why}")
        else:
            self._prune(end - cfg.window_s - 1.0)

    def _start_learning(self, period: float, end: float) -> None:
        n = max(8, round(period / RESAMPLE_DT))
        start = end - period
        tu = start + np.arange(n) * (period / n)
        t, q = np.asarray(self._t), np.asarray(self._q)
        qc = np.stack([np.interp(tu, t, q[:, j]) for j in range(q.shape[1])], axis=1)
        cyc = cycle_from_samples("stream", start, qc, period / n)
        self.net, self.dt, self.per_stride, self.teach_rms = HumanoidCPG.learning_network(
            cyc, self.settings, self.params)
        self.period_s, self.teacher_period_s, self.t0 = period, period, start
        self._k, self._lo = 0, 0
        self.state = LEARNING
        self._prune(start - 1.0)

    def _estimate_period(self) -> tuple[float | None, float]:
        """(period, correlation) of the newest ``window_s`` of the stream."""
        cfg = self.cfg
        end = self._t[-1]
        _, q = self._uniform(end - cfg.window_s, end)
        return autocorrelation_period(q, RESAMPLE_DT, cfg.min_period_s, cfg.max_period_s,
                                      keep_s=cfg.window_s - cfg.max_period_s, refine=True, dip=PERIOD_DIP,
                                      shortest_within=PERIOD_NEAR_BEST)

    def _end_chunk(self) -> None:
        s, net = self.settings, self.net
        period, corr = self._estimate_period()  # the teacher's, on the newest window (no start-up in it)
        if period is not None and corr >= self.cfg.min_correlation:
            self.teacher_period_s, self.correlation = period, round(corr, 4)
        self.strides += s.chunk_strides
        net.t = self.strides * self.period_s  # the clock on the stride grid, as offline
        self._k = 0
        self.error_rms = np.sqrt(self._err_sq / self.per_stride)
        self._err_sq[:] = 0.0
        snap = snapshot(net, self.error_rms)
        if self._prev is not None:
            ok, _ = stable(self._prev, snap, self.teach_rms, s)
            self._good = self._good + 1 if ok else 0
        self._prev = snap
        if self._good >= s.converged_chunks:
            self._converge()
        elif self.strides >= s.max_strides:
            self.refuse(f"the learning did not converge within {s.max_strides} strides "
                        f"({self.strides * self.period_s:.0f} teacher s)")

    def _converge(self) -> None:
        tc = self.t0 + self.strides * self.period_s
        net = self.net
        learned_hz = float(np.mean(net.omega[:, 0] * net.time_scale) / (2 * math.pi))
        teaching = {"gait": "stream", "cycle_start_s": tc, "cycle_period_s": 1.0 / learned_hz,
                    "recorded_gait_frequency_hz": 1.0 / self.teacher_period_s,
                    "description": "a live teaching stream; phase 0 is its state at teacher time "
                                   "cycle_start_s; the period is the learned one, the recorded frequency "
                                   "the stream's autocorrelation's"}
        learning = {"converged": True, "strides": self.strides, "learn_time_s": self.strides * self.period_s,
                    "dt_s": self.dt, "live": True}
        self.result = HumanoidCPG.from_learning(self.net, self.settings, teaching, learning)
        self.result_info = {"converged_after_s": round(tc - self.first_t, 3), "strides": self.strides,
                            "teacher_frequency_hz": 1.0 / self.teacher_period_s,
                            "learned_frequency_hz": self.result.gait_frequency_hz(),
                            "teaching": self.teachings}
        last = self.last_arrival
        self._reset(CONVERGED, "")
        self.last_arrival = last

    # ------------------------------------------------------------------ progress
    def progress(self) -> dict:
        """What a user watches: state, reason, teacher s seen, the period found, strides learned, and per
        DOF the learned frequency (Hz), amplitude (rad, oscillator 0's) and the last stride's RMS error
        (°)."""
        out: dict = {"state": self.state, "reason": self.reason, "teachings": self.teachings,
                     "converged_result": self.result is not None}
        if self.first_t is not None and self.last_t is not None:
            out["teacher_s"] = round(self.last_t - self.first_t, 3)
        if self.correlation is not None:
            out["correlation"] = self.correlation
        if self.teacher_period_s is not None:
            out["teacher_frequency_hz"] = 1.0 / self.teacher_period_s
        net = self.net
        if self.state == LEARNING and net is not None:
            om = net.omega[:, 0] * net.time_scale / (2 * math.pi)
            out.update(strides=self.strides + self._k / self.per_stride,
                       learned_frequency_hz=om.tolist(),
                       amplitude_rad=(np.abs(net.alpha[:, 0]) * net.gain * math.sqrt(net.params.mu)).tolist(),
                       error_deg=np.degrees(self.error_rms).tolist())
        if self.result is not None:
            out.update({f"result_{k}": v for k, v in self.result_info.items()})
        return out
