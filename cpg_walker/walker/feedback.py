"""Sensory feedback pathways of the humanoid CPG (paper Section III-B, eqs 14–18; gains eqs 19–20).

No rclpy, no simulation (numpy, plus the robot layer's contact hysteresis and IMU tilt): the inputs are
the chest IMU orientation (quaternion) and angular velocity, as on /imu, and the two sole loads (as on
/foot_load), so the in-process loop and a ROS node feed the same object.

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
* Beyond the paper (ours, each switchable by name; how they were measured: config/feedback.yaml):
  ``amplitude``: per-DOF amplitude factors 1 + k_b·max(|ζ| − 1, 0) on Hip1, Hip2, Knee, Ankle1, Ankle2
  (shorter Hip1/Ankle2 sway, shorter Hip2 strides and more knee lift at speed), and 1 + k_slow,b·
  max(1 − |ζ|, 0) below |ζ| = 1 (more knee lift when slow), a function of the
  *applied* (filtered) ζ, so it ramps in with a ζ change. ``reset_both``: soft phase resetting at the
  touchdown of either foot, Δ = κ·wrap(φ_TD − θ_ref) with φ_TD the right-touchdown phase for the walking
  direction (forward ``reset_phase_rad``, backward ``reset_phase_backward_rad``) and φ_TD + π at a left
  touchdown (the legs are half a cycle apart), none while |ζ| < ``reset_min_abs_zeta`` (a reversal
  passing through ζ = 0 has no touchdown phase) or α < ``reset_min_alpha`` (shorter steps touch down at
  other phases). ``heading``: keeps the IMU yaw on a reference (the yaw
  when feedback takes over, or the first observed one: ``heading_reference``; advanced by the commanded
  ``turn_rate``) with an antisymmetric hip-yaw
  oscillation q_yaw,R = −q_yaw,L = u·cos(θ_ref − φ_TD), u = heading_gain·(filtered yaw error) plus the
  commanded turn's feedforward c·ω·T/4 (``heading_amplitude``): each stance hip turns the pelvis over its
  planted foot by ≈ 2u per step. ``ankle``: an ankle strategy on
  the IMU — both ankles' pitch (Ankle1) and roll (Ankle2) targets offset by
  Δq_pitch = k_p·ψ_pend + k_pd·ω_y and Δq_roll = k_r·ψ_lat + k_rd·ω_x (ψ the filtered tilt, ω the chest's
  angular velocity), clipped to ``ankle_limit_rad``: a forward lean or pitch rate plantar-flexes, a right
  lean or roll rate rolls the soles against it, which moves the centre of pressure under the falling
  chest (it damps the growing sway that preceded the random sequences' falls). ``free_leg``: while
  standing, when the lateral tilt |ψ_lat| passes ``free_leg_threshold_rad`` and the upper foot (the left
  one for a tilt to the right) is off the ground, both hip rolls (Hip1) turn outward: the free leg's by
  k·e (its mass a counterweight against the fall), the stance leg's by k_s·e (turning the body back over
  its foot), e = |ψ_lat| − threshold, each clipped to ``free_leg_limit_rad``. Full at applied α 0, fading
  out by ``free_leg_max_alpha`` (walking's swing foot is off the ground every step).

Every action (g, reset shift, amplitude factors, hip-yaw, ankle and hip-roll offsets) is scaled by
``weight`` ∈ [0, 1] (a ROS node fades feedback out with it when its sensor data go stale); weight 0 is the
open loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from cpg_walker.cpg.hopf import phase
from cpg_walker.errors import InputError
from cpg_walker.robot.contact import TouchdownDetector
from cpg_walker.robot.hoap2 import tilt_from_quat
from cpg_walker.robot.joints import CONTROLLED_JOINTS, PAPER_LEG_DOFS, SIDES

#: The paper's pathways (Sec. III-B, as printed) and ours (module docstring).
PAPER_PATHWAYS = ("lateral", "pendulum", "reset")
PATHWAYS = (*PAPER_PATHWAYS, "amplitude", "reset_both", "heading", "ankle", "free_leg")


def _dofs(paper: str) -> tuple[int, ...]:
    return tuple(CONTROLLED_JOINTS.index(f"{s}leg_joint_{PAPER_LEG_DOFS[paper]}") for s in SIDES)


HIP1 = _dofs("Hip1")
HIP2 = _dofs("Hip2")
ANKLE2 = _dofs("Ankle2")
KNEE = _dofs("Knee")
ANKLE1 = _dofs("Ankle1")
RIGHT_HIP2 = CONTROLLED_JOINTS.index(f"rleg_joint_{PAPER_LEG_DOFS['Hip2']}")
#: hip yaw joints (``*_joint_1``, not driven by the CPG) as (left, right) names
HIP_YAW = tuple(f"{s}leg_joint_1" for s in SIDES)
#: The ankle pathway's joints (names): both Ankle1 (pitch), both Ankle2 (roll).
ANKLE_PITCH_JOINTS = tuple(f"{s}leg_joint_{PAPER_LEG_DOFS['Ankle1']}" for s in SIDES)
ANKLE_ROLL_JOINTS = tuple(f"{s}leg_joint_{PAPER_LEG_DOFS['Ankle2']}" for s in SIDES)
#: The free_leg pathway's joints (names): the hip roll (Hip1) of each leg, in SIDES order.
HIP_ROLL_JOINTS = tuple(f"{s}leg_joint_{PAPER_LEG_DOFS['Hip1']}" for s in SIDES)


@dataclass(frozen=True)
class FeedbackConfig:
    """Constants of the feedback pathways. Their values live in config/feedback.yaml only: build with
    ``load`` (overrides by keyword); a bad value raises ValueError naming the field."""

    gain_scale: float  # our g per rad of tilt = gain_scale × the paper's K (eqs 19–20)
    lateral_base: float  # eq 19
    lateral_slope: float  # eq 19
    pendulum_slope: float  # eq 20
    lateral_mode: str  # "abs" (eqs 14–15 as printed) | "signed" (beyond the paper)
    lateral_sign: float  # s of the signed variant
    pitch_reference_rad: float  # ψ_pend = pitch − this
    tilt_time_constant_s: float  # first-order low-pass on the IMU tilt
    g_limit: float  # |g| clip (internal units; g = 8 ≈ +40 % radius)
    reset_phase_rad: float  # right Hip2 oscillator 0 phase at right touchdown (learned gait, forward)
    reset_strength: float  # fraction of the phase error removed at a reset ("reset", the paper's)
    # ours ("amplitude"): amplitude factor 1 + k·max(|ζ| − 1, 0) per DOF (both legs)
    amp_slope_hip1: float
    amp_slope_hip2: float
    amp_slope_knee: float
    amp_slope_ankle1: float
    amp_slope_ankle2: float
    # ... and 1 + k·max(1 − |ζ|, 0) below |ζ| = 1 (slow walking)
    amp_slow_slope_hip1: float
    amp_slow_slope_hip2: float
    amp_slow_slope_knee: float
    amp_slow_slope_ankle1: float
    amp_slow_slope_ankle2: float
    # ours ("reset_both")
    reset_both_strength: float  # κ of the soft reset at either foot's touchdown
    reset_phase_backward_rad: float  # right Hip2 oscillator 0 phase at right touchdown walking backward
    reset_min_abs_zeta: float  # no reset_both while |applied ζ| is below this (reversing through ζ = 0)
    reset_min_alpha: float  # no reset_both while the applied α is below this (shorter steps)
    # ours ("heading")
    heading_gain: float  # hip-yaw amplitude u (rad) per rad of heading error
    heading_limit_rad: float  # |u| clip of the closed loop
    # c(applied α) of the turn's feedforward u_ff = c·ω·T/4: c_short at α <= short_alpha, c_long at α >=
    # long_alpha, linear in between
    turn_feedforward_short: float
    turn_feedforward_short_alpha: float
    turn_feedforward_long: float
    turn_feedforward_long_alpha: float
    hip_yaw_limit_rad: float  # |u_fb + u_ff| clip
    # the side step (/cmd_vel linear.y; not a feedback pathway: a command's hip-roll oscillation)
    side_step_gain: float  # hip-roll amplitude (rad) per (m/s of linear.y × s of stride period)
    side_step_limit_rad: float  # |amplitude| clip
    side_step_phase_rad: float  # the oscillation's phase after the heading pathway's cos(θ − φ_TD)
    side_step_rate: float  # rad per sim s the amplitude moves at most
    # side step ankle rolls = −ratio × its hip rolls (1: soles level): see side_step_ankle_ratio()
    side_step_ankle_ratio: float  # the ratio of a full side step in place
    side_step_level_turn_rad_s: float  # level (ratio 1) from this |turn rate| on
    side_step_level_alpha_from: float  # levelling as the applied α rises from this ...
    side_step_level_alpha_to: float  # ... to this
    side_step_tilt_from_rad: float  # level below this hip-roll amplitude (rad) ...
    side_step_tilt_full_rad: float  # ... fully tilted from this on
    heading_time_constant_s: float  # low-pass on the heading error (the gait's own yaw sway)
    heading_reference: str  # "handover": the yaw when feedback takes over | "start": the first observed yaw
    # ours ("ankle"): both ankles' pitch/roll target offsets from the chest's tilt and angular velocity
    ankle_pitch_gain: float  # rad per rad of ψ_pend
    ankle_pitch_rate_gain: float  # rad per rad/s of pitch rate (ω_y)
    ankle_roll_gain: float  # rad per rad of lateral tilt
    ankle_roll_rate_gain: float  # rad per rad/s of roll rate (ω_x)
    ankle_limit_rad: float  # |offset| clip, each axis
    ankle_rate_time_constant_s: float  # low-pass on the angular velocity it uses (the sway, not the impacts)
    ankle_max_sample_age_s: float  # it acts only on sensor samples at most this old (sim s) ...
    ankle_fade_s: float  # ... fading out over this when they are older, and back in when fresh again
    # ours ("free_leg"): the unloaded upper leg's hip roll swung outward while standing
    free_leg_gain: float  # rad of hip roll per rad of lateral tilt beyond the threshold
    free_leg_stance_gain: float  # the same for the stance (lower) leg's hip roll, outward too
    free_leg_threshold_rad: float  # |ψ_lat| below this: no action
    free_leg_limit_rad: float  # |offset| clip
    free_leg_max_alpha: float  # full at applied α 0, none from this α on (linear in between)
    free_leg_unloaded_n: float  # a sole bearing less than this (N) is off the ground

    def __post_init__(self) -> None:
        if self.lateral_mode not in ("abs", "signed"):
            raise InputError(f"lateral_mode must be 'abs' or 'signed', got {self.lateral_mode!r}")
        if self.heading_reference not in ("handover", "start"):
            raise InputError(f"heading_reference must be 'handover' or 'start', "
                             f"got {self.heading_reference!r}")
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("lateral_mode", "heading_reference"):
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise InputError(f"{f.name} must be a finite number, got {v!r}")
        for name in ("reset_strength", "reset_both_strength"):
            if not (0.0 < getattr(self, name) <= 1.0):
                raise InputError(f"{name} must be in (0, 1], got {getattr(self, name)}")
        for name in ("gain_scale", "g_limit", "tilt_time_constant_s", "heading_gain", "heading_limit_rad",
                     "ankle_rate_time_constant_s", "ankle_max_sample_age_s", "ankle_fade_s",
                     "heading_time_constant_s", "reset_min_abs_zeta", "reset_min_alpha", "free_leg_gain",
                     "free_leg_stance_gain", "free_leg_threshold_rad", "free_leg_unloaded_n",
                     "side_step_gain", "side_step_rate", "turn_feedforward_short", "turn_feedforward_long"):
            if getattr(self, name) < 0:
                raise InputError(f"{name} must be >= 0, got {getattr(self, name)}")
        if not 0.0 <= self.ankle_limit_rad <= 0.3:
            raise InputError(f"ankle_limit_rad must be in [0, 0.3] rad (ankle offsets), "
                             f"got {self.ankle_limit_rad}")
        for name in ("ankle_pitch_gain", "ankle_pitch_rate_gain", "ankle_roll_gain", "ankle_roll_rate_gain"):
            if abs(getattr(self, name)) > 5.0:
                raise InputError(f"{name} must be in [-5, 5], got {getattr(self, name)}")
        if not 0.0 <= self.free_leg_limit_rad <= 0.6:
            raise InputError(f"free_leg_limit_rad must be in [0, 0.6] rad (hip roll offsets), "
                             f"got {self.free_leg_limit_rad}")
        if not 0.0 < self.free_leg_max_alpha <= 1.0:
            raise InputError(f"free_leg_max_alpha must be in (0, 1], got {self.free_leg_max_alpha}")
        if not 0.0 <= self.turn_feedforward_short_alpha < self.turn_feedforward_long_alpha <= 2.0:
            raise InputError(f"turn_feedforward_short_alpha must be below turn_feedforward_long_alpha, both "
                             f"in [0, 2]; got {self.turn_feedforward_short_alpha} / "
                             f"{self.turn_feedforward_long_alpha}")
        if not 0.0 <= self.side_step_limit_rad <= 0.3:
            raise InputError(f"side_step_limit_rad must be in [0, 0.3] rad (hip-roll offsets), "
                             f"got {self.side_step_limit_rad}")
        lo, hi = self.side_step_level_alpha_from, self.side_step_level_alpha_to
        if not 0.0 <= lo < hi <= 2.0:
            raise InputError(f"side_step_level_alpha_from must be below side_step_level_alpha_to, both in "
                             f"[0, 2]; got {lo} / {hi}")
        if not 0.0 <= self.side_step_tilt_from_rad < self.side_step_tilt_full_rad <= 0.3:
            raise InputError(f"side_step_tilt_from_rad must be below side_step_tilt_full_rad, both in "
                             f"[0, 0.3] rad; got {self.side_step_tilt_from_rad} / "
                             f"{self.side_step_tilt_full_rad}")
        if not self.side_step_level_turn_rad_s > 0.0:
            raise InputError(f"side_step_level_turn_rad_s must be > 0 rad/s, "
                             f"got {self.side_step_level_turn_rad_s}")
        if not 0.0 <= self.side_step_ankle_ratio <= 1.0:
            raise InputError(f"side_step_ankle_ratio must be in [0, 1] (1: soles kept level), "
                             f"got {self.side_step_ankle_ratio}")
        if abs(self.side_step_phase_rad) > math.pi:
            raise InputError(f"side_step_phase_rad must be in [-pi, pi], got {self.side_step_phase_rad}")
        for name in ("heading_limit_rad", "hip_yaw_limit_rad"):
            if not 0.0 <= getattr(self, name) <= 0.5:
                raise InputError(f"{name} must be in [0, 0.5] rad (hip-yaw offsets), "
                                 f"got {getattr(self, name)}")
        if abs(self.lateral_sign) != 1.0:
            raise InputError(f"lateral_sign must be +1 or -1, got {self.lateral_sign}")
        for name in ("reset_phase_rad", "reset_phase_backward_rad"):
            if abs(getattr(self, name)) > math.pi:
                raise InputError(f"{name} must be in [-pi, pi], got {getattr(self, name)}")
        for name in (f"amp_{w}slope_{j}" for w in ("", "slow_")
                     for j in ("hip1", "hip2", "knee", "ankle1", "ankle2")):
            if abs(getattr(self, name)) > 2.0:
                raise InputError(f"{name} must be in [-2, 2], got {getattr(self, name)}")

    @classmethod
    def load(cls, path: str | None = None, **overrides: object) -> FeedbackConfig:
        d, p = _read_yaml(path)
        d.pop("pathways", None)
        known = {f.name for f in fields(cls)}
        unknown = sorted((set(d) | set(overrides)) - known)
        if unknown:
            raise InputError(f"{p}: unknown key(s) {unknown}")
        d.update(overrides)
        missing = sorted(known - set(d))
        if missing:
            raise InputError(f"{p}: missing key(s) {missing}")
        return cls(**d)


def _read_yaml(path: str | None) -> tuple[dict, str]:
    import yaml

    from cpg_walker.paths import config_path

    p = path or config_path("feedback.yaml")
    with open(p, encoding="utf-8") as fh:
        d = yaml.safe_load(fh) or {}
    if not isinstance(d, dict):
        raise InputError(f"{p}: expected a mapping")
    return d, str(p)


def check_pathways(names: object) -> tuple[str, ...]:
    """The validated pathway tuple (unknown names, and "reset" with "reset_both", are refused)."""
    if isinstance(names, str):
        raise InputError(f"feedback pathways must be a list of names, got the string {names!r}")
    names = tuple(names)  # type: ignore[arg-type]
    bad = [p for p in names if p not in PATHWAYS]
    if bad:
        raise InputError(f"unknown feedback pathway(s) {bad}; choose from {list(PATHWAYS)}")
    if "reset" in names and "reset_both" in names:
        raise InputError("feedback pathways 'reset' and 'reset_both' both reset at right touchdown: "
                         "choose one")
    return tuple(dict.fromkeys(names))


def default_pathways(path: str | None = None) -> tuple[str, ...]:
    """The pathways feedback "on" closes by default: config/feedback.yaml's ``pathways``."""
    d, p = _read_yaml(path)
    if "pathways" not in d:
        raise InputError(f"{p}: missing key 'pathways'")
    return check_pathways(d["pathways"])


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


