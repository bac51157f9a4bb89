"""/cmd_vel (geometry_msgs/Twist) for the walking HOAP-2, without ROS: linear.x -> (ζ, α), angular.z ->
the heading pathway's turn rate, a command timeout, and direction changes.

* ``SpeedMap`` — the forward speed measured per ζ (α = 1) and per α at ζ = ±``slow_abs_zeta``, forward and
  backward (config/speed_map.yaml, which says how it was measured). Its inverse: |v| at or above the
  speed of ζ = ±1 (α = 1) -> ζ by monotone interpolation of the measured speeds at α = 1 (up to the
  fastest walkable ζ); below it -> α by interpolation of the measured speeds at ζ = ±1 (shorter steps at
  the learned rhythm; speed ≈ linear in α). Slower ζ than 1 are measured and recorded but not used:
  ζ 0.7 walks but 0.6 falls, and reversing into ζ −0.6 … −0.8 falls (docs/feedback.md, "Our pathways"), while
  α 0.2 … 1 at ζ ±1 walks. Continuous in v (the branches meet at ζ = ±1, α = 1). Past the fastest ζ at
  α 1, optional ``fast_speed`` nodes (ζ, α > 1, m/s) go on to longer steps: they walk only with the ankle
  pathway (config/governor.yaml ``ankle``), so a follower that cannot close it stops short of them
  (``CmdVelFollower.allow_fast``).
* ``CmdVelFollower`` — a small state machine on sim time: ``command(t, linear_x, angular_z)`` and
  ``update(t, applied_zeta, applied_alpha)`` -> ``CmdVelOutput`` (ζ, α, turn rate to command). States:
  ``waiting`` (no command yet: None, the node keeps its parameters' ζ/α), ``following``, ``standing``
  (|linear.x| below ``stand_below``: α -> 0, the robot stands), ``reversing`` (the sign of linear.x flipped
  while stepping: α -> 0 first, ζ swapped once the applied α is below REVERSE_ALPHA, α back once the
  applied ζ is within REVERSE_ZETA_TOLERANCE of the new one), ``ramping`` (after a reversal the α command
  rises at most REVERSE_ALPHA_RATE per sim s: measured safer, docs/cmd_vel.md), ``timed_out`` (no command for
  ``timeout`` sim s: α -> 0, turn 0, like diff_drive_controller's cmd_vel_timeout; the next command
  resumes). α -> 0 is smooth: HumanoidCPG's cascaded ζ/α command filter (3 × 0.25 s lags).
* Turning: angular.z (clamped to ±``max_angular_z``) is FeedbackController.set_turn_rate: the heading
  reference advances at that rate. Anti-windup: ``apply_output`` sets the controller's
  ``heading_window_rad`` (|reference − yaw| ≤ the error that saturates heading_limit_rad) while turning,
  and when the turn command returns to 0 it takes the walked heading (the reference minus the filtered
  error: the stride-mean yaw) as the new reference (``hold_heading``), so the robot keeps its new
  heading instead of turning on through the lag that built up.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from cpg_walker.errors import InputError

#: keys of a CmdVelLimits (and of cpg_node's ``cmd_vel.<key>`` parameters)
LIMIT_KEYS = ("timeout", "max_linear_x", "min_linear_x", "max_angular_z", "stand_below", "alpha_fall_rate",
              "max_linear_y", "steer_zeta", "steer_alpha", "turn_alpha", "angular_z_rate",
              "angular_z_rate_in_place", "side_step_max_alpha")


def _read_yaml(path: str | Path | None, default: str) -> tuple[dict, Path]:
    import yaml

    from cpg_walker.paths import config_path, yaml_error

    p = Path(path) if path else config_path(default)
    if not p.is_file() and path and not Path(path).is_absolute():
        try:
            p = config_path(str(path))
        except FileNotFoundError:
            pass
    if not p.is_file():
        raise InputError(f"speed map file not found: {path}")
    with open(p, encoding="utf-8") as fh:
        try:
            d = yaml.safe_load(fh) or {}
        except yaml.YAMLError as exc:
            raise InputError(yaml_error(p, exc)) from None
    if not isinstance(d, dict):
        raise InputError(f"{p}: expected a mapping")
    return d, p


def _pairs(d: dict, key: str, where: str) -> np.ndarray:
    v = d.get(key)
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{where}.{key}: expected a list of [x, speed] pairs, got {v!r}") from None
    if a.ndim != 2 or a.shape[1] != 2 or len(a) < 1 or not np.all(np.isfinite(a)):
        raise InputError(f"{where}.{key}: expected a non-empty list of finite [x, speed] pairs, got {v!r}")
    return a[np.argsort(np.abs(a[:, 0]))]


def monotone(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares non-decreasing fit of y over sorted x (pool adjacent violators), with every
    pooled block merged into one point (mean x, pooled y): strictly increasing in both."""
    blocks: list[list[float]] = []  # [sum x, sum y, n]
    for xi, yi in zip(x, y, strict=True):
        blocks.append([float(xi), float(yi), 1.0])
        while len(blocks) > 1 and blocks[-2][1] / blocks[-2][2] >= blocks[-1][1] / blocks[-1][2]:
            last = blocks.pop()
            blocks[-1] = [blocks[-1][0] + last[0], blocks[-1][1] + last[1], blocks[-1][2] + last[2]]
    return (np.array([b[0] / b[2] for b in blocks]), np.array([b[1] / b[2] for b in blocks]))


