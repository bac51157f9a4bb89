"""Per-joint PID servo law of the HOAP-2, a pure class over arrays (no MuJoCo, no ROS).

    tau = kp*(q* - q) + ki*I + kd*(qd* - qd),   I = integral of (q* - q) dt

then clamped to +-max_torque. Anti-windup: the integral term is clamped to +-integral_limit (N*m), and the
integral does not grow while the output is saturated in the direction of the error. Velocity limit: a
joint already moving faster than max_velocity gets no torque that would speed it up further (the motor's
no-load speed). Non-finite inputs are refused with a ValueError naming the joint.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from cpg_walker.robot.joints import GROUPS, JOINT_NAMES, MAX_TORQUE_NM, MAX_VELOCITY_RADS, group_of

#: The pid node's name: its parameters are ``pid: ros__parameters:`` in config/pid.yaml.
PID_NODE = "pid"
#: The gains, each per joint group (``kp.leg``) or per joint (``kp.lleg_joint_4``, overriding its group).
GAINS = ("kp", "ki", "kd")
#: The law's scalar settings (N*m, N*m, rad/s).
LIMITS = ("max_torque", "integral_limit", "max_velocity")


def load_pid_config(path: str | Path | None = None) -> dict:
    """The pid node's ROS parameters from ``config/pid.yaml`` (or ``path``), flattened as ROS does
    (``kp.leg``, ``max_torque``, ...): the same values pid_node gets through ``--params-file``."""
    from cpg_walker.paths import ros_parameters

    return ros_parameters("pid.yaml" if path is None else Path(path), PID_NODE)


def gain_owner(name: str) -> str:
    """The group or joint a gain parameter (``kp.leg``, ``kd.rarm_joint_2``) sets; ValueError if neither."""
    gain, _, owner = name.partition(".")
    if gain not in GAINS or not (owner in GROUPS or owner in JOINT_NAMES):
        raise ValueError(f"pid parameter {name!r}: expected <{'|'.join(GAINS)}>.<group or joint name> with "
                         f"group one of {', '.join(GROUPS)}")
    return owner


class PidLaw:
    """Independent PID servos for the joints ``names`` with per-joint gains (arrays of len(names))."""

    def __init__(
        self,
        names: Sequence[str],
        kp: Sequence[float] | np.ndarray,
        ki: Sequence[float] | np.ndarray,
        kd: Sequence[float] | np.ndarray,
        max_torque: float | Sequence[float] = MAX_TORQUE_NM,
        integral_limit: float = math.inf,
        max_velocity: float | None = MAX_VELOCITY_RADS,
    ):
        self.names = tuple(names)
        n = len(self.names)
        self.kp, self.ki, self.kd = (self._vector(x) for x in (kp, ki, kd))
        self.max_torque = np.broadcast_to(np.asarray(max_torque, dtype=float), (n,)).copy()
        checks = ((self.kp, "kp"), (self.ki, "ki"), (self.kd, "kd"), (self.max_torque, "max_torque"))
        for arr, label in checks:
            if not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ValueError(f"PID {label} must be finite and >= 0, got {arr}")
        if not integral_limit >= 0:  # inf (the default: no clamp) is allowed, nan is not
            raise ValueError(f"PID integral_limit must be >= 0, got {integral_limit}")
        self.integral_limit = float(integral_limit)
        self.max_velocity = None if max_velocity is None else float(max_velocity)
        self.integral = np.zeros(n)

    def _vector(self, x) -> np.ndarray:
        return np.broadcast_to(np.asarray(x, dtype=float), (len(self.names),)).copy()

    @classmethod
    def from_config(
        cls, names: Sequence[str] = JOINT_NAMES, config: Mapping | None = None, scale_kp: float = 1.0,
        scale_kd: float = 1.0,
    ) -> PidLaw:
        """The law from the pid parameters (``load_pid_config()`` by default, or a mapping with the same
        flat keys, e.g. pid_node's current parameters): ``kp.<group>`` etc. for every group, overridden
        by ``kp.<joint>``, and max_torque, integral_limit, max_velocity. Other keys (pid_node's watchdog
        settings) are ignored. ``scale_kp``/``scale_kd`` multiply every gain (for margin sweeps)."""
        cfg = load_pid_config() if config is None else config
        missing = [f"{g}.{group}" for g in GAINS for group in GROUPS if f"{g}.{group}" not in cfg]
        missing += [k for k in LIMITS if k not in cfg]
        if missing:
            raise ValueError(f"pid config: missing {', '.join(missing)}")
        for key in cfg:
            if key.split(".", 1)[0] in GAINS:
                gain_owner(key)  # a typo (kp.legg) is an error, not a silently ignored gain
        gains = {g: np.array([float(cfg.get(f"{g}.{name}", cfg[f"{g}.{group_of(name)}"])) for name in names])
                 for g in GAINS}
        return cls(
            names, gains["kp"] * scale_kp, gains["ki"], gains["kd"] * scale_kd,
            max_torque=float(cfg["max_torque"]), integral_limit=float(cfg["integral_limit"]),
            max_velocity=float(cfg["max_velocity"]),
        )

    def reset(self) -> None:
        """Forget the integral (call when the robot is reset or the targets jump)."""
        self.integral[:] = 0.0

    def _check(self, label: str, x) -> np.ndarray:
        arr = np.asarray(x, dtype=float)
        if arr.shape != (len(self.names),):
            raise ValueError(f"PID {label}: expected {len(self.names)} values, got shape {arr.shape}")
        bad = ~np.isfinite(arr)
        if bad.any():
            joints = [self.names[i] for i in np.flatnonzero(bad)]
            raise ValueError(f"PID {label}: non-finite value for joint(s) {joints}")
        return arr

    def step(self, target_pos, target_vel, measured_pos, measured_vel, dt: float) -> np.ndarray:
        """Torques (N*m) for one control period ``dt`` (s); updates the integral. Every input is checked.
        ``dt`` = 0 is the first sample of a run (no interval yet: the integral does not change)."""
        self._check_dt(dt, first_sample=True)
        qt = self._check("target_pos", target_pos)
        vt = self._check("target_vel", target_vel)
        q = self._check("measured_pos", measured_pos)
        v = self._check("measured_vel", measured_vel)
        err = qt - q
        pd = self.kp * err + self.kd * (vt - v)
        return self._torque(err, pd, v, dt)

    @staticmethod
    def _check_dt(dt: float, first_sample: bool = False) -> None:
        if not (math.isfinite(dt) and (dt > 0 or (first_sample and dt == 0))):
            raise ValueError(f"PID dt must be a positive number (0 only for a run's first sample), "
                             f"got {dt!r}")

    def _torque(self, err: np.ndarray, pd: np.ndarray, v: np.ndarray, dt: float) -> np.ndarray:
        """The law from the error q* - q and the PD term: conditional integration, clamps, velocity limit."""
        candidate = self.integral + err * dt
        i_term = self.ki * candidate
        saturated = np.abs(pd + i_term) > self.max_torque
        pushing = np.sign(pd + i_term) == np.sign(err)
        grow = ~(saturated & pushing)  # conditional integration
        self.integral = np.where(grow, candidate, self.integral)
        with np.errstate(divide="ignore", invalid="ignore"):
            cap = np.where(self.ki > 0, self.integral_limit / self.ki, 0.0)
        self.integral = np.clip(self.integral, -cap, cap)
        tau = np.clip(pd + self.ki * self.integral, -self.max_torque, self.max_torque)
        if self.max_velocity is not None:
            over = (np.abs(v) > self.max_velocity) & (np.sign(tau) == np.sign(v))
            tau = np.where(over, 0.0, tau)
        return tau

    def stepper(self, dt: float, compiled: bool | None = None
                ) -> Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
        """``step`` at a fixed period ``dt`` for a loop that calls it every period (walker/loop.py).

        ``dt`` is checked here, once. A call ``f(target_pos, target_vel, measured_pos, measured_vel)``
        takes float arrays of len(names) and returns the torques ``step`` returns (the same operations,
        equal to the last bit; the integral is shared with ``step``; the gains are those of now). It
        skips the per-input checks: a non-finite input makes its joint's PD term non-finite, which the
        lean law detects (one reduction), and such a call, or one whose inputs are not arrays of the
        right shape, goes through the checked ``step``, which refuses it naming the joint. With every
        ki = 0 and every torque limit > 0 (the configured servos) the integral stays 0 (``step`` clamps
        it to 0), so the lean law leaves it out, and ``compiled`` runs it as a numba kernel
        (``_lean_pd_law``); None = compiled when numba is already loaded in this process (the CPG's
        kernels load it), so a replay of a recording does not pay numba's import."""
        self._check_dt(dt)
        kp, kd, mt = self.kp, self.kd, self.max_torque
        neg_mt = -mt
        n = len(self.names)
        shape = (n,)
        err, pd, dv = np.empty(n), np.empty(n), np.empty(n)
        vmax = self.max_velocity
        has_vmax, vmax_value = vmax is not None, 0.0 if vmax is None else vmax
        no_integral = not np.any(self.ki)
        if no_integral:
            self.integral[:] = 0.0  # what the first step's clamp to +-0 would do
        lean_clamp = no_integral and bool(np.all(mt > 0))  # max/min = np.clip's result for limits > 0
        kernel = _lean_pd_kernel(compiled) if lean_clamp else None
        ndarray, isfinite, f8, empty = np.ndarray, math.isfinite, np.dtype(float), np.empty
        add_reduce, max_reduce = np.add.reduce, np.maximum.reduce
        add, subtract, multiply, maximum, minimum = np.add, np.subtract, np.multiply, np.maximum, np.minimum

        def lean(qt: np.ndarray, vt: np.ndarray, q: np.ndarray, v: np.ndarray) -> np.ndarray:
            if not (type(qt) is ndarray and type(vt) is ndarray and type(q) is ndarray
                    and type(v) is ndarray and qt.shape == shape and vt.shape == shape
                    and q.shape == shape and v.shape == shape):
                return self.step(qt, vt, q, v, dt)
            if kernel is not None and qt.dtype is f8 and vt.dtype is f8 and q.dtype is f8 and v.dtype is f8:
                tau = empty(n)
                if kernel(qt, vt, q, v, kp, kd, mt, has_vmax, vmax_value, tau):
                    return tau
                return self.step(qt, vt, q, v, dt)  # a non-finite input: refused, naming the joint
            subtract(qt, q, out=err)
            multiply(kp, err, out=pd)
            subtract(vt, v, out=dv)
            multiply(dv, kd, out=dv)
            add(pd, dv, out=pd)
            if not isfinite(add_reduce(pd)):  # a non-finite input (or an overflow): the checked law
                return self.step(qt, vt, q, v, dt)
            if not lean_clamp:
                return self._torque(err, pd, v, dt)  # allocates its result
            add(pd, 0.0, out=pd)  # + ki*integral = +0.0 (turns a -0.0 PD term into +0.0, as step does)
            tau = maximum(pd, neg_mt)
            minimum(tau, mt, out=tau)
            if has_vmax:
                np.abs(v, out=dv)
                if max_reduce(dv) > vmax:
                    tau[(dv > vmax) & (np.sign(tau) == np.sign(v))] = 0.0
            return tau

        return lean


def _lean_pd_law(qt, vt, q, v, kp, kd, mt, has_vmax, vmax, out) -> bool:  # pragma: no cover (compiled)
    """`PidLaw.step` with ki = 0 and limits > 0, element by element in the same operations (the torque
    into ``out``); False, with ``out`` unfinished, if a PD term is not finite (a non-finite input)."""
    for j in range(qt.shape[0]):
        p = kp[j] * (qt[j] - q[j]) + kd[j] * (vt[j] - v[j])
        if not math.isfinite(p):
            return False
        p = p + 0.0  # + ki*integral (+0.0)
        lo, hi = -mt[j], mt[j]
        p = p if p > lo else lo  # np.clip(p, lo, hi) = min(max(p, lo), hi) as numpy orders it
        p = p if p < hi else hi
        if has_vmax and abs(v[j]) > vmax and ((p > 0.0 and v[j] > 0.0) or (p < 0.0 and v[j] < 0.0)):
            p = 0.0  # the velocity limit: sign(tau) == sign(v) != 0
        out[j] = p
    return True


_KERNEL: Callable | bool | None = False  # False: not built yet; None: numba is not installed


def _lean_pd_kernel(compiled: bool | None) -> Callable | None:
    """``_lean_pd_law`` compiled by numba (built on first use, cached on disk), or None (see stepper)."""
    global _KERNEL
    if compiled is False or (compiled is None and "numba" not in sys.modules):
        return None
    if _KERNEL is False:
        try:
            from numba import njit
        except ImportError:
            _KERNEL = None
        else:
            _KERNEL = njit(cache=True)(_lean_pd_law)
    if _KERNEL is None and compiled:
        raise ImportError("compiled PID law requested but numba is not installed (pip install numba)")
    return _KERNEL  # type: ignore[return-value]


class ServoHold:
    """The servo drives' own watchdog (a real drive holds its position when its controller goes quiet):
    after ``after_s`` sim s without a new torque the joints hold the posture measured at that moment
    through the PID law with config/pid.yaml's gains (sim_node), until the next fresh torque. Blending to
    the standing crouch from mid-stride instead fell within 1 s (measured: docs/ROS_INTERFACE.md,
    "Faults")."""

    def __init__(self, after_s: float) -> None:
        self.after_ns = round(after_s * 1e9)
        self.law = PidLaw.from_config(config=load_pid_config())
        self.active = False
        self.entries = 0
        self.q0: np.ndarray | None = None

    def torque(self, q: np.ndarray, qd: np.ndarray, dt: float) -> np.ndarray:
        """The hold's torque for the measured state; the first call after a release takes the posture."""
        if not self.active:
            self.active, self.q0 = True, np.array(q, dtype=float)
            self.law.integral[:] = 0.0
            self.entries += 1
        return self.law.step(self.q0, np.zeros_like(self.q0), q, qd, dt)
