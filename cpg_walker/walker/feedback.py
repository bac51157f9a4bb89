"""Sensory feedback pathways of the humanoid CPG (paper Section III-B, eqs 14–18; gains eqs 19–20).

Pure numpy (no rclpy, no MuJoCo): the inputs are the chest IMU orientation (quaternion, as on /imu) and
the two sole loads (as on /foot_load), so the in-process loop and a ROS node feed the same object.

How we read the paper:

* (14)/(15) lateral: g_Ankle2 = K_lat·|ψ_lat|, g_Hip1 = −K_lat·|ψ_lat| on all oscillators of the Hip1 and
  Ankle2 CPGs of both legs (the same for both legs, as the text asks), projected on the radius by
  (16)/(17) (CPGNetwork's ``feedback``). With |·| the sign of the tilt is irrelevant: any tilt enlarges
  the Ankle2 and shrinks the Hip1 amplitude, on both sides alike. ``lateral_mode="abs"`` is this law as
  printed. ``lateral_mode="signed"`` (beyond the paper) drops the |·|: g_Ankle2 = s·K_lat·ψ_lat,
  g_Hip1 = −s·K_lat·ψ_lat with s = ``lateral_sign`` — a leaning-right tilt then moves the amplitudes the
  other way than a leaning-left one.
* (18) pendulum: g_Pendulum = K_pend·ψ_pend on all oscillators of the Knee and Ankle1 CPGs. ψ_pend is
  the sagittal tilt measured from ``pitch_reference_rad`` (the mean torso pitch of the learned gait at
  ζ = 1, the posture the CPG was taught with) — our reading of "tilt in the direction of walking".
* (19)/(20) K_lat = 2000 + 200(ζ − 1), K_pend = 1000(ζ − 1), in the paper's (unstated) units. Our ψ are
  radians and g acts on oscillators of radius √μ = 1 in internal time (ṙ = c·[γ(μ − r²)r + g], c the
  time scale), where a constant g moves the radius by ≈ g/(2γμ). We use g = ``gain_scale``·K·ψ; the
  scale is a configuration constant (config/feedback.yaml) chosen so that the paper's K_lat at a
  typical tilt changes the amplitude by a few tens of percent (see the YAML for the numbers).
* Phase resetting (III-B-3): at each right-foot touchdown (sole-load hysteresis, as replay's contact
  events) all oscillators are shifted in time so that oscillator 0 of the right Hip2 CPG sits at
  ``reset_phase_rad`` — the phase it has at right touchdown in the learned gait. A time shift keeps
  every relative phase: oscillator i of CPG b is rotated by (ω_{b,i}/ω_ref)·Δ, Δ the wrapped phase
  error of the reference oscillator (``strength`` < 1 applies a fraction of Δ).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from cpg_walker.cpg.hopf import phase
from cpg_walker.robot.contact import TouchdownDetector
from cpg_walker.robot.joints import CONTROLLED_JOINTS, PAPER_LEG_DOFS, SIDES

PATHWAYS = ("lateral", "pendulum", "reset")


def _dofs(paper: str) -> tuple[int, ...]:
    return tuple(CONTROLLED_JOINTS.index(f"{s}leg_joint_{PAPER_LEG_DOFS[paper]}") for s in SIDES)


HIP1 = _dofs("Hip1")
ANKLE2 = _dofs("Ankle2")
KNEE = _dofs("Knee")
ANKLE1 = _dofs("Ankle1")
RIGHT_HIP2 = CONTROLLED_JOINTS.index(f"rleg_joint_{PAPER_LEG_DOFS['Hip2']}")


@dataclass(frozen=True)
class FeedbackConfig:
    """Constants of the feedback pathways. Their values live in config/feedback.yaml only: build with
    ``load`` (overrides by keyword)."""

    gain_scale: float  # our g per rad of tilt = gain_scale × the paper's K (eqs 19–20)
    lateral_base: float  # eq 19
    lateral_slope: float  # eq 19
    pendulum_slope: float  # eq 20
    lateral_mode: str  # "abs" (eqs 14–15 as printed) | "signed" (beyond the paper)
    lateral_sign: float  # s of the signed variant
    pitch_reference_rad: float  # ψ_pend = pitch − this
    tilt_time_constant_s: float  # first-order low-pass on the IMU tilt
    g_limit: float  # |g| clip (internal units; g = 8 ≈ +40 % radius)
    reset_phase_rad: float  # right Hip2 oscillator 0 phase at right touchdown (learned gait)
    reset_strength: float  # fraction of the phase error removed at a reset

    def __post_init__(self) -> None:
        if self.lateral_mode not in ("abs", "signed"):
            raise ValueError(f"lateral_mode must be 'abs' or 'signed', got {self.lateral_mode!r}")
        if not (0.0 < self.reset_strength <= 1.0):
            raise ValueError(f"reset_strength must be in (0, 1], got {self.reset_strength}")

    @classmethod
    def load(cls, path: str | None = None, **overrides: object) -> FeedbackConfig:
        import yaml

        from cpg_walker.paths import config_path

        p = path or config_path("feedback.yaml")
        with open(p, encoding="utf-8") as fh:
            d = yaml.safe_load(fh) or {}
        known = {f.name for f in fields(cls)}
        unknown = sorted((set(d) | set(overrides)) - known)
        if unknown:
            raise ValueError(f"{p}: unknown key(s) {unknown}")
        d.update(overrides)
        missing = sorted(known - set(d))
        if missing:
            raise ValueError(f"{p}: missing key(s) {missing}")
        return cls(**d)


# ------------------------------------------------------------------------------------------- the laws
def gains(zeta: float, cfg: FeedbackConfig) -> tuple[float, float]:
    """Eqs 19–20 in the paper's units: (K_lateral, K_pendulum) at frequency ratio ζ."""
    return cfg.lateral_base + cfg.lateral_slope * (zeta - 1.0), cfg.pendulum_slope * (zeta - 1.0)