def fast_chain(top: float, fast: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Effort c and (|ζ|, α) of (top, 1) followed by the fast nodes ``fast`` ((|ζ|, α) rows): c advances
    by |Δζ| + |Δα| from ``top``."""
    za = np.vstack([[top, 1.0], fast])
    return top + np.concatenate([[0.0], np.cumsum(np.abs(np.diff(za, axis=0)).sum(axis=1))]), za


@dataclass(frozen=True)
class Branch:
    """One walking direction (``sign`` ±1) as one chain of "effort" c, s = slow_abs_zeta: c < s ->
    (ζ = ±s, α = c / s), s <= c <= top (the fastest ζ at α 1) -> (ζ = ±c, α = 1), continuous at c = s;
    past ``top``, the fast nodes ``fast`` ((|ζ|, α) rows, α > 1, reached with the ankle pathway), linear in
    c between them, c advancing by |Δζ| + |Δα| from (top, 1). ``c`` and ``speed`` (|v|) strictly
    increasing (the measured points made monotone by ``monotone``)."""

    sign: float
    slow: float
    c: np.ndarray
    speed: np.ndarray
    top: float = math.inf
    fast: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def v_min(self) -> float:
        return float(self.speed[0])

    @property
    def v_max(self) -> float:
        return float(self.speed[-1])

    @property
    def v_plain(self) -> float:
        """The fastest |v| without the fast nodes (ζ at ``top``, α 1)."""
        return float(np.interp(self.top, self.c, self.speed)) if self.top < math.inf else self.v_max

    def modulation(self, c: float) -> tuple[float, float]:
        """(ζ, α) of effort c."""
        if c > self.top and len(self.fast):
            cs, za = fast_chain(self.top, self.fast)
            return self.sign * float(np.interp(c, cs, za[:, 0])), float(np.interp(c, cs, za[:, 1]))
        if c >= self.slow:
            return self.sign * c, 1.0
        return self.sign * self.slow, c / self.slow

    def inverse(self, speed: float) -> tuple[float, float]:
        """(ζ, α) for |v| = ``speed``, clamped to [v_min, v_max]."""
        s = min(max(abs(speed), self.v_min), self.v_max)
        return self.modulation(float(np.interp(s, self.speed, self.c)))

    def speed_at(self, zeta: float, alpha: float) -> float:
        """The map's signed speed at (ζ, α) (α < 1 only at the slow ζ; α > 1 on the fast nodes, by α)."""
        if alpha > 1.0 and len(self.fast):
            cs, za = fast_chain(self.top, self.fast)
            c = float(np.interp(alpha, za[:, 1], cs))
        else:
            c = alpha * self.slow if alpha < 1.0 else min(abs(zeta), self.top)
        return self.sign * float(np.interp(c, self.c, self.speed))


class SpeedMap:
    """Measured speed vs (ζ, α) and its inverse (module docstring). ``load(path)``: a YAML with
    ``slow_abs_zeta`` and ``forward`` / ``backward`` mappings of ``zeta_speed`` ([ζ, m/s] at α = 1),
    ``alpha_speed`` ([α, m/s] at ζ = ±slow_abs_zeta) and optionally ``fast_speed`` ([ζ, α, m/s], α > 1);
    anything else (how it was measured) is kept as ``meta``. The measured points are made monotone
    (``monotone``: measurement noise can make ζ 1.4 slower than 1.3); bad data (wrong signs, ζ =
    ±slow_abs_zeta missing) raise ValueError naming the file and key."""

    def __init__(self, data: dict, origin: str = "<dict>"):
        self.origin = origin
        slow = data.get("slow_abs_zeta", 1.0)
        if isinstance(slow, bool) or not isinstance(slow, (int, float)) or not (0 < slow <= 2):
            raise InputError(f"{origin}: slow_abs_zeta must be in (0, 2], got {slow!r}")
        self.slow_abs_zeta = float(slow)
        self.meta = {k: v for k, v in data.items() if k not in ("slow_abs_zeta", "forward", "backward")}
        self.forward = self._branch(data, "forward", 1.0)
        self.backward = self._branch(data, "backward", -1.0)

    def _branch(self, data: dict, key: str, sign: float) -> Branch:
        where = f"{self.origin}: {key}"
        d = data.get(key)
        if not isinstance(d, dict):
            raise InputError(f"{where}: missing (a mapping with zeta_speed and alpha_speed)")
        z, a = _pairs(d, "zeta_speed", where), _pairs(d, "alpha_speed", where)
        rel = "> 0" if sign > 0 else "< 0"
        if np.any(np.sign(z[:, 0]) != sign) or np.any(np.sign(z[:, 1]) != sign):
            raise InputError(f"{where}.zeta_speed: every zeta and speed must be {rel}")
        if np.any(np.sign(a[:, 1]) != sign) or np.any(a[:, 0] <= 0) or np.any(a[:, 0] >= 1):
            raise InputError(f"{where}.alpha_speed: alpha in (0, 1), speeds {rel}")
        s = self.slow_abs_zeta
        z = z[np.abs(z[:, 0]) >= s - 1e-9]
        if len(z) < 1 or abs(abs(z[0, 0]) - s) > 1e-9:
            raise InputError(f"{where}.zeta_speed: needs the point at zeta = {sign * s:g}")
        top = float(abs(z[-1, 0]))
        fast = self._fast(d, where, sign, top)
        c = np.concatenate([a[:, 0] * s, np.abs(z[:, 0])])
        v = np.abs(np.concatenate([a[:, 1], z[:, 1]]))
        if len(fast):
            c = np.concatenate([c, fast_chain(top, fast[:, :2])[0][1:]])
            v = np.concatenate([v, np.abs(fast[:, 2])])
        c, v = monotone(c, v)
        return Branch(sign, s, c, v, top, fast[:, :2])

    @staticmethod
    def _fast(d: dict, where: str, sign: float, top: float) -> np.ndarray:
        """The optional ``fast_speed`` rows [ζ, α, m/s] (α > 1, |ζ| >= the fastest ζ at α 1, both not
        decreasing, α rising), as (|ζ|, α, |v|)."""
        if "fast_speed" not in d:
            return np.zeros((0, 3))
        v = d["fast_speed"]
        try:
            f = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"{where}.fast_speed: expected a list of [zeta, alpha, speed] rows, got {v!r}") \
                from None
        if f.ndim != 2 or f.shape[1] != 3 or len(f) < 1 or not np.all(np.isfinite(f)):
            raise InputError(f"{where}.fast_speed: expected a non-empty list of finite [zeta, alpha, speed] "
                             f"rows, got {v!r}")
        rel = "> 0" if sign > 0 else "< 0"
        if np.any(np.sign(f[:, 0]) != sign) or np.any(np.sign(f[:, 2]) != sign):
            raise InputError(f"{where}.fast_speed: every zeta and speed must be {rel}")
        za = np.vstack([[top, 1.0], np.abs(f[:, :2])])
        if np.any(np.diff(za[:, 0]) < 0) or np.any(np.diff(za[:, 1]) <= 0):
            raise InputError(f"{where}.fast_speed: alpha must rise above 1 and |zeta| not fall below the "
                             f"fastest zeta at alpha 1 ({top:g}), row by row")
        return np.abs(f)

    @classmethod
    def load(cls, path: str | Path | None = None) -> SpeedMap:
        """The map in ``path`` (a file, or a name in the package's config/; None: config/speed_map.yaml)."""
        d, p = _read_yaml(path, "speed_map.yaml")
        return cls(d, str(p))

    @property
    def v_max(self) -> float:
        """Fastest forward speed (m/s)."""
        return self.forward.v_max

    @property
    def v_min(self) -> float:
        """Fastest backward speed (m/s, negative)."""
        return -self.backward.v_max

    def inverse(self, v: float) -> tuple[float, float]:
        """(ζ, α) of the signed speed v != 0 (m/s), clamped to the walkable range of its direction."""
        if not math.isfinite(v) or v == 0:
            raise ValueError(f"speed map inverse needs a finite non-zero speed, got {v}")
        return (self.forward if v > 0 else self.backward).inverse(v)

    def speed(self, zeta: float, alpha: float = 1.0) -> float:
        """The map's speed (m/s) at (ζ, α)."""
        return (self.forward if zeta > 0 else self.backward).speed_at(zeta, alpha)

    def alpha_at(self, v: float, abs_zeta: float) -> float:
        """The α (<= 1) that walks at signed speed v at |ζ| = ``abs_zeta``, taking the speed at a given ζ
        as proportional to α (v(ζ, α) ≈ α·v(ζ, 1): the map's α points at ζ ±1 lie within 0.02 m/s of
        it above α 0.4)."""
        full = abs(self.speed(math.copysign(abs_zeta, v), 1.0))
        return min(abs(v) / full, 1.0) if full > 0 else 1.0

    def command(self, linear_x: float, limits: CmdVelLimits, fast: bool = True) -> tuple[float, float]:
        """(ζ, α) for a linear.x: clamped to the limits (without ``fast``, also to the speeds short of the
        fast nodes), |v| < stand_below -> (1 or −1 by sign, 0)."""
        v = limits.clamp_linear(linear_x)
        if not fast:
            top = (self.forward if v > 0 else self.backward).v_plain
            v = min(max(v, -top), top)
        if abs(v) < limits.stand_below:
            return (math.copysign(self.slow_abs_zeta, v) if v else self.slow_abs_zeta), 0.0
        return self.inverse(v)


