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
import yaml

from cpg_walker.robot.joints import JOINT_NAMES, MAX_TORQUE_NM, MAX_VELOCITY_RADS, group_of


def load_pid_config(path: str | Path | None = None) -> dict:
    """The PID configuration (``config/pid.yaml`` by default) as a dict."""
    if path is None:
        from cpg_walker.paths import config_path

        path = config_path("pid.yaml")
    with open(path, encoding="utf-8") as fh:
        cfg = yaml.safe_load(fh)
    if not isinstance(cfg, dict) or "groups" not in cfg:
        raise ValueError(f"{path}: expected a mapping with 'groups' (leg/arm/body/head gains)")
    return cfg


class PidLaw:
    """Independent PID servos for the joints ``names`` with per-joint gains (arrays of len(names))."""

    def __init__(
        self,
        names: Sequence[str],
        kp: Sequence[float] | np.ndarray,
        ki: Sequence[float] | np.ndarray,
        kd: Sequence[float] | np.ndarray,
        max_torque: float | Sequence[float] = MAX_TORQUE_NM,
        integral_limit: float = 0.5,
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
        if not (math.isfinite(integral_limit) and integral_limit >= 0):
            raise ValueError(f"PID integral_limit must be finite and >= 0, got {integral_limit}")
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
        """Gains by joint group, overridden per joint, from ``config/pid.yaml`` (or a given dict).
        ``scale_kp``/``scale_kd`` multiply every gain (for margin sweeps)."""
        cfg = dict(load_pid_config() if config is None else config)
        groups, per_joint = cfg["groups"], cfg.get("joints") or {}
        unknown = sorted(set(per_joint) - set(JOINT_NAMES))
        if unknown:
            raise ValueError(f"pid config: unknown joint(s) {unknown}")
        gains = []
        for name in names:
            g = dict(groups[group_of(name)])
            g.update(per_joint.get(name, {}))
            gains.append((float(g["kp"]), float(g.get("ki", 0.0)), float(g["kd"])))
        kp, ki, kd = (np.array(col) for col in zip(*gains, strict=True))
        return cls(
            names, kp * scale_kp, ki, kd * scale_kd,
            max_torque=float(cfg.get("max_torque", MAX_TORQUE_NM)),
            integral_limit=float(cfg.get("integral_limit", 0.5)),
            max_velocity=cfg.get("max_velocity", MAX_VELOCITY_RADS),
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
        """Torques (N*m) for one control period ``dt`` (s); updates the integral. Every input is checked."""
        self._check_dt(dt)
        qt = self._check("target_pos", target_pos)
        vt = self._check("target_vel", target_vel)
        q = self._check("measured_pos", measured_pos)
        v = self._check("measured_vel", measured_vel)
        err = qt - q
        pd = self.kp * err + self.kd * (vt - v)
        return self._torque(err, pd, v, dt)

    @staticmethod
    def _check_dt(dt: float) -> None:
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"PID dt must be a positive number, got {dt!r}")

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