# ------------------------------------------------------------------------------------------- ours
def amplitude_factors(zeta: float, cfg: FeedbackConfig) -> np.ndarray:
    """(10,) per-DOF amplitude factors ("amplitude"), >= 0: 1 + k_b·max(|ζ| − 1, 0) above |ζ| = 1,
    1 + k_slow,b·max(1 − |ζ|, 0) below (1 at |ζ| = 1)."""
    fast, slow = max(abs(zeta) - 1.0, 0.0), max(1.0 - abs(zeta), 0.0)
    f = np.ones(len(CONTROLLED_JOINTS))
    for dofs, j in ((HIP1, "hip1"), (HIP2, "hip2"), (KNEE, "knee"), (ANKLE1, "ankle1"), (ANKLE2, "ankle2")):
        k, k_slow = getattr(cfg, f"amp_slope_{j}"), getattr(cfg, f"amp_slow_slope_{j}")
        f[list(dofs)] = max(1.0 + k * fast + k_slow * slow, 0.0)
    return f


def touchdown_phase(zeta: float, cfg: FeedbackConfig) -> float:
    """Phase of the right Hip2 main oscillator at right touchdown for the walking direction sign(ζ)."""
    return cfg.reset_phase_rad if zeta >= 0 else cfg.reset_phase_backward_rad