@dataclass(frozen=True)
class CmdVelLimits:
    """The /cmd_vel limits (cpg_node's ``cmd_vel.*`` parameters; defaults in config/cpg.yaml):
    ``timeout`` sim s, linear.x in [min_linear_x, max_linear_x] m/s, |angular.z| <= max_angular_z rad/s,
    |linear.x| < stand_below -> stand (α 0), the α command falls at most ``alpha_fall_rate`` per sim s
    (a stop — timeout, standing, reversal — takes 1 / alpha_fall_rate s: the robot decelerates over
    strides instead of freezing mid-stride; measured, docs/cmd_vel.md)."""

    timeout: float
    max_linear_x: float
    min_linear_x: float
    max_angular_z: float
    stand_below: float
    alpha_fall_rate: float
    max_linear_y: float = 0.0
    steer_zeta: float = 1.5
    steer_alpha: float = 0.3
    turn_alpha: float = 0.25
    angular_z_rate: float = 0.3
    angular_z_rate_in_place: float = 1.0
    side_step_max_alpha: float = 1.0  # α at most while side-stepping (the forward speed beside it)

    def __post_init__(self) -> None:
        for k in LIMIT_KEYS:
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"cmd_vel.{k} must be a finite number, got {v!r}")
        if not self.timeout > 0:
            raise ValueError(f"cmd_vel.timeout must be > 0 s, got {self.timeout}")
        if not self.max_linear_x >= 0 or not self.min_linear_x <= 0:
            raise ValueError(f"cmd_vel.max_linear_x must be >= 0 and cmd_vel.min_linear_x <= 0, got "
                             f"{self.max_linear_x} / {self.min_linear_x}")
        if not 0 <= self.max_angular_z <= 1.0:
            raise ValueError(f"cmd_vel.max_angular_z must be in [0, 1] rad/s, got {self.max_angular_z}")
        if not 0 <= self.max_linear_y <= 0.2:
            raise ValueError(f"cmd_vel.max_linear_y must be in [0, 0.2] m/s, got {self.max_linear_y}")
        if not 0.3 <= self.steer_zeta <= 2.0:
            raise ValueError(f"cmd_vel.steer_zeta must be in [0.3, 2], got {self.steer_zeta}")
        for k in ("steer_alpha", "turn_alpha", "side_step_max_alpha"):
            if not 0 < getattr(self, k) <= 1.0:
                raise ValueError(f"cmd_vel.{k} must be in (0, 1], got {getattr(self, k)}")
        for k in ("angular_z_rate", "angular_z_rate_in_place"):
            if not getattr(self, k) > 0:
                raise ValueError(f"cmd_vel.{k} must be > 0 rad/s^2, got {getattr(self, k)}")
        if self.side_step_max_alpha < self.steer_alpha:
            raise ValueError(f"cmd_vel.side_step_max_alpha must be >= cmd_vel.steer_alpha (a side step "
                             f"in place steps at steer_alpha), got {self.side_step_max_alpha} < "
                             f"{self.steer_alpha}")
        if not self.stand_below >= 0:
            raise ValueError(f"cmd_vel.stand_below must be >= 0, got {self.stand_below}")
        if not self.alpha_fall_rate > 0:
            raise ValueError(f"cmd_vel.alpha_fall_rate must be > 0 per s, got {self.alpha_fall_rate}")

    @classmethod
    def load(cls, path: str | Path | None = None, **overrides: float) -> CmdVelLimits:
        """From cpg_node's parameters file (config/cpg.yaml: ``cmd_vel.<key>``), with overrides."""
        from cpg_walker.paths import config_path, ros_parameters

        p = ros_parameters(path or config_path("cpg.yaml"), "cpg")
        d = {k: p.get(f"cmd_vel.{k}") for k in LIMIT_KEYS}
        d.update(overrides)
        missing = [k for k, v in d.items() if v is None]
        if missing:
            raise InputError(f"cmd_vel limits: missing {missing} in {path or 'config/cpg.yaml'}")
        return cls(**{k: float(v) for k, v in d.items()})

    def clamp_linear(self, v: float) -> float:
        return min(max(float(v), self.min_linear_x), self.max_linear_x)

    def clamp_angular(self, w: float) -> float:
        return min(max(float(w), -self.max_angular_z), self.max_angular_z)

    def clamp_lateral(self, v: float) -> float:
        return min(max(float(v), -self.max_linear_y), self.max_linear_y)

    def as_dict(self) -> dict:
        return asdict(self)