def lateral_terms(psi_lat: float, k_lat: float, mode: str = "abs", sign: float = 1.0) -> tuple[float, float]:
    """(g_Ankle2, g_Hip1): eqs 14–15 (``mode="abs"``), or the signed variant (beyond the paper)."""
    u = abs(psi_lat) if mode == "abs" else sign * psi_lat
    return k_lat * u, -k_lat * u


def pendulum_term(psi_pend: float, k_pend: float) -> float:
    """g_Pendulum of eq 18."""
    return k_pend * psi_pend


def feedback_vector(psi_lat: float, psi_pend: float, zeta: float, cfg: FeedbackConfig,
                    pathways: tuple[str, ...] = ("lateral", "pendulum")) -> np.ndarray:
    """(10,) g_k over CONTROLLED_JOINTS for CPGNetwork.step(feedback=...): eqs 14, 15, 18 with the
    eq 19–20 gains times ``gain_scale``, clipped to ±g_limit."""
    k_lat, k_pend = gains(zeta, cfg)
    g = np.zeros(len(CONTROLLED_JOINTS))
    if "lateral" in pathways:
        ga, gh = lateral_terms(psi_lat, k_lat, cfg.lateral_mode, cfg.lateral_sign)
        g[list(ANKLE2)] = ga
        g[list(HIP1)] = gh
    if "pendulum" in pathways:
        g[list(KNEE) + list(ANKLE1)] = pendulum_term(psi_pend, k_pend)
    return np.clip(cfg.gain_scale * g, -cfg.g_limit, cfg.g_limit)


# ------------------------------------------------------------------------------------------- sensing
class LowPass:
    """First-order low-pass, exact for a held input over dt."""

    def __init__(self, time_constant: float, n: int = 1):
        self.T = float(time_constant)
        self.y: np.ndarray | None = None
        self.n = n

    def update(self, u: np.ndarray, dt: float) -> np.ndarray:
        u = np.asarray(u, dtype=float)
        if self.y is None or self.T <= 0:
            self.y = u.copy()
        else:
            self.y += (u - self.y) * (1 - math.exp(-dt / self.T))
        return self.y


# ------------------------------------------------------------------------------------------- phase reset
def phase_reset(state: np.ndarray, omega: np.ndarray, target: float, ref: tuple[int, int] = (RIGHT_HIP2, 0),
                strength: float = 1.0) -> float:
    """Shift all oscillators in time so oscillator ``ref`` = (cpg, i) reaches phase ``target``.

    ``state`` is the network's (≥2, B, N) state (x, y rows modified in place); ``omega`` (B, N) the
    learned frequencies. Oscillator (b, i) is rotated by (ω_{b,i}/ω_ref)·Δ, Δ = wrap(target − θ_ref)·
    strength, so every relative phase (eq 8 harmonics, eq 13 inter-DOF links, the legs' π) is kept.
    Returns Δ (rad)."""
    b0, i0 = ref
    d = (target - phase(state[0, b0, i0], state[1, b0, i0]) + math.pi) % (2 * math.pi) - math.pi
    d *= strength
    ang = (omega / omega[b0, i0]) * d
    c, s = np.cos(ang), np.sin(ang)
    x, y = state[0].copy(), state[1].copy()
    # θ = atan2(x, −y) increases counter-clockwise in (x, y): rotate by +ang
    state[0] = c * x - s * y
    state[1] = s * x + c * y
    return d


# ------------------------------------------------------------------------------------------- controller
class FeedbackController:
    """Turns sensor readings into the eqs 14–18 g vector and right-touchdown reset events."""

    def __init__(self, cfg: FeedbackConfig, pathways: tuple[str, ...] = PATHWAYS):
        bad = [p for p in pathways if p not in PATHWAYS]
        if bad:
            raise ValueError(f"unknown feedback pathway(s) {bad}; choose from {list(PATHWAYS)}")
        self.cfg = cfg
        self.pathways = tuple(pathways)
        self.tilt = LowPass(cfg.tilt_time_constant_s)
        self.touch = TouchdownDetector()
        self.psi = (0.0, 0.0)
        self._t: float | None = None
        self.resets: list[tuple[float, float]] = []  # (t, Δ rad)
        #: in [0, 1]: scales every pathway's action (g, the reset's shift); cpg_node fades it out when
        #: the sensor data goes stale
        self.weight = 1.0

    def observe(self, t: float, tilt: tuple[float, float], loads: tuple[float, float]) -> bool:
        """Filter the (roll, pitch) tilt; True if the right foot just touched down."""
        dt = 0.0 if self._t is None else t - self._t
        self._t = t
        roll, pitch = self.tilt.update(np.array(tilt, dtype=float), max(dt, 0.0))
        self.psi = (float(roll), float(pitch) - self.cfg.pitch_reference_rad)
        _, right = self.touch.update(t, loads)
        return right

    def g(self, zeta: float) -> np.ndarray:
        return self.weight * feedback_vector(self.psi[0], self.psi[1], zeta, self.cfg, self.pathways)
