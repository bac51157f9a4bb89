"""The humanoid CPG controller (paper Section III-A): 10 generic CPGs, one per controlled DOF, coupled.

Pure numpy (no rclpy, no MuJoCo): learning, playback, modulation, a run_replay target source. Its YAML
file: walker/storage.py (``storage.load``/``save``/``to_dict``/``from_dict``), which imports this module.

Architecture (Fig 5), over ``robot.joints.CONTROLLED_JOINTS`` (Hip1, Hip2, Knee, Ankle1, Ankle2 of the
left, then the right leg), B = 10 CPGs of N oscillators each (the paper: N = 3):

* Inside each CPG: eqs 4–11 (CPGNetwork), oscillator i >= 1 phase-locked to the CPG's main oscillator 0
  through the learned φ_i of eq 8.
* Between CPGs (eqs 12–13): the main oscillator of a child DOF gets τ·sin(θ_parent − φ_child) and, while
  learning, φ̇_child = sin(θ_parent − θ_child − φ_child) — 4 links per leg, 8 learned inter-DOF phases.
  Each leg is a tree rooted at Hip2, the DOF that carries the inter-leg coupling (Fig 5's "first DOF"):
  sagittal chain Hip2 → Knee → Ankle1, lateral chain Hip2 → Hip1 → Ankle2. The lateral pair hangs from
  Hip1 rather than from Ankle1 because Hip1 and Ankle2 are the two roll joints that together keep the
  foot parallel to the ground (the paper's eqs 14–15 treat them as one pair), so their relative phase is
  the one that must be held tightly; a single chain Hip2 → … → Ankle2 through the pitch joints would
  accumulate the phase errors of three links between them.
* Between the legs: the two Hip2 main oscillators reference each other with φ = π (antisymmetric
  coupling). π is a design constant, not one of the 8 learned phases (the recording's Hip2 fundamentals
  are π − 0.001 rad apart), so the link is fixed (``couple_cpgs(..., learn_phase=False)``: eq 12's
  coupling term, no eq 13 learning; φ stays exactly π). The link is already present while learning
  because a locked coupling term also enlarges the oscillator's radius, which α must absorb.

Offsets: the recorded angles have a non-zero mean (the crouched walking posture) that zero-mean
oscillators cannot learn. Each DOF's target is q*_k = offset_k + gain_k·Σ_i α_{k,i} x_{k,i}, where
offset_k is the mean of DOF k over the teaching cycle (CPGNetwork's ``offset``), subtracted from the
teaching signal before F (eq 10) is formed, and gain_k = RMS_k / 1.39 normalises each DOF to the RMS of
Fig 2's signal (the band the paper's constants were chosen for). The amplitude command α scales only the
oscillating part: α = 0 holds the mean posture.

Time: all CPGs share one time scale c = ω_gait / 15 (the stride's fundamental maps onto Fig 2's 15 rad/s
in internal time), so the ρ = 1 links of eq 13 relate equal frequencies.

Initial frequencies: eq 8's ratio ω_i/ω_0 is meaningful only if oscillator 0 holds the fundamental and
the others hold integer harmonics. Oscillator 0 of every CPG starts at 0.97·ω_gait; oscillators 1..N−1
start at 0.97·k·ω_gait for the N−1 harmonics k >= 2 with the largest amplitude in that DOF's teaching
cycle (Fourier magnitudes of the cycle). The adaptive rule (eq 6) then does the locking and fine tuning.
The harmonics are seeded on the integer multiples (not 3 % off, as oscillator 0 is): most are weak
(0.1–2° next to a 9–18° fundamental) and their locking range under τ = 2 phase pinning is narrower than
a 3 % offset — seeded at 0.99·k they had not locked after 150 strides (free-run error up to 1.3°).

Teaching signal: the recording's last full steady stride (``gait_data.find_steady_cycle``: walk
5.616–8.129 s, 2.513 s), repeated as a periodic signal (periodic cubic spline through its samples).

Modulation (frozen network): commanded ζ (frequency ratio, negative = backwards) and α (amplitude scale)
reach the network through a third-order low-pass (three cascaded first-order lags of time constant
``modulation_time_constant``): the applied ζ(t), α(t) are C², so the target's jerk stays bounded when a
command steps. (CPGNetwork's own first-order α relaxation is disabled: it is only C⁰ in α̇.)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from cpg_walker.cpg.network import MAX_RATE_STEP, CPGNetwork, CPGParams
from cpg_walker.errors import InputError
from cpg_walker.robot.joints import CONTROLLED_JOINTS, PAPER_LEG_DOFS, SIDES

DOFS: tuple[str, ...] = CONTROLLED_JOINTS
B = len(DOFS)


def _dof(side: str, paper: str) -> int:
    return DOFS.index(f"{side}leg_joint_{PAPER_LEG_DOFS[paper]}")


#: (child, parent) inter-CPG links of eqs 12–13, 4 per leg (8 learned phases).
CHAIN: tuple[tuple[int, int], ...] = tuple(
    (_dof(s, child), _dof(s, parent))
    for s in SIDES
    for child, parent in (("Knee", "Hip2"), ("Ankle1", "Knee"), ("Hip1", "Hip2"), ("Ankle2", "Hip1"))
)
#: The two Hip2 main oscillators (antisymmetric inter-leg coupling, fixed phase π).
HIP2_PAIR: tuple[int, int] = (_dof("l", "Hip2"), _dof("r", "Hip2"))
LEG_PHASE = math.pi

#: The commands' ranges (cpg_node's parameter descriptors, the CLI's checks, ``set_zeta``/``set_alpha``).
ZETA_RANGE = (-2.0, 2.0)  # frequency ratio ζ; negative plays the gait backwards
ALPHA_RANGE = (0.0, 2.0)  # amplitude (step length) scale α; 0 stops stepping


def modulation_error(name: str, value: object) -> str | None:
    """Why ``value`` is not an acceptable ``zeta``/``alpha`` command (None if it is)."""
    lo, hi = ZETA_RANGE if name == "zeta" else ALPHA_RANGE
    if isinstance(value, bool) or not isinstance(value, float | int):
        return f"{name} must be a number (double), got {type(value).__name__} {value!r}"
    if not math.isfinite(float(value)):
        return f"{name} must be finite, got {value!r}"
    if not lo <= float(value) <= hi:
        return f"{name} must be in [{lo:g}, {hi:g}], got {value!r}"
    return None


@dataclass(frozen=True)
class HumanoidSettings:
    """Constants of the humanoid learning. Their values live in config/cpg_humanoid_learning.yaml (and in a
    learned file's ``settings``), nowhere in code: build with ``from_mapping`` or walker.learning."""

    n_oscillators: int
    reference_omega: float  # internal rad/s of the gait's fundamental (Fig 2's lowest component)
    normalised_rms: float  # each DOF's teaching RMS in normalised units (Fig 2's signal: 1.39)
    seed_factor: float  # oscillator 0: ω(0) = seed_factor·ω_gait (the gait frequency is learned)
    harmonic_seed_factor: float  # oscillator i >= 1: ω(0) = harmonic_seed_factor·k_i·ω_gait
    max_harmonic: int  # harmonics considered when seeding oscillators 1..N−1
    steps_per_fastest_period: float  # learning dt: this many RK4 steps per fastest oscillator period
    chunk_strides: int  # convergence is checked every chunk
    max_strides: int  # learning budget
    tol_omega: float  # max relative change of an active ω over a chunk
    tol_alpha: float  # max change of an active α over a chunk, relative to its CPG's largest α
    tol_phi: float  # max change (rad) of an active φ (eq 8) or inter-DOF φ (eq 13) over a chunk
    tol_error: float  # max change of a DOF's RMS error over a chunk, relative to its teaching RMS
    active_fraction: float  # an oscillator is active if |α| >= this × its CPG's largest |α|
    converged_chunks: int  # consecutive chunks meeting every tolerance
    modulation_time_constant: float  # s, each of the 3 lags of the ζ/α command filter
    control_dt: float  # s, playback step of the target source (the PID rate)

    @classmethod
    def from_mapping(cls, d: dict, where: str) -> HumanoidSettings:
        """From a YAML mapping (every field, nothing else); ValueError naming ``where`` and the key."""
        known = cls.__dataclass_fields__
        unknown, missing = sorted(set(d) - set(known)), sorted(set(known) - set(d))
        if unknown or missing:
            raise InputError(f"{where}: humanoid settings: unknown key(s) {unknown}, "
                             f"missing key(s) {missing}")
        try:
            return cls(**{k: (int(v) if known[k].type == "int" else float(v)) for k, v in d.items()})
        except (TypeError, ValueError) as exc:
            raise InputError(f"{where}: humanoid settings: {exc}") from None

    def __post_init__(self) -> None:
        if not isinstance(self.n_oscillators, (int, np.integer)) or self.n_oscillators < 1:
            raise ValueError(f"n_oscillators must be an integer >= 1, got {self.n_oscillators!r}")
        if self.n_oscillators > self.max_harmonic:
            raise ValueError(
                f"n_oscillators ({self.n_oscillators}) exceeds max_harmonic ({self.max_harmonic})")


# --------------------------------------------------------------------------------------- teaching cycle
@dataclass
class TeachingCycle:
    """One steady stride of the recording over the 10 DOFs, played periodically."""

    gait: str
    start: float  # s, in the recording
    period: float  # s
    q: np.ndarray  # (n, 10) samples over [start, start + period)
    dt: float
    spline: Callable[[np.ndarray], np.ndarray] = field(repr=False)

    def sample(self, times: np.ndarray) -> np.ndarray:
        """Teaching values (len(times), 10) at times measured from the cycle's start (periodic)."""
        return self.spline(np.mod(np.asarray(times, dtype=float), self.period))

    @property
    def omega(self) -> float:
        return 2 * math.pi / self.period

    def harmonics(self, kmax: int) -> np.ndarray:
        """Fourier magnitudes (10, kmax + 1) of the cycle, index = harmonic number."""
        C = np.fft.rfft(self.q - self.q.mean(axis=0), axis=0) * (2.0 / len(self.q))
        return np.abs(C[: kmax + 1]).T


def cycle_from_samples(gait: str, start: float, q: np.ndarray, dt: float) -> TeachingCycle:
    """A TeachingCycle from one period of uniform samples ``q`` (n, 10), the first at ``start``: periodic
    cubic spline closed on the first sample (the recorded walk's seam: 4e-4 rad)."""
    from scipy.interpolate import CubicSpline

    n = len(q)
    tt = np.arange(n + 1) * dt
    closed = np.concatenate([q, q[:1]], axis=0)
    spline = CubicSpline(tt, closed, axis=0, bc_type="periodic")
    return TeachingCycle(gait, float(start), float(n * dt), q, dt, spline)


def teaching_cycle(gait_name: str = "walk") -> TeachingCycle:
    """The steady stride of a packaged recording (or CSV) as a periodic teaching signal."""
    from cpg_walker.robot.gait_data import find_steady_cycle, load_gait

    gait = load_gait(gait_name)
    missing = [j for j in DOFS if j not in gait.names]
    if missing:
        raise ValueError(f"{gait.source}: the recording lacks controlled joint(s) {missing}")
    cyc = find_steady_cycle(gait)
    i0 = round(cyc.start / gait.dt)
    n = round(cyc.period / gait.dt)
    q = np.stack([gait.column(j)[i0 : i0 + n] for j in DOFS], axis=1)
    return cycle_from_samples(gait.name, cyc.start, q, gait.dt)


def harmonic_seed_omegas(cycle: TeachingCycle, s: HumanoidSettings) -> np.ndarray:
    """(10, N) internal ω(0): fundamental for oscillator 0, strongest harmonics k >= 2 for the rest."""
    mags = cycle.harmonics(s.max_harmonic)
    out = np.empty((B, s.n_oscillators))
    for b in range(B):
        ks = 2 + np.argsort(-mags[b, 2:], kind="stable")[: s.n_oscillators - 1]
        out[b] = s.reference_omega * np.concatenate([[s.seed_factor], s.harmonic_seed_factor * np.sort(ks)])
    return out


# --------------------------------------------------------------------------------------- the controller
@dataclass
class LearnReport:
    """What learning did: strides, convergence, and the per-chunk history of the monitored quantities."""

    converged: bool
    strides: int
    learn_time_s: float
    dt: float
    wall_time_s: float
    history: list[dict]


class HumanoidCPG:
    """The 10-DOF CPG controller. Build with `learn(...)` or `load(path)`; the network is then frozen.

    Playback: `step(dt)` advances the network (and the ζ/α command filter), `joint_targets()` gives the
    10 DOFs' (q*, q̇*). `set_zeta`, `set_alpha` command the modulation; `reset_phase(s)` puts the
    oscillators at the state they have s seconds after the teaching cycle's start."""

    def __init__(self, net: CPGNetwork, meta: dict, phase_zero_state: np.ndarray, settings: HumanoidSettings):
        self.net = net
        self.meta = meta  # teaching/learning facts (serialised as is)
        self.settings = settings
        self.phase_zero_state = np.array(phase_zero_state, dtype=float)  # (2, 10, N) x, y at cycle phase 0
        self.zeta_command = 1.0
        self.alpha_command = 1.0
        self._zf = np.ones(3)  # cascaded lag states (ζ)
        self._af = np.ones(3)  # cascaded lag states (α)
        self.dof_scale = np.ones(net.B)  # per-DOF amplitude factor on top of α (feedback "amplitude")
        self._deriv = np.empty((2, net.B, net.N))
        self.alpha_learned = net.alpha.copy()  # frozen with amplitude scale 1
        if not net.learning:
            self._install_leg_coupling()

    # ------------------------------------------------------------------ construction
    @staticmethod
    def build_network(omega0: np.ndarray, params: CPGParams, time_scale: float, offset: np.ndarray,
                      gain: np.ndarray, **state) -> CPGNetwork:
        net = CPGNetwork(omega0, params, time_scale=time_scale, offset=offset, gain=gain, **state)
        for child, parent in CHAIN:
            net.couple_cpgs(child, parent, phase_offset=None)
        return net

    @staticmethod
    def couple_legs(net: CPGNetwork) -> None:
        """The fixed antisymmetric Hip2 ↔ Hip2 link (eq 12 with φ = π; not learned by eq 13)."""
        a, b = HIP2_PAIR
        net.couple_cpgs(a, b, phase_offset=LEG_PHASE, learn_phase=False)
        net.couple_cpgs(b, a, phase_offset=LEG_PHASE, learn_phase=False)

    def _install_leg_coupling(self) -> None:
        self.couple_legs(self.net)

    @classmethod
    def learn(cls, gait: str, settings: HumanoidSettings, params: CPGParams,
              progress: object | None = None) -> tuple[HumanoidCPG, LearnReport]:
        """Learn the 10 DOFs of the recording's steady stride (eqs 4–13) until converged; freeze.

        Convergence (checked every `chunk_strides` strides): over the last chunk no active ω moved by more
        than tol_omega (relative), no active α by more than tol_alpha (of its CPG's largest α), no active
        eq-8 φ nor any eq-13 inter-DOF φ by more than tol_phi rad, and no DOF's RMS error (P − Q over the
        chunk's last stride) by more than tol_error of its teaching RMS — for `converged_chunks` chunks in
        a row. Learning always ends at a whole number of strides, so the final state is the network at
        the teaching cycle's phase 0 (stored as `phase_zero_state`)."""
        import time

        s = settings
        cyc = teaching_cycle(gait)
        net, dt, per_stride, rms = cls.learning_network(cyc, s, params)
        history: list[dict] = []
        wall0 = time.perf_counter()
        prev = None
        good = 0
        strides = 0
        converged = False
        chunk = s.chunk_strides
        while strides < s.max_strides:
            err_sq = np.zeros(B)
            for k in range(chunk * per_stride):
                t = net.t
                P = cyc.sample(np.array([t, t + dt / 2, t + dt]))
                if k >= (chunk - 1) * per_stride:
                    err_sq += (P[0] - net.output()) ** 2
                net.step(dt, P)
            strides += chunk
            net.t = strides * cyc.period  # keep the clock on the stride grid (no rounding drift)
            err = np.sqrt(err_sq / per_stride)
            snap = snapshot(net, err)
            if prev is not None:
                ok, deltas = stable(prev, snap, rms, s)
                good = good + 1 if ok else 0
                history.append({"strides": strides, "rms_error_deg": np.degrees(err).round(4).tolist(),
                                **deltas})
            prev = snap
            if progress is not None:
                progress.update(strides, f"max err {math.degrees(err.max()):.2f} deg")
            if good >= s.converged_chunks:
                converged = True
                break
        wall = time.perf_counter() - wall0
        teaching = {"gait": cyc.gait, "cycle_start_s": cyc.start, "cycle_period_s": cyc.period,
                    "recorded_gait_frequency_hz": 1.0 / cyc.period,
                    "description": "the recording's last full steady stride, repeated periodically"}
        learning = {"converged": converged, "strides": strides, "learn_time_s": strides * cyc.period,
                    "dt_s": dt, "wall_time_s": round(wall, 3)}
        ctrl = cls.from_learning(net, s, teaching, learning)
        report = LearnReport(converged, strides, strides * cyc.period, dt, wall, history)
        return ctrl, report

    @classmethod
    def learning_network(cls, cyc: TeachingCycle, s: HumanoidSettings,
                         params: CPGParams) -> tuple[CPGNetwork, float, int, np.ndarray]:
        """The network that learns ``cyc`` (eqs 4–13), seeded on its harmonics, and how: (network, RK4 step
        dt, steps per stride, each DOF's teaching RMS). Shared by ``learn`` and live teaching."""
        p = CPGParams(params.mu, params.gamma, params.epsilon, params.eta, params.tau, 0.0)
        offset = cyc.q.mean(axis=0)
        rms = np.sqrt(np.mean((cyc.q - offset) ** 2, axis=0))
        gain = rms / s.normalised_rms
        c = cyc.omega / s.reference_omega
        om0 = harmonic_seed_omegas(cyc, s)
        net = cls.build_network(om0, p, c, offset, gain)
        # The Hip2–Hip2 link is present while learning too: a locked coupling term τ·sin θ = τ·x/r also
        # pushes the radius (r² -> μ + τ/2γ), so α must be learned with the coupling that plays it back.
        # It is fixed (learn_phase=False): its φ is π throughout, not learned by eq 13.
        cls.couple_legs(net)
        fastest = float(om0.max()) * c / min(1.0, s.harmonic_seed_factor)  # rad/s
        dt_max = 2 * math.pi / (s.steps_per_fastest_period * fastest)
        dt_max = min(dt_max, 0.9 * MAX_RATE_STEP / (c * 2 * p.gamma * p.mu))  # radial rate, 10 % margin
        per_stride = math.ceil(cyc.period / dt_max)
        dt = cyc.period / per_stride
        net.check_step(dt)
        return net, dt, per_stride, rms

    @classmethod
    def from_learning(cls, net: CPGNetwork, s: HumanoidSettings, teaching: dict,
                      learning: dict) -> HumanoidCPG:
        """Freeze a learning network whose state is at the teaching cycle's phase 0 into a controller;
        ``teaching`` and ``learning`` become its meta (the criterion and the learned frequency added)."""
        phase_zero = net.state[:2].copy()
        net.freeze()
        meta = {"teaching": dict(teaching), "learning": {**learning, "criterion": _criterion_text(s)}}
        ctrl = cls(net, meta, phase_zero, s)
        ctrl.meta["learning"]["gait_frequency_hz"] = ctrl.gait_frequency_hz()
        return ctrl

    # ------------------------------------------------------------------ facts
    @property
    def names(self) -> tuple[str, ...]:
        return DOFS

    @property
    def period(self) -> float:
        return float(self.meta["teaching"]["cycle_period_s"])

    def gait_frequency_hz(self) -> float:
        """Learned gait frequency: mean over the 10 CPGs of the main oscillator's ω (physical), in Hz."""
        om = self.net.omega[:, 0] * self.net.time_scale
        return float(np.mean(om) / (2 * math.pi))

    # ------------------------------------------------------------------ playback
    def reset_phase(self, seconds: float = 0.0) -> None:
        """Oscillators at phase 0 of the teaching cycle, then run `seconds` (ζ = 1) to reach that phase."""
        self.net.state[:2] = self.phase_zero_state
        zc, ac = self.zeta_command, self.alpha_command
        zf, af = self._zf.copy(), self._af.copy()
        self.net.set_frequency_scale(1.0)
        self.net.set_amplitude_scale(1.0)
        h = self.settings.control_dt
        n = round(seconds / h)
        for _ in range(n):
            self.net.step(h)
        rest = seconds - n * h
        if rest > 1e-12:
            self.net.step(rest)
        self._zf, self._af = zf, af
        self.net.set_frequency_scale(float(self._zf[-1]))
        self.net.set_amplitude_scale(float(self._af[-1]) * self.dof_scale)
        self.zeta_command, self.alpha_command = zc, ac

    def set_zeta(self, zeta: float) -> None:
        """Command the frequency ratio ζ (negative = backwards); reached smoothly (C²)."""
        reason = modulation_error("zeta", zeta)
        if reason:
            raise ValueError(reason)
        self.zeta_command = float(zeta)

    def set_alpha(self, alpha: float) -> None:
        """Command the amplitude (step-length) scale α >= 0 (0 stops stepping); reached smoothly (C²)."""
        reason = modulation_error("alpha", alpha)
        if reason:
            raise ValueError(reason)
        self.alpha_command = float(alpha)

    def set_modulation_state(self, zeta: float, alpha: float) -> None:
        """Apply ζ, α at once (filters settled): for start-up, not for changes while walking."""
        self.set_zeta(zeta)
        self.set_alpha(alpha)
        self._zf[:] = self.zeta_command
        self._af[:] = self.alpha_command
        self.net.set_frequency_scale(self.zeta_command)
        self.net.set_amplitude_scale(self.alpha_command * self.dof_scale)

    def set_dof_amplitude_scale(self, scale: np.ndarray) -> None:
        """Per-DOF factor s_b on the amplitude: α_b = α·s_b·α_learned (s = 1: the plain α command). Held
        until changed; the network's amplitude relaxation smooths a step."""
        scale = np.asarray(scale, dtype=float).reshape(-1)
        if scale.shape != (self.net.B,) or not np.all(np.isfinite(scale)) or np.any(scale < 0):
            raise ValueError(f"dof amplitude scale: expected {self.net.B} finite values >= 0, got {scale}")
        if np.array_equal(scale, self.dof_scale):
            return
        self.dof_scale = scale.copy()
        self.net.set_amplitude_scale(float(self._af[-1]) * self.dof_scale)

    def unit_pattern(self, x: np.ndarray | None = None) -> np.ndarray:
        """The oscillating part of the 10 DOFs' targets at amplitude 1, gain·Σ α_learned x (offsets and
        modulation left out: what identifies a phase), of the oscillator states ``x`` (…, 10, N; default
        the current)."""
        x = self.net.x if x is None else x
        return self.net.gain * np.einsum("bi,...bi->...b", self.alpha_learned, x)

    def match_phase(self, pattern: np.ndarray, points: int = 256) -> float:
        """Put the oscillators at the phase of their cycle (at ζ = 1, from phase 0) whose ``unit_pattern`` is
        nearest (least squares) to ``pattern`` (another network's, at a hand-over), among ``points`` phases
        per period; returns that phase as s after phase 0."""
        net = self.net
        zf, af = self._zf.copy(), self._af.copy()
        net.state[:2] = self.phase_zero_state
        net.set_frequency_scale(1.0)
        net.set_amplitude_scale(1.0)
        h = self.period / points
        states = np.empty((points, *self.phase_zero_state.shape))
        for k in range(points):
            states[k] = net.state[:2]
            net.step(h)
        k = int(np.argmin(np.sum((self.unit_pattern(states[:, 0]) - pattern) ** 2, axis=1)))
        net.state[:2] = states[k]
        net.set_frequency_scale(float(zf[-1]))
        net.set_amplitude_scale(float(af[-1]) * self.dof_scale)
        return k * h

    @property
    def zeta(self) -> float:
        """ζ currently applied (filtered)."""
        return float(self._zf[-1])

    @property
    def alpha(self) -> float:
        """α scale currently applied (filtered)."""
        return float(self._af[-1])

    def _filter(self, state: np.ndarray, command: float, dt: float) -> bool:
        """Advance the cascaded lags exactly over dt; True if the output changed."""
        if state[0] == command and state[1] == command and state[2] == command:  # settled (cheap test)
            return False
        T = self.settings.modulation_time_constant
        if T <= 0:
            state[:] = command
            return True
        d = math.exp(-dt / T)
        state[0] = command + (state[0] - command) * d
        state[1] = state[0] + (state[1] - state[0]) * d
        state[2] = state[1] + (state[2] - state[1]) * d
        if np.max(np.abs(state - command)) < 1e-9:
            state[:] = command
        return True

    def step(self, dt: float, feedback: np.ndarray | None = None) -> None:
        """Advance the frozen network and the modulation filters by dt (s); `feedback` = the (10,) g_k
        of eqs 16–17 held over the step (cpg/feedback.py), None = open loop."""
        if self._filter(self._zf, self.zeta_command, dt):
            self.net.set_frequency_scale(float(self._zf[-1]))
        if self._filter(self._af, self.alpha_command, dt):
            self.net.set_amplitude_scale(float(self._af[-1]) * self.dof_scale)
        self.net.step(dt, feedback=feedback)

    def joint_targets(self) -> tuple[np.ndarray, np.ndarray]:
        """(q*, q̇*) of the 10 DOFs: offset + gain·Σ α x and its time derivative (α held)."""
        net = self.net
        net.playback_derivative(self._deriv)
        q = net.output()
        qd = net.gain * np.einsum("bi,bi->b", net.alpha, self._deriv[0])
        return q, qd

    def forecast(self, offsets: np.ndarray, fade: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(q*, q̇*) of the 10 DOFs at ``offsets`` (s ahead, non-decreasing, >= 0): what `joint_targets`
        will give after stepping that far, predicted without changing the controller
        (`CPGNetwork.forecast`, RK4 at up to the guard's step). While a ζ/α command is being reached the
        filters' future is that of `step` at ``control_dt`` (exact, `_filter_path`): ζ at each interval's
        middle, α at each point. ``fade``: (K,) factors in [0, 1] on the applied α at each offset (a stop
        foreseen: the oscillators' amplitude, not their phase, goes to 0; None = 1). Two (K, 10) arrays."""
        offsets = np.asarray(offsets, dtype=float).reshape(-1)
        zc, ac = self.zeta_command, self.alpha_command
        settled = (self._zf == zc).all() and (self._af == ac).all()
        if settled and fade is None:  # as applied now
            return self.net.forecast(offsets)
        h = self.settings.control_dt
        zeta = None
        if not settled:
            mid = np.concatenate(([0.0], offsets[:-1])) if offsets.size else offsets
            zeta = self._filter_path(self._zf, zc, np.rint(0.5 * (mid + offsets) / h))
        alpha = np.full(offsets.shape, float(self._af[-1])) if settled else \
            self._filter_path(self._af, ac, np.rint(offsets / h))
        if fade is not None:
            fade = np.asarray(fade, dtype=float).reshape(-1)
            if fade.shape != offsets.shape or not np.all((fade >= 0) & (fade <= 1)):
                raise ValueError(f"forecast fade: expected {offsets.size} factors in [0, 1]")
            alpha = alpha * fade
        return self.net.forecast(offsets, zeta=zeta, amplitude=alpha[:, None] * self.dof_scale[None])

    def _filter_path(self, state: np.ndarray, command: float, steps: np.ndarray) -> np.ndarray:
        """The output of the cascaded lags (`_filter`) after each of ``steps`` steps of control_dt, in
        closed form: the error e = state - command evolves as e <- A e with A = d·I + L (d = e^(-dt/T),
        L strictly lower triangular), so A^n = d^n I + n d^(n-1) L + n(n-1)/2 d^(n-2) L² (L³ = 0)."""
        T = self.settings.modulation_time_constant
        if T <= 0:
            return np.full(steps.shape, command)
        d = math.exp(-self.settings.control_dt / T)
        c = 1.0 - d
        L = np.array([[0.0, 0.0, 0.0], [c * d, 0.0, 0.0], [c * c * d, c * d, 0.0]])
        e = state - command
        Le, L2e = L @ e, L @ (L @ e)
        n = np.asarray(steps, dtype=float)
        dn = d ** n
        with np.errstate(divide="ignore", invalid="ignore"):
            out = dn * e[2] + n * dn / d * Le[2] + 0.5 * n * (n - 1) * dn / (d * d) * L2e[2]
        return command + out


# --------------------------------------------------------------------------------------- helpers
def snapshot(net: CPGNetwork, err: np.ndarray) -> dict:
    """What the convergence criterion compares between chunks (``stable``): ω, α, φ and the RMS error."""
    return {"omega": net.omega.copy(), "alpha": net.alpha.copy(), "phi": net.phi.copy(), "err": err}


def stable(prev: dict, cur: dict, teach_rms: np.ndarray, s: HumanoidSettings) -> tuple[bool, dict]:
    """The convergence criterion between two chunks' snapshots (``_criterion_text``): (met, changes)."""
    amax = np.max(np.abs(cur["alpha"]), axis=1, keepdims=True)
    active = np.abs(cur["alpha"]) >= s.active_fraction * amax
    active[:, 0] = True
    d_om = float(np.max(np.where(active, np.abs(cur["omega"] - prev["omega"]) / np.abs(cur["omega"]), 0)))
    d_al = float(np.max(np.where(active, np.abs(cur["alpha"] - prev["alpha"]) / amax, 0)))
    dphi = np.abs(np.angle(np.exp(1j * (cur["phi"] - prev["phi"]))))
    learned_phi = active.copy()
    learned_phi[:, 0] = False
    for child, _ in CHAIN:
        learned_phi[child, 0] = True
    d_ph = float(np.max(np.where(learned_phi, dphi, 0)))
    d_err = float(np.max(np.abs(cur["err"] - prev["err"]) / teach_rms))
    ok = d_om < s.tol_omega and d_al < s.tol_alpha and d_ph < s.tol_phi and d_err < s.tol_error
    return ok, {"d_omega_rel": d_om, "d_alpha_rel": d_al, "d_phi_rad": d_ph, "d_error_rel": d_err}


def _criterion_text(s: HumanoidSettings) -> str:
    return (f"every {s.chunk_strides} strides: active omega change < {s.tol_omega:g} (relative), active "
            f"alpha change < {s.tol_alpha:g} of the CPG's largest alpha, eq-8/eq-13 phi change < "
            f"{s.tol_phi:g} rad, per-DOF RMS error change < {s.tol_error:g} of the teaching RMS; "
            f"{s.converged_chunks} chunks in a row (active: |alpha| >= {s.active_fraction:g} x largest)")
