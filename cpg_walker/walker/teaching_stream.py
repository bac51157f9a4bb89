"""What a teacher streams to cpg_node's /cpg/teach: a recorded gait as an endless joint-angle signal.

``TeachingStream`` plays a recording (a packaged gait name, e.g. ``walk`` or ``slow``, a CSV in the
walk data format, or a ``Gait`` made elsewhere, e.g. from a bag) from its start and then its steady
stride (``gait_data.find_steady_cycle``) over and over, so a short recording teaches for as long as the
learning needs. A stride is taken only from a recording periodic by live teaching's own rule (its period
past the first lag correlating below ``PERIOD_DIP``, correlating at least ``min_correlation``): looping a
"stride" cut from a slow drift would make a periodic stream of it, which cpg_node would learn. A recording
without one (``periodic`` False) streams all of it over and over, for cpg_node to refuse ("not periodic");
``speed`` time-scales it (the gait at ``speed`` times its frequency: a stream the recorded gaits never
were). Teacher time starts at 0.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cpg_walker.errors import InputError
from cpg_walker.robot.gait_data import Gait, find_steady_cycle, load_gait
from cpg_walker.walker.controller import DOFS, HumanoidCPG
from cpg_walker.walker.learning import live_teaching_config
from cpg_walker.walker.live_teaching import PERIOD_DIP


class TeachingStream:
    """The ten DOFs of a recording at teacher time t: the recording, then its steady stride repeated."""

    def __init__(self, gait: str | Path | Gait, speed: float = 1.0) -> None:
        if not np.isfinite(speed) or speed <= 0:
            raise InputError(f"the teaching stream's speed must be a positive number, got {speed!r}")
        rec = gait if isinstance(gait, Gait) else load_gait(gait)
        missing = [j for j in DOFS if j not in rec.names]
        if missing:
            raise InputError(f"{rec.source}: the recording lacks the CPG's joint(s) {', '.join(missing)}")
        cols = [rec.names.index(j) for j in DOFS]
        self.gait = rec.__class__(rec.name, DOFS, rec.t, rec.q[:, cols], rec.source)
        cfg = live_teaching_config()  # a stride as long as cpg_node looks for, periodic as it judges
        try:
            cyc = find_steady_cycle(rec, lo=cfg.min_period_s, hi=cfg.max_period_s, dip=PERIOD_DIP,
                                    min_correlation=cfg.min_correlation)
            self.cycle_start, self.cycle_period = float(cyc.start), float(cyc.period)
            self.periodic, self.why_not_periodic = True, ""
        except InputError as exc:  # no gait in it: the whole recording over and over (cpg_node refuses it)
            self.cycle_start, self.cycle_period = 0.0, float(rec.duration)
            self.periodic, self.why_not_periodic = False, str(exc)
        self.speed = float(speed)
        self.names = DOFS
        self.source = rec.source

    @property
    def period_s(self) -> float:
        """The stream's stride period in teacher s (the recording's steady stride over ``speed``)."""
        return self.cycle_period / self.speed

    @property
    def frequency_hz(self) -> float:
        return 1.0 / self.period_s

    def at(self, t: float | np.ndarray) -> np.ndarray:
        """Angles (…, 10) at teacher time(s) ``t`` (s)."""
        r = np.asarray(t, dtype=float) * self.speed
        end = self.cycle_start + self.cycle_period
        looped = np.where(r < end, r, self.cycle_start + np.mod(r - self.cycle_start, self.cycle_period))
        return self.gait.at(looped)

    def recording_phase_s(self, t: float) -> float:
        """Teacher s since the steady stride last started at teacher time ``t`` (in [0, period_s))."""
        return float(np.mod(t - self.cycle_start / self.speed, self.period_s))

    def aligned(self, ctrl: HumanoidCPG, phase_zero_t: float) -> HumanoidCPG:
        """A controller learned from this stream (its phase 0 at teacher time ``phase_zero_t``) re-based on
        the recording: phase 0 moved to the steady stride's start and ``meta["teaching"]`` naming the
        recording, so it starts from the recording's opening steps as the offline-learned CPG does
        (``CPGGaitSource``'s "recording" transition) and saves as a file ``cpg_file`` loads."""
        ahead = (self.period_s - self.recording_phase_s(phase_zero_t)) % self.period_s
        ctrl.reset_phase(ahead / self.period_s * ctrl.period)  # run on to the stride's start
        ctrl.phase_zero_state = ctrl.net.state[:2].copy()
        ctrl.meta["teaching"].update(
            gait=self.gait.name,
            cycle_start_s=self.cycle_start, stream_speed=self.speed,
            description=f"taught live from {self.source} at {self.speed:g}x its speed; phase 0 is its steady "
                        f"stride's start")
        return ctrl