def yaw_from_quat(q: np.ndarray) -> float:
    """Heading (rad, about world z, counter-clockwise = left) of the chest's x axis from (w, x, y, z)."""
    w, x, y, z = (float(v) for v in q)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def hip_yaw_offsets(u, theta_ref, phi_td: float, dtheta: float) -> tuple[np.ndarray, np.ndarray]:
    """(left, right) hip-yaw (q, q̇) of the heading pathway: q_R = u·cos(θ − φ_TD) = −q_L (module
    docstring); ``dtheta`` = dθ_ref/dt (rad/s). ``u`` and ``theta_ref`` scalars (two values) or (K,)
    arrays (K rows of two: a whole forecast at once)."""
    c, sn = np.cos(theta_ref - phi_td), np.sin(theta_ref - phi_td)
    q = np.stack([-u * c, u * c], axis=-1)
    qd = np.stack([u * sn * dtheta, -u * sn * dtheta], axis=-1)
    return q, qd


# ------------------------------------------------------------------------------------------- controller
class FeedbackController:
    """Turns sensor readings into the pathways' actions: the eqs 14–18 g vector, touchdown events for
    the resets, amplitude factors and the heading pathway's hip-yaw amplitude. ``observe`` is fed every
    control tick; ``weight`` ∈ [0, 1] scales every action; ``set_pathways``/``set_config``/
    ``set_turn_rate`` may be called between ticks."""

    def __init__(self, cfg: FeedbackConfig, pathways: tuple[str, ...] | None = None):
        self.cfg = cfg
        self.pathways = default_pathways() if pathways is None else check_pathways(pathways)
        self.tilt = LowPass(cfg.tilt_time_constant_s)
        self.touch = TouchdownDetector()
        self.psi = (0.0, 0.0)
        self.yaw = 0.0  # unwrapped IMU yaw (rad)
        self.gyro = np.zeros(3)
        self._t: float | None = None
        self._weight = 1.0
        self.turn_rate = 0.0  # rad/s, commanded (a later /cmd_vel); advances the heading reference
        self.heading_ref: float | None = None  # rad, None until captured (``capture_heading``)
        self.heading_window_rad = math.inf  # anti-windup: |heading_ref - yaw| kept within this
        self._herr = LowPass(cfg.heading_time_constant_s)
        self.heading_error = 0.0  # filtered (rad)
        self._rate = LowPass(cfg.ankle_rate_time_constant_s)
        self.rate = np.zeros(3)  # the angular velocity the ankle pathway uses (low-passed, rad/s)
        self.ankle_fresh = 1.0  # the ankle pathway's freshness weight (sample age, ``observe``)
        self.ankle_allowed = True  # False: the ankle pathway stays out (a loop without bounded delay)
        self.touchdowns = (False, False)  # (left, right) events of the last observe
        self.loads = (0.0, 0.0)  # (left, right) sole loads of the last observe (N)
        self.resets: list[tuple[float, float]] = []  # (t, Δ rad)

    def side_step_ankle_ratio(self, alpha: float, amplitude: float) -> float:
        """The side step's ankle-roll ratio (1: soles level) at the applied α and hip-roll ``amplitude``
        (rad): ``side_step_ankle_ratio`` for a full side step in place, levelled (each linearly) by a
        turn command up to ``side_step_level_turn_rad_s``, by α over ``side_step_level_alpha_from/_to``
        and by an amplitude below ``side_step_tilt_full_rad/_from_rad``. On tilted soles a turn beside a
        side step slipped, and forward steps or a small amplitude beside it yawed the base
        (docs/steering.md)."""
        c = self.cfg
        level = max(np.interp(abs(self.turn_rate), (0.0, c.side_step_level_turn_rad_s), (0.0, 1.0)),
                    np.interp(alpha, (c.side_step_level_alpha_from, c.side_step_level_alpha_to), (0.0, 1.0)),
                    np.interp(abs(amplitude), (c.side_step_tilt_from_rad, c.side_step_tilt_full_rad),
                              (1.0, 0.0)))
        return float(c.side_step_ankle_ratio + (1.0 - c.side_step_ankle_ratio) * level)

    # ---- run-time settings
    @property
    def weight(self) -> float:
        return self._weight

    @weight.setter
    def weight(self, w: float) -> None:
        w = float(w)
        if not (0.0 <= w <= 1.0):
            raise ValueError(f"feedback weight must be in [0, 1], got {w}")
        self._weight = w

    def set_pathways(self, names) -> None:
        self.pathways = check_pathways(names)

    def set_config(self, cfg: FeedbackConfig) -> None:
        if not isinstance(cfg, FeedbackConfig):
            raise ValueError(f"set_config needs a FeedbackConfig, got {type(cfg).__name__}")
        self.cfg = cfg
        self.tilt.T = cfg.tilt_time_constant_s
        self._herr.T = cfg.heading_time_constant_s
        self._rate.T = cfg.ankle_rate_time_constant_s

    def set_turn_rate(self, rate: float) -> None:
        rate = float(rate)
        if not (math.isfinite(rate) and abs(rate) <= 1.0):
            raise ValueError(f"turn_rate must be finite and within ±1 rad/s, got {rate}")
        self.turn_rate = rate

    def capture_heading(self) -> None:
        """Take the current (observed) yaw as the heading reference (FeedbackGaitSource: at the hand-over or
        at the first observation, ``heading_reference``)."""
        self.heading_ref = self.yaw
        self._herr.y = None

    def hold_heading(self) -> None:
        """Make the walked heading the reference (a turn command ended): the reference minus the filtered
        error, i.e. the yaw without its within-stride sway. The filtered error then decays smoothly
        (``heading_time_constant_s``) instead of turning the robot on through the lag of the turn."""
        if self.heading_ref is not None:
            self.heading_ref -= self.heading_error

    # ---- sensing
    def observe(self, t: float, quat_wxyz: np.ndarray, gyro: np.ndarray, loads: tuple[float, float],
                age_s: float = 0.0) -> None:
        """One control tick's readings: chest IMU orientation (w, x, y, z) and angular velocity (rad/s,
        as on /imu), (left, right) sole loads (N); ``age_s``: how old they are at the tick (sim s; 0
        in-process and in lockstep). Updates the filtered tilt ψ, the yaw, the heading error,
        ``touchdowns`` and the ankle pathway's freshness weight (its gains on rates do not tolerate a
        delay: in-process, samples 0.05 s late fell 6 random sequences of 6 within 1.5 s of the pathway
        closing, 0.04 s late none of 2; the others walked the same with and without such a delay)."""
        q = np.asarray(quat_wxyz, dtype=float)
        if q.shape != (4,) or not np.all(np.isfinite(q)) or not (0.5 < float(q @ q) < 2.0):
            raise ValueError(f"observe: quat_wxyz must be a finite unit quaternion (w, x, y, z), got {q}")
        dt = 0.0 if self._t is None else max(t - self._t, 0.0)
        roll, pitch = self.tilt.update(np.array(tilt_from_quat(q)), dt)
        self.psi = (float(roll), float(pitch) - self.cfg.pitch_reference_rad)
        yaw = yaw_from_quat(q)
        self.yaw = yaw if self._t is None else self.yaw + wrap(yaw - self.yaw)
        self.gyro = np.asarray(gyro, dtype=float)
        self.rate = self._rate.update(self.gyro, dt).copy()
        want = 1.0 if self.ankle_allowed and age_s <= self.cfg.ankle_max_sample_age_s else 0.0
        step = math.inf if self.cfg.ankle_fade_s <= 0 else dt / self.cfg.ankle_fade_s
        self.ankle_fresh = min(want, self.ankle_fresh + step) if want > self.ankle_fresh \
            else max(want, self.ankle_fresh - step)
        if self.heading_ref is not None:
            self.heading_ref += self.turn_rate * dt
            w = self.heading_window_rad
            self.heading_ref = min(max(self.heading_ref, self.yaw - w), self.yaw + w)
            self.heading_error = float(self._herr.update(np.array([self.heading_ref - self.yaw]), dt)[0])
        self._t = t
        self.touchdowns = self.touch.update(t, loads)
        self.loads = (float(loads[0]), float(loads[1]))

    # ---- actions (all × weight)
    def g(self, zeta: float) -> np.ndarray:
        """(10,) g of eqs 14–18 ("lateral", "pendulum")."""
        g = feedback_vector(self.psi[0], self.psi[1], zeta, self.cfg, self.pathways)
        return g * self._weight if self._weight != 1.0 else g

    def amplitude(self, zeta: float) -> np.ndarray:
        """(10,) per-DOF amplitude factors ("amplitude"; ones without it)."""
        if "amplitude" not in self.pathways:
            return np.ones(len(CONTROLLED_JOINTS))
        return 1.0 + self._weight * (amplitude_factors(zeta, self.cfg) - 1.0)

    def reset_events(self, zeta: float, alpha: float = 1.0) -> list[tuple[float, float]]:
        """(target phase of the right Hip2 main oscillator, strength) for the touchdowns of the last
        ``observe``: the paper's right-foot reset, or ours at either foot (not while the applied |ζ| or
        α is below ``reset_min_abs_zeta`` / ``reset_min_alpha``: its touchdown phases are those of full
        steps)."""
        left, right = self.touchdowns
        out = []
        w = self._weight
        if w <= 0.0:
            return out
        if "reset" in self.pathways and right:
            out.append((self.cfg.reset_phase_rad, w * self.cfg.reset_strength))
        if ("reset_both" in self.pathways and abs(zeta) >= self.cfg.reset_min_abs_zeta
                and alpha >= self.cfg.reset_min_alpha):
            phi = touchdown_phase(zeta, self.cfg)
            k = w * self.cfg.reset_both_strength
            if right:
                out.append((phi, k))
            if left:
                out.append((wrap(phi + math.pi), k))
        return out

    def ankle_offsets(self) -> tuple[float, float]:
        """(pitch, roll) offsets (rad) of both ankles' targets ("ankle"; zeros without it)."""
        w = self._weight * self.ankle_fresh
        if "ankle" not in self.pathways or w <= 0.0:
            return 0.0, 0.0
        c, lim = self.cfg, self.cfg.ankle_limit_rad
        dp = c.ankle_pitch_gain * self.psi[1] + c.ankle_pitch_rate_gain * float(self.rate[1])
        dr = c.ankle_roll_gain * self.psi[0] + c.ankle_roll_rate_gain * float(self.rate[0])
        return (w * min(max(dp, -lim), lim), w * min(max(dr, -lim), lim))

    def free_leg_offsets(self, alpha: float) -> tuple[float, float]:
        """Hip roll (Hip1) offsets (rad) of the (left, right) legs ("free_leg"; zeros without it, in double
        support, below the threshold, or from ``free_leg_max_alpha`` on): when the upper sole is off the
        ground, both legs turned outward, the free one by ``free_leg_gain``, the stance one by
        ``free_leg_stance_gain`` per rad of tilt beyond the threshold."""
        c = self.cfg
        fade = 1.0 - alpha / c.free_leg_max_alpha
        w = self._weight * min(fade, 1.0)
        excess = abs(self.psi[0]) - c.free_leg_threshold_rad
        if "free_leg" not in self.pathways or w <= 0.0 or excess <= 0.0:
            return 0.0, 0.0
        upper = 0 if self.psi[0] > 0 else 1  # ψ_lat > 0: tilted to the right, the left foot is the upper one
        if self.loads[upper] >= c.free_leg_unloaded_n:
            return 0.0, 0.0
        u = w * min(c.free_leg_gain * excess, c.free_leg_limit_rad)  # outward: +roll left, -roll right
        v = w * min(c.free_leg_stance_gain * excess, c.free_leg_limit_rad)
        return (u, -v) if upper == 0 else (v, -u)

    def heading_amplitude(self, stride_s: float = 0.0, alpha: float = 1.0) -> float:
        """u (rad) of the heading pathway's hip-yaw oscillation (0 without it or before the capture): the
        closed loop u_fb = heading_gain·e (|u_fb| <= heading_limit_rad) plus the commanded turn's
        feedforward u_ff = c·ω·T/4 (T = ``stride_s``, the stride period: each stance hip turns the pelvis
        by 2u per step, two steps per stride, so u = ω·T/4 without slip; c > 1 makes up the measured slip,
        larger on the shorter steps of a small applied ``alpha``: turn_feedforward_short up to
        turn_feedforward_short_alpha, turn_feedforward_long from turn_feedforward_long_alpha, linear
        between), the sum clipped to hip_yaw_limit_rad."""
        if "heading" not in self.pathways or self.heading_ref is None:
            return 0.0
        cfg = self.cfg
        lim = cfg.heading_limit_rad
        u = min(max(cfg.heading_gain * self.heading_error, -lim), lim)
        if self.turn_rate:
            c = float(np.interp(alpha, (cfg.turn_feedforward_short_alpha, cfg.turn_feedforward_long_alpha),
                                (cfg.turn_feedforward_short, cfg.turn_feedforward_long)))
            u += c * self.turn_rate * stride_s / 4.0
        lim = cfg.hip_yaw_limit_rad
        return self._weight * min(max(u, -lim), lim)