def check_twist(linear_x: float, angular_z: float, others: tuple[float, ...] = (),
                linear_y: float = 0.0) -> None:
    """ValueError with the reason for a Twist the robot must not follow: non-finite components (the
    unused ones, ``others``, too: a NaN anywhere says the sender is broken)."""
    for name, v in (("linear.x", linear_x), ("linear.y", linear_y), ("angular.z", angular_z)):
        if not math.isfinite(v):
            raise ValueError(f"non-finite {name} ({v})")
    if not all(math.isfinite(v) for v in others):
        raise ValueError("non-finite linear.z or angular.x/y")


@dataclass(frozen=True)
class CmdVelOutput:
    """What to command now: ζ, α (HumanoidCPG.set_zeta/set_alpha), turn rate (rad/s), the state and the
    sideways speed (m/s, the side step's amplitude)."""

    zeta: float
    alpha: float
    turn_rate: float
    state: str
    linear_y: float = 0.0


#: |angular.z| (rad/s) from which a Twist with linear.x ~ 0 steps in place to turn
STEER_MIN_ANGULAR_Z = 0.02
#: |angular.z| (rad/s) up to which a walk turns at the speed map's (ζ, α) (the hip-yaw amplitude of the
#: closed loop alone walked it: 0.134-0.140 rad/s at 0.15); faster turns step at cmd_vel.steer_zeta
GENTLE_TURN = 0.15
#: ... and only once the applied α is within this of the steering α, as the side step (a fast turn on
#: long steps fell: in-process, the governed walk at α 1 turned in place at 0.5 rad/s fell 1.8 s after
#: the command; a side step without the ankle pathway 2.4 s after it)
TURN_ALPHA_TOLERANCE = 0.1
#: ... and, walking (not in place), the applied |ζ| within this of steer_zeta (the walk at 0.08 m/s
#: turning 0.3 rad/s at once, without the ankle pathway, fell 3.5 s after the command with ζ on its way)
TURN_ZETA_TOLERANCE = 0.15
#: Reversal: α command 0 until the applied α is below this, ...
REVERSE_ALPHA = 0.05
#: ... then the new ζ, α 0 until the applied ζ is this close (fraction of |new ζ|) to it, ...
REVERSE_ZETA_TOLERANCE = 0.1
#: ... then the α command rises at most this fast (per sim s; measured: docs/cmd_vel.md).
REVERSE_ALPHA_RATE = 0.05


