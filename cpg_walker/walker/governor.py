"""The governor: any requested (ζ, α) in the declared ranges, at any moment, reached along a path the robot
walks (issue 24). Pure (no ROS); the gait source runs it once per control step after the CPG has taken
over, between the requests (parameters, /cmd_vel, schedules: `CPGGaitSource.command`) and the CPG's own
command filters (`HumanoidCPG.set_zeta` / ``set_alpha``, the cascaded C² lags).

What it does, each rule from a measured fall (config/governor.yaml says which):

* **Envelope**: α is at most ``Envelope.alpha_max(ζ)`` — the step length that walks at that frequency,
  interpolated from a measured table, forward and backward apart (slow walking needs short steps; |ζ|
  below the table's first point stands: α 0, while the oscillators keep turning at that first point's
  rhythm — near ζ 0 the learned network's phase relations drift: after 12 s at ζ 0.01 one DOF had moved
  1.6 rad from its place in the gait, and raising α 15 s after stepping off from there fell).
* **Longer steps with the ankle pathway**: ``ankle`` (optional) is the envelope while the ankle pathway is
  closed at full weight: the fast corner (α above 1 at |ζ| 1.5–1.7) walked only with it. ``needs_ankle``
  says when the request (or the applied step length) lies beyond the plain envelope but within it — what
  makes cpg_node close the ankle pathway in realtime (``ankle_for_speed``).
* **Slowing down**: when the requested ζ allows less α than is applied, α comes down first (ζ held) and
  ζ follows once the applied α fits the new ζ's envelope. **Speeding up** the other way round: α rises
  only once the applied ζ is within ``reverse_zeta_tolerance`` of the new one (both rising together fell:
  −0.48, α 0.59 → −1.0, α 1.0 at any rate tried, while each alone walked).
* **Reversal through a stop**: a request of the other direction brings α to 0 (ζ held), flips ζ once the
  applied α is below ``reverse_alpha``, waits until the applied ζ is within ``reverse_zeta_tolerance`` of
  the new one, then raises α at ``ramp_rate`` per s.
* **Rates**: α falls at most ``fall_rate`` per s (a stop within a stride fell at some phases) and rises at
  most ``rise_rate`` per s, from standing (after a stop, a reversal, or α 0) at most ``ramp_rate``; ζ moves
  at most ``zeta_rate`` per s within a direction. The CPG's own filters smooth what comes out.

``state`` says what it is doing (following | limited | slowing | accelerating | reversing | ramping |
standing | waiting) and
``reason`` why the commanded values differ from the requested ones ('' when they do not).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cpg_walker.errors import InputError
from cpg_walker.paths import config_path
from cpg_walker.walker.controller import ALPHA_RANGE, ZETA_RANGE, modulation_error

#: After a reversal the robot steps off at |ζ| at most this (the learned rhythm), then speeds up.
STEP_OFF_ZETA = 1.0
#: A state's α may exceed the envelope by this much before ζ waits for it (filter residue).
ALPHA_SLACK = 0.02


@dataclass(frozen=True)
class Envelope:
    """α_max per |ζ|, forward and backward: ((|ζ|, α_max), ...) sorted by |ζ|, linear in between, held
    past the last point; below the first point the robot stands (α 0)."""

    forward: tuple[tuple[float, float], ...]
    backward: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        for name, pts in (("forward", self.forward), ("backward", self.backward)):
            z = [p[0] for p in pts]
            if not pts or z != sorted(z) or len(set(z)) != len(z) or any(
                    not (math.isfinite(a) and a >= 0 and zz > 0) for zz, a in pts):
                raise InputError(f"governor envelope {name}: |zeta| points must be > 0, strictly increasing, "
                                 f"with finite alpha_max >= 0; got {pts}")

    @property
    def alpha_top(self) -> float:
        """The largest α_max of either direction."""
        return max(a for pts in (self.forward, self.backward) for _, a in pts)

    def slowest(self, zeta: float) -> float:
        """The smallest |ζ| that steps in ``zeta``'s direction (the table's first point)."""
        return (self.forward if zeta >= 0 else self.backward)[0][0]

    def alpha_max(self, zeta: float) -> float:
        pts = self.forward if zeta >= 0 else self.backward
        z = abs(zeta)
        if z < pts[0][0]:
            return 0.0
        xs, ys = zip(*pts, strict=True)
        return float(np.interp(z, xs, ys))


@dataclass(frozen=True)
class GovernorConfig:
    """The governor's envelopes and rates (config/governor.yaml): ``envelope`` with the feedback pathways
    closed, ``open_loop`` without them (None: the same), ``ankle`` with the ankle pathway closed too (None:
    the same as ``envelope``)."""

    envelope: Envelope
    open_loop: Envelope | None = None
    ankle: Envelope | None = None
    fall_rate: float = 0.5
    ramp_rate: float = 0.25
    rise_rate: float = 0.25
    zeta_rate: float = 0.25
    reverse_alpha: float = 0.05
    reverse_zeta_tolerance: float = 0.1

    @property
    def alpha_limit(self) -> float:
        """The top of the α range that walks: the largest α_max of the envelopes (longer steps fell at every
        ζ measured), at most the CPG's own limit."""
        tops = [e.alpha_top for e in (self.envelope, self.open_loop, self.ankle) if e is not None]
        return min(max(tops), ALPHA_RANGE[1])

    @classmethod
    def load(cls, path: str | Path | None = None) -> GovernorConfig:
        """config/governor.yaml (read once per process: the config is immutable), or the file at ``path``
        (read every time); a broken file: an InputError naming the file and the problem."""
        if not path:
            return _packaged()
        return cls._read(Path(path))

    @classmethod
    def _read(cls, p: Path) -> GovernorConfig:
        import yaml

        try:
            d = yaml.safe_load(p.read_text(encoding="utf-8"))
        except (OSError, yaml.YAMLError) as exc:
            raise InputError(f"{p}: {exc}") from None
        if not isinstance(d, dict) or not isinstance(d.get("envelope"), dict):
            raise InputError(f"{p}: expected a mapping with 'envelope: {{forward: ..., backward: ...}}'")

        def envelope(name: str) -> Envelope:
            env = d.pop(name)
            if not isinstance(env, dict):
                raise InputError(f"{p}: {name} must be a mapping with forward: and backward:")

            def table(key: str) -> tuple[tuple[float, float], ...]:
                rows = env.get(key)
                if not isinstance(rows, list) or not all(isinstance(r, list) and len(r) == 2 for r in rows):
                    raise InputError(f"{p}: {name}.{key} must be a list of [|zeta|, alpha_max] pairs")
                return tuple((float(z), float(a)) for z, a in rows)

            return Envelope(table("forward"), table("backward"))

        closed = envelope("envelope")
        open_loop = envelope("open_loop") if "open_loop" in d else None
        ankle = envelope("ankle") if "ankle" in d else None

        known = {"fall_rate", "ramp_rate", "rise_rate", "zeta_rate", "reverse_alpha",
                 "reverse_zeta_tolerance"}
        unknown = sorted(set(d) - known)
        if unknown:
            raise InputError(f"{p}: unknown key(s) {unknown}")
        rates = {k: float(v) for k, v in d.items()}
        if any(not (math.isfinite(v) and v > 0) for v in rates.values()):
            raise InputError(f"{p}: rates and tolerances must be finite and > 0, got {rates}")
        return cls(closed, open_loop, ankle, **rates)