class CmdVelFollower:
    """Twist commands -> (ζ, α, turn rate) over sim time (module docstring). ``zeta``: the ζ commanded
    before the first Twist (its sign is the current walking direction)."""

    def __init__(self, speed_map: SpeedMap, limits: CmdVelLimits, zeta: float = 1.0):
        self.map, self.limits = speed_map, limits
        self.zeta = float(zeta) if zeta else 1.0  # the ζ commanded (direction: its sign)
        self.state = "waiting"
        self.last: tuple[float, float, float] | None = None  # (t, linear.x, angular.z) as received
        self.linear_y = 0.0  # as received
        self.target: tuple[float, float, float] = (self.zeta, 0.0, 0.0)
        self.target_y = 0.0
        self._turn_out = 0.0  # the turn rate output (slewed at limits.angular_z_rate[_in_place])
        self.side_step_allowed = True  # False: linear.y is taken as 0 (``allow_side_step``)
        self.fast_allowed = True  # False: linear.x short of the speed map's fast nodes (``allow_fast``)
        self._reversing = False  # direction swapped, waiting for the applied ζ
        self.reverse_via_stop = True  # False: flip ζ at once (measured against; docs/cmd_vel.md)
        self.alpha_rate: float | None = None  # limit on every rise of the α command (per sim s); None: none
        self.reverse_alpha_rate: float | None = REVERSE_ALPHA_RATE  # ... after a reversal
        self._ramp = False
        self._t_prev, self._alpha_out = 0.0, 1.0

    def allow_side_step(self, allowed: bool) -> None:
        """Whether linear.y can be followed (cpg_node: not without the ankle pathway); refused, a Twist's
        linear.y counts as 0 (a side step alone then stands)."""
        if bool(allowed) != self.side_step_allowed:
            self.side_step_allowed = bool(allowed)
            if self.last is not None:
                self._retarget()

    def allow_fast(self, allowed: bool) -> None:
        """Whether linear.x may reach the speed map's fast nodes (cpg_node: not without the ankle pathway);
        refused, a faster linear.x walks at the fastest speed short of them."""
        if bool(allowed) != self.fast_allowed:
            self.fast_allowed = bool(allowed)
            if self.last is not None:
                self._retarget()

    @property
    def side_step_commanded(self) -> bool:
        """The last Twist's side step is followed or waited for (a non-zero linear.y that may side-step,
        not timed out)."""
        return self.last is not None and self.target_y != 0.0 and self.state != "timed_out"

    def set_limits(self, limits: CmdVelLimits) -> None:
        self.limits = limits
        if self.last is not None:
            self._retarget()

    def command(self, t: float, linear_x: float, angular_z: float,
                linear_y: float = 0.0) -> CmdVelOutput | None:
        """A Twist at sim time t (ValueError for a bad one: nothing changes)."""
        check_twist(linear_x, angular_z, linear_y=linear_y)
        if not math.isfinite(t):
            raise ValueError(f"non-finite command time {t}")
        self.last = (float(t), float(linear_x), float(angular_z))
        self.linear_y = float(linear_y)
        self._retarget()
        return None

    def _retarget(self) -> None:
        """The target (ζ, α, turn rate) and sideways speed of the last Twist. A turn faster than
        GENTLE_TURN, or a sideways speed of at least stand_below, steps at |ζ| >= steer_zeta and α >=
        steer_alpha, its forward speed kept by the α at that ζ (``SpeedMap.alpha_at``); with |linear.x|
        below stand_below a side step steps in place at (+steer_zeta, steer_alpha) (forward steps: a
        backward walker reverses first), a turn alone of at least STEER_MIN_ANGULAR_Z at (±steer_zeta,
        turn_alpha) in the walking direction. Gentler turns walk at the speed map's (ζ, α).
        Beside a side step α is at most side_step_max_alpha (at ±steer_zeta): linear.x is followed only
        up to the speed of those steps."""
        _, vx, wz = self.last  # type: ignore[misc]
        lim = self.limits
        wz, vy = lim.clamp_angular(wz), lim.clamp_lateral(self.linear_y) if self.side_step_allowed else 0.0
        side = abs(vy) >= max(lim.stand_below, 1e-9)
        z, a = self.map.command(vx, lim, self.fast_allowed)
        if a == 0.0:
            z = self.zeta  # standing (or stepping in place): keep the walking direction ...
            if side:  # ... but a side step steps forward (with backward steps it barely moved sideways)
                z, a = lim.steer_zeta, lim.steer_alpha
            elif abs(wz) >= STEER_MIN_ANGULAR_Z:
                z, a = math.copysign(lim.steer_zeta, z), lim.turn_alpha
        elif (side or abs(wz) > GENTLE_TURN) and abs(z) < lim.steer_zeta:
            v = lim.clamp_linear(vx)
            z = math.copysign(lim.steer_zeta, v)
            a = max(self.map.alpha_at(v, lim.steer_zeta), lim.steer_alpha)
        if side and a > lim.side_step_max_alpha:  # longer steps beside a side step fell: walk slower
            z, a = math.copysign(lim.steer_zeta, z), lim.side_step_max_alpha
        self.target = (z, a, wz if a > 0 else 0.0)
        self.target_y = vy if a > 0 else 0.0

    def update(self, t: float, applied_zeta: float, applied_alpha: float) -> CmdVelOutput | None:
        """What to command at sim time t, given the controller's applied (filtered) ζ and α; None while
        no Twist has come."""
        if self.last is None:
            return None
        if t - self.last[0] > self.limits.timeout:
            self.state = "timed_out"
            return self._out(t, self.zeta, 0.0, 0.0)
        z, a, w = self.target
        if a == 0.0:
            self.state = "standing"
            return self._out(t, self.zeta, 0.0, 0.0)
        if math.copysign(1.0, z) != math.copysign(1.0, self.zeta) and self.reverse_via_stop:  # flips
            if applied_alpha > REVERSE_ALPHA:
                self.state = "reversing"  # stop stepping first
                return self._out(t, self.zeta, 0.0, 0.0)
            self.zeta, self._reversing = z, True  # stepping has stopped: swap the direction
        if self._reversing:
            if abs(applied_zeta - z) > REVERSE_ZETA_TOLERANCE * abs(z):
                self.state = "reversing"  # the new ζ first, then step again
                return self._out(t, z, 0.0, 0.0)
            self._reversing, self._ramp = False, True
        vy = self.target_y
        in_place = self.map.command(self.last[1], self.limits)[1] == 0.0
        if applied_alpha > a + TURN_ALPHA_TOLERANCE or (  # a fast turn or a side step waits for the steps
                not in_place and abs(applied_zeta) < self.limits.steer_zeta - TURN_ZETA_TOLERANCE):
            vy = 0.0
            if abs(w) > GENTLE_TURN:
                w = math.copysign(GENTLE_TURN, w)
        self.zeta = z
        self.state = "stepping in place" if in_place else "following"
        rate = self.alpha_rate
        if rate is None and self._ramp:
            rate = self.reverse_alpha_rate
        if rate is not None:  # the α command rises at most ``rate`` per sim s
            ramped = self._alpha_out + rate * max(t - self._t_prev, 0.0)
            if ramped < a:
                a = ramped
                self.state = "ramping"
            else:
                self._ramp = False
        return self._out(t, z, a, w, vy)

    def _out(self, t: float, z: float, a: float, w: float, vy: float = 0.0) -> CmdVelOutput:
        dt = max(t - self._t_prev, 0.0)
        if a < self._alpha_out:  # the α command falls at most limits.alpha_fall_rate per sim s
            a = max(a, self._alpha_out - self.limits.alpha_fall_rate * dt)
        lim = self.limits  # the turn rate moves at most angular_z_rate(_in_place) per sim s
        step = (lim.angular_z_rate_in_place if self.state == "stepping in place" else lim.angular_z_rate) * dt
        w = min(max(w, self._turn_out - step), self._turn_out + step)
        if w * self._turn_out < 0.0:  # the turn reverses: through 0 for a tick (apply_output: hold heading)
            w = 0.0
        self._t_prev, self._alpha_out, self._turn_out = t, a, w
        return CmdVelOutput(z, a, w, self.state, vy)


def apply_output(source, out: CmdVelOutput) -> None:
    """Command ``out`` to a gait source (its ``command``: the one entry point of ζ and α) and to its
    feedback controller ``source.fb`` (None: no turning possible), with the heading anti-windup (module
    docstring)."""
    ctrl = source.ctrl
    if (ctrl.zeta_command, ctrl.alpha_command) != (out.zeta, out.alpha):
        source.command(out.zeta, out.alpha)
    fb = getattr(source, "fb", None)
    if fb is None:
        return
    source.side_step = out.linear_y
    if out.turn_rate != 0.0:
        cfg = fb.cfg
        fb.heading_window_rad = cfg.heading_limit_rad / cfg.heading_gain if cfg.heading_gain > 0 else 0.0
    elif fb.turn_rate != 0.0:
        fb.hold_heading()
    if fb.turn_rate != out.turn_rate:
        fb.set_turn_rate(out.turn_rate)