@functools.cache
def _packaged() -> GovernorConfig:
    return GovernorConfig._read(config_path("governor.yaml"))


def command_range(name: str, governor: GovernorConfig | None) -> tuple[float, float]:
    """The accepted range of the ``zeta``/``alpha`` command: the CPG's own (controller.ZETA_RANGE,
    ALPHA_RANGE) without a governor; with one, α only up to what walks (``alpha_limit``)."""
    if name == "zeta":
        return ZETA_RANGE
    return (ALPHA_RANGE[0], ALPHA_RANGE[1] if governor is None else governor.alpha_limit)


def command_error(name: str, value: object, governor: GovernorConfig | None) -> str | None:
    """Why ``value`` is not an acceptable ``zeta``/``alpha`` command (None if it is): not a finite number
    in the CPG's range, or (with a governor) a step length longer than any that walked."""
    if reason := modulation_error(name, value):
        return reason
    lo, hi = command_range(name, governor)
    if not lo <= float(value) <= hi:
        return (f"{name} must be in [{lo:g}, {hi:g}], got {value!r}: longer steps fell at every zeta "
                f"measured "
                f"(the governor's envelope, config/governor.yaml; without the governor the raw CPG takes "
                f"up to {ALPHA_RANGE[1]:g})")
    return None


class Governor:
    """Requested (ζ, α) -> the (ζ, α) to command, one control step at a time (module docstring).
    ``zeta``, ``alpha``: what is commanded (and requested) when it starts."""

    def __init__(self, config: GovernorConfig, zeta: float, alpha: float) -> None:
        self.cfg = config
        self.requested = (float(zeta), float(alpha))
        self.zeta, self.alpha = float(zeta), float(alpha)  # the commands given to the CPG
        self.state, self.reason = "following", ""
        self._ramping = False

    def request(self, zeta: float, alpha: float) -> None:
        self.requested = (float(zeta), float(alpha))

    def reset(self, zeta: float, alpha: float) -> None:
        """Commanded = requested = (ζ, α): a re-entry (the CPG restarted at these commands)."""
        self.requested = self.zeta, self.alpha = float(zeta), float(alpha)
        self.state, self.reason, self._ramping = "following", "", False

    def needs_ankle(self, applied_zeta: float, applied_alpha: float) -> bool:
        """The ankle pathway is wanted: the request's step length, capped to the ``ankle`` envelope, is longer
        than the plain envelope allows, or the applied one still is (winding down)."""
        cfg = self.cfg
        if cfg.ankle is None:
            return False
        zr, ar = self.requested
        want = zr != 0.0 and min(ar, cfg.ankle.alpha_max(zr)) > cfg.envelope.alpha_max(zr) + ALPHA_SLACK
        return want or applied_alpha > cfg.envelope.alpha_max(applied_zeta) + ALPHA_SLACK

    def update(self, dt: float, applied_zeta: float, applied_alpha: float, open_loop: bool = False,
               ankle: bool = False, ankle_pending: bool = False) -> tuple[float, float]:
        """The (ζ, α) to command for the next ``dt`` s, given the CPG's applied (filtered) ζ and α;
        ``open_loop``: the feedback pathways are not (fully) closed (the ``open_loop`` envelope);
        ``ankle``: they are, the ankle pathway too (the ``ankle`` envelope, if any); ``ankle_pending``:
        the ankle pathway is fading in — a request that needs it waits, the steps as they are."""
        cfg = self.cfg
        if open_loop:
            env = cfg.open_loop or cfg.envelope
        else:
            env = cfg.ankle if ankle and cfg.ankle is not None else cfg.envelope
        if ankle_pending and not ankle and not open_loop and self.needs_ankle(applied_zeta, applied_alpha):
            return self._set("waiting", "for the ankle pathway to close (the longer steps walk only with it)",
                             self.zeta, min(self.alpha, env.alpha_max(self.zeta)), dt)
        zr, ar = self.requested
        too_slow = zr != 0.0 and abs(zr) < env.slowest(zr)
        if too_slow:  # it stands (α 0) with the oscillators at the slowest rhythm that steps (module doc)
            zr, ar = math.copysign(env.slowest(zr), zr), 0.0
        direction = 1.0 if self.zeta >= 0 else -1.0
        step_off = math.copysign(min(abs(zr), STEP_OFF_ZETA), zr)  # steps begin at most at the learned rhythm
        if zr != 0.0 and (zr > 0) != (direction > 0):  # the other way
            if applied_alpha > cfg.reverse_alpha or self.alpha > cfg.reverse_alpha:
                return self._set("reversing", f"reversing to zeta {zr:g} through a stop", self.zeta, 0.0, dt)
            self.zeta, self._ramping = step_off, True  # stepping has stopped: the new direction
        elif not self._ramping and self.alpha <= cfg.reverse_alpha < min(ar, env.alpha_max(zr)) and zr != 0.0:
            self.zeta, self._ramping = step_off, True  # stepping off from standing
        z_target = self.zeta if zr == 0.0 else zr  # ζ 0: stand, keeping the direction
        if self._ramping and self.alpha <= cfg.reverse_alpha \
                and abs(applied_zeta - self.zeta) > cfg.reverse_zeta_tolerance * abs(self.zeta):
            return self._set("reversing", f"to zeta {zr:g}: zeta {self.zeta:g} first, then steps", self.zeta,
                             0.0, dt)
        a_max = 0.0 if zr == 0.0 else env.alpha_max(z_target)  # ζ 0: stand
        a_target = min(ar, a_max)
        if self._ramping:  # steps growing at ramp_rate at the step-off ζ, then on to the requested ζ
            a_ramp = min(a_target, env.alpha_max(self.zeta))
            if self.alpha < a_ramp:
                return self._set("ramping", f"steps growing at {cfg.ramp_rate:g}/s at zeta {self.zeta:g}, "
                                 f"then zeta {z_target:g}", self.zeta, a_ramp, dt)
            self._ramping = False
        if applied_alpha > a_max + ALPHA_SLACK and abs(z_target) < abs(self.zeta):
            why = f"alpha {applied_alpha:.2f} down to {a_max:g} before zeta {z_target:g}"
            return self._set("slowing", why, self.zeta, a_target, dt)
        far = abs(applied_zeta - z_target) > cfg.reverse_zeta_tolerance * abs(z_target)
        if a_target > self.alpha and far:
            why = f"zeta {z_target:g} first, then alpha {a_target:.3g}"  # α and ζ rising together fell
            return self._set("accelerating", why, z_target, self.alpha, dt)
        limit = ""
        if too_slow:
            limit = f"zeta {self.requested[0]:g}: stands (the measured envelope), its rhythm held at {zr:g}"
            return self._set("standing", limit, z_target, 0.0, dt)
        if a_target < ar:
            why = "stands" if a_max == 0.0 else f"alpha limited to {a_max:.3g}"
            limit = f"zeta {z_target:g}: {why} (the measured envelope)"
            return self._set("standing" if a_max == 0.0 else "limited", limit, z_target, a_target, dt)
        return self._set("standing" if a_target == 0.0 else "following", "", z_target, a_target, dt)

    def _set(self, state: str, reason: str, zeta: float, alpha: float, dt: float) -> tuple[float, float]:
        """Command (ζ, α): α falls at most fall_rate per s and rises at most rise_rate (ramp_rate after a
        stop); ζ moves at most zeta_rate per s within a direction (a reversal flips it at α 0)."""
        cfg = self.cfg
        if alpha < self.alpha:
            alpha = max(alpha, self.alpha - cfg.fall_rate * dt)
        elif alpha > self.alpha:
            alpha = min(alpha, self.alpha + (cfg.ramp_rate if self._ramping else cfg.rise_rate) * dt)
        if zeta != self.zeta and (zeta > 0) == (self.zeta > 0):
            step = cfg.zeta_rate * dt
            zeta = min(max(zeta, self.zeta - step), self.zeta + step)
        self.zeta, self.alpha = zeta, alpha
        self.state, self.reason = state, reason
        return zeta, alpha
