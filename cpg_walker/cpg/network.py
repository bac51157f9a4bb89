"""The generic programmable CPG (paper eqs 4–11), vectorised over B independent CPGs of N oscillators.

State: five (B, N) arrays x, y, ω, α, φ stacked as one (5, B, N) array, integrated with RK4
(integrators.py). CPG b's output is Q_b = offset_b + gain_b·Σ_i α_{b,i} x_{b,i}.

How we read the paper's equations (its typos, and the choices it leaves open) — all of them are in
`learning_rhs` below, one comment per equation:

* (4)  ẋ_i = γ(μ − r_i²)x_i − ω_i y_i + εF + τ·sin(R_i − φ_i), with R_i = (ω_i/ω_0)·θ_0.
       The printed coupling term sin(θ_i − φ_i) does not involve oscillator 0, so it cannot be the
       "Kuramoto coupling to oscillator 0" the text and Fig 1 ("the scaled phase input R_i from
       oscillator 0") describe; we read θ_i there as R_i. With eq 9's convention sin θ = x/r, so
       τ·sin(R_i − φ_i) is a unit-amplitude copy of the x-signal oscillator i should have, and averaged
       over a cycle it adds τ/(2r)·sin(R_i − φ_i − θ_i) to θ̇_i: it locks θ_i to R_i − φ_i, the target
       whose offset eq 8 learns. (Verified in test_cpg_network: φ converges to the true offsets and the
       frozen network reproduces the teaching signal's phases.) Oscillator 0 has no such term.
* (5)  as printed.
* (6)  the left side is ω̇_i (printed υ̇_i) and y/r is y_i/r_i (printed g_i/r): eq 3 per oscillator.
* (7)  α̇_i = η x_i F: the printed "n" is the learning constant η.
* (8)  φ̇_i = sin(R_i − θ_i − φ_i): φ_i converges to R_i − θ_i (mod 2π), which is a constant only if
       ω_i/ω_0 is an integer — oscillator 0 must hold the fundamental (true in Fig 2, where ω_0(0) is the
       lowest initial frequency). With θ = ψ + π/2 (hopf.py), the learned offset for oscillator
       phases ψ_i = ω_i t + c_i is φ_i = k_i c_0 − c_i + (k_i − 1)π/2, k_i = ω_i/ω_0. For a
       non-integer ratio see "Non-harmonic oscillators" below.
* (9)  θ_i = sgn(x_i)·arccos(−y_i/r_i) = atan2(x_i, −y_i) (see hopf.phase).
* (10) F = P_teach − Q_learned; with a per-CPG offset/gain normalisation (teaching.py) F is computed in
       normalised units: F = (P_teach − offset)/gain − Σ α_i x_i. offset = 0, gain = 1 is the paper.
* (11) Q_learned = Σ_i α_i x_i, the sum over all oscillators i = 0..N−1.
* (12) (humanoid, inter-CPG) ẋ_{0,k} = γ(μ − r²)x_{0,k} − ω_{0,k}y_{0,k} + τ·sin(θ_{0,k−1} − φ_{0,k}):
       the printed equation omits γ; it is the same γ as eq 4 (the oscillator is the same Hopf
       oscillator). The printed coupling sin(θ_{0,k} − φ_{0,k}) has the same typo as eq 4: the target
       of oscillator (0,k) is θ_{0,k−1} − φ_{0,k}, which is what eq 13 makes φ_{0,k} converge to.
* (13) the left side is φ̇_{0,k} (printed φ_{0,k}): φ̇_{0,k} = sin(θ_{0,k−1} − θ_{0,k} − φ_{0,k}).
* (16)/(17) (feedback) + g_k·x_i/r_i and + g_k·y_i/r_i on all oscillators of CPG k: a push along the
       radius that changes the amplitude and not the phase; the printed (μ − r²) again omits γ.

Eqs 4/8 and 12/13 are one mechanism: every oscillator has at most one *reference* oscillator (any
oscillator of any CPG) and a coupling strength; its target phase is Θ = ρ·θ_ref − φ with ρ = ω/ω_ref
(eq 8, inside a CPG) or ρ = 1 (eq 13, between CPGs). By default oscillator i ≥ 1 of CPG b references
oscillator 0 of CPG b with strength τ; `couple_cpgs` adds the eq 12–13 links between main oscillators
(a chain, or two main oscillators referencing each other for the legs' antisymmetric coupling); a link
made with `learn_phase=False` is fixed: eq 12's coupling term acts, eq 13 does not (φ stays as given).
φ of an oscillator without reference is unused, so φ_{b,0} is the eq 13 state "φ_{0,k}" of CPG b.

Non-harmonic oscillators (eq 8 with a non-integer ρ = ω_i/ω_0). R_i = ρ·θ_0 is built on θ_0 of eq 9,
a wrapped angle in (−π, π]. At each wrap of θ_0 (once per cycle of oscillator 0) R_i jumps by 2πρ,
which is 0 mod 2π only for an integer ρ. For a non-integer ρ the target Θ_i = R_i − φ_i jumps by
2π(ρ − round ρ) every cycle: no constant φ_i satisfies eq 8, and the frozen network's coupling term
τ·sin(R_i − φ_i) kicks oscillator i to a new phase every cycle, so the waveform is lost although eq 6
learns ω_i (`cpg-walker fit` on 7/11/19 rad/s: frequencies within 0.5 %, free-run error 58 % of the
teaching RMS). The printed equations cannot fix this: a continuous R_i needs the unwrapped phase of
oscillator 0, i.e. a count of its turns, and no variable of eqs 4–9 holds one. We add that count where
it is needed: for an oscillator flagged `nonharmonic`, φ_i absorbs the jump at each wrap of its
reference's θ (φ_i −= ±2π(ρ − round ρ): + for a forward wrap π → −π, − for a backward one, as with
ω_0 < 0 or ζ < 0), so R_i − φ_i = ρ·(unwrapped θ_0) − const is continuous and φ_i is the (learned,
then frozen) offset to the unwrapped reference. This runs after each integrator step
(`_absorb_reference_wraps`, the same for both backends), while learning and while frozen; the RK4
stages of the wrapping step that saw the jumped target are corrected to first order, so a wrap costs
O(dt²), not O(dt) (0.4/1.0/1.7 Hz fit: free-run error 4.5 % without this stage correction, 0.5 % with
it). Why only flagged oscillators: for harmonic content the wrapped reference helps. R_i is then
periodic in θ_0, so τ·sin(R_i − φ_i) forces oscillator i at harmonics of ω_0 and entrains ω_i onto an
exact integer multiple; with the correction the forcing follows ω_i itself and that pull is gone
(Fig 2 with oscillators 1–3 flagged: 15.0, 30.0, 45.0, 63.8 rad/s instead of 60.0; the humanoid,
seeded on exact harmonics, learned and walked 30 s flagged too, but unflagged it stays as it was).
Default: none flagged, i.e. the printed eq 8, and `step` pays one `is None` test. teaching.py flags
the oscillators seeded at a component that is clearly not an integer multiple of oscillator 0's.

Learning vs playback: while `learning` is True all five variables evolve (eqs 4–11). `freeze()` sets
F = 0 and stops ω, α, φ (the paper's "set F(t) = 0"; φ is frozen too so a perturbation cannot be
re-learned as a new phase offset); only x, y are integrated, with the cheaper `playback_rhs`.

Modulation (frozen network only), as parameters of the dynamical system:
* frequency: ω_eff = ζ_b·ω (per CPG). ζ < 0 inverts the rotation, i.e. plays the pattern backwards.
  Ratios ω_i/ω_0 are unchanged, so phase relations hold; x, y are continuous, so the output is too.
* amplitude: α relaxes exponentially to s_b·α_learned with time constant `amplitude_time_constant`
  (physical seconds; 0 = instantaneous). The paper gives no mechanism for its smooth change of α; an
  instantaneous change of α would make Q jump, so we let α move as a first-order state. It is updated
  exactly (α* + (α − α*)·e^{−dt/T}) after each RK4 step; the oscillators are untouched.

Integration backends: `step` integrates with RK4 either in numpy (integrators.RK4 over `learning_rhs` /
`playback_rhs`, the reference) or, when numba is installed, with compiled kernels (kernels.py) that do
one whole RK4 step with the same equations in the same order (equal to ~1e-12, test_cpg_kernels.py) and
avoid numpy's per-call overhead. Choose with `backend=` / the `backend` attribute or the environment
variable CPG_WALKER_BACKEND = auto (default: numba if importable) | numpy | numba.

Time scale: every rate is multiplied by time_scale_b (per CPG), i.e. CPG b evolves in the internal time
u = time_scale_b·t. Physical frequencies are time_scale·ω (`frequencies()`); this is how teaching.py
maps any signal's band onto the band the paper's constants were tuned for.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from cpg_walker.cpg.hopf import R_FLOOR, phase
from cpg_walker.cpg.integrators import RK4

#: RK4 accuracy/stability guard: time_scale·dt·max(|ω|, 2γμ) must not exceed this (see `check_step`).
MAX_RATE_STEP = 0.5

#: Values of `CPGNetwork.backend` / the CPG_WALKER_BACKEND environment variable.
BACKENDS = ("auto", "numpy", "numba")
_kernels: ModuleType | bool | None = False  # False: not tried yet; None: numba unavailable


def _load_kernels() -> ModuleType | None:
    """kernels.py if numba is importable, else None (imported on first use: numba is slow to import)."""
    global _kernels
    if _kernels is False:
        from cpg_walker.cpg import kernels

        _kernels = kernels if kernels.AVAILABLE else None
    return _kernels  # type: ignore[return-value]


@dataclass(frozen=True)
class CPGParams:
    """Constants of eqs 4–11 (defaults: the paper's Fig 2) and of amplitude modulation."""

    mu: float = 1.0
    gamma: float = 8.0
    epsilon: float = 0.9
    eta: float = 0.5
    tau: float = 2.0
    amplitude_time_constant: float = 0.05

    def __post_init__(self) -> None:
        for name in ("mu", "gamma", "epsilon", "eta", "tau", "amplitude_time_constant"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"CPG parameter {name} must be a finite number >= 0, got {value!r}")
        if self.mu <= 0:
            raise ValueError(f"CPG parameter mu must be > 0 (it sets the amplitude), got {self.mu}")


def fastest_rate(params: CPGParams, omega: np.ndarray, time_scale: np.ndarray) -> float:
    """The fastest rate (1/s) RK4 must resolve: max over oscillators of time_scale·max(|ω|, 2γμ) — the
    rotation (ω: (B, N) internal, ζ included) and the radial relaxation. `CPGNetwork.check_step` requires
    dt·fastest_rate <= MAX_RATE_STEP."""
    radial = 2 * params.gamma * params.mu
    return float(np.max(np.asarray(time_scale)[:, None] * np.maximum(np.abs(omega), radial)))


def _per_cpg(value: float | np.ndarray, B: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(B, float(arr))
    if arr.shape != (B,):
        raise ValueError(f"{name} must be a scalar or have shape ({B},) (one value per CPG), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return arr


def _per_oscillator(value: float | np.ndarray, shape: tuple[int, int], name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    try:
        arr = np.broadcast_to(arr, shape).copy()
    except ValueError:
        raise ValueError(f"{name} has shape {arr.shape}, which does not fit the network's {shape}") from None
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return arr


class CPGNetwork:
    """B independent generic CPGs of N adaptive Hopf oscillators each (optionally coupled, eqs 12–13).

    Parameters
    ----------
    omega0: initial frequencies, shape (B, N) or (N,) (= one CPG), in internal units (rad per unit of
        internal time; rad/s when time_scale = 1). Oscillator 0 of each CPG is the phase reference.
    params: the constants μ, γ, ε, η, τ.
    x0, y0, alpha0, phi0: initial state, broadcast to (B, N) (paper: 1, 0, 0, 0).
    time_scale, offset, gain: per CPG, shape (B,) or scalar (see the module docstring).
    backend: "auto" | "numpy" | "numba" (None: $CPG_WALKER_BACKEND, default "auto"); see the module
        docstring. "numba" without numba installed raises ImportError; "auto" falls back to numpy.
    nonharmonic: (B, N) booleans (broadcast): oscillators whose eq 8 reference phase gets the wrap
        correction (module docstring, "Non-harmonic oscillators"); default none: the printed eq 8.
    """

    def __init__(
        self,
        omega0: np.ndarray,
        params: CPGParams | None = None,
        *,
        x0: float | np.ndarray = 1.0,
        y0: float | np.ndarray = 0.0,
        alpha0: float | np.ndarray = 0.0,
        phi0: float | np.ndarray = 0.0,
        time_scale: float | np.ndarray = 1.0,
        offset: float | np.ndarray = 0.0,
        gain: float | np.ndarray = 1.0,
        backend: str | None = None,
        nonharmonic: bool | np.ndarray = False,
    ):
        om = np.asarray(omega0, dtype=float)
        if om.ndim == 1:
            om = om[None, :]
        if om.ndim != 2:
            raise ValueError(f"omega0 must have shape (B, N) or (N,), got {np.shape(omega0)}")
        B, N = om.shape
        if N == 0:
            raise ValueError("a CPG needs at least one oscillator (got zero oscillators)")
        if B == 0:
            raise ValueError("the network needs at least one CPG (got B = 0)")
        if not np.all(np.isfinite(om)):
            raise ValueError("omega0 contains NaN or infinite values")
        self.params = params if params is not None else CPGParams()
        self.B, self.N = B, N
        shape = (B, N)
        self._s = np.empty((5, B, N))
        self._s[0] = _per_oscillator(x0, shape, "x0")
        self._s[1] = _per_oscillator(y0, shape, "y0")
        self._s[2] = om
        self._s[3] = _per_oscillator(alpha0, shape, "alpha0")
        self._s[4] = _per_oscillator(phi0, shape, "phi0")
        self.time_scale = _per_cpg(time_scale, B, "time_scale")
        if np.any(self.time_scale <= 0):
            raise ValueError("time_scale must be > 0")
        self.offset = _per_cpg(offset, B, "offset")
        self.gain = _per_cpg(gain, B, "gain")
        if np.any(self.gain == 0):
            raise ValueError("gain must be non-zero")
        # Coupling graph (see module docstring): reference oscillator as a flat index into B*N.
        idx = np.arange(B * N).reshape(shape)
        self._ref = np.where(np.arange(N)[None, :] == 0, idx, idx[:, :1])
        self._ref_omega = self._ref.copy()  # whose ω divides ω_i in ρ: the reference (eq 8) or itself (eq 13)
        self._k = np.where(np.arange(N)[None, :] == 0, 0.0, self.params.tau) * np.ones(shape)
        self._learn_phi = (self._k > 0).astype(float)
        self.learning = True
        self.t = 0.0
        self._rk_full = RK4((5, B, N))
        self._rk_xy = RK4((2, B, N))
        self._g: np.ndarray | None = None
        self._checked_dt: float | None = None
        self._scaled_h = not np.all(self.time_scale == 1.0)
        self._gmu_l = self.params.gamma * self.params.mu
        self._ts3 = self.time_scale[None, :, None]
        # playback (frozen) parameters, set by freeze()
        self._zeta = np.ones(B)
        self._amp = np.ones(B)
        self._alpha_learned = self._s[3].copy()
        self._alpha_target = self._s[3].copy()
        self._alpha_relaxing = False
        self._work = np.empty((5, 5, B, N))  # numba backend: k1..k4 and the stage state
        self._consts = np.array([self.params.epsilon, self.params.gamma, self._gmu_l, self.params.eta])
        self._g_none = np.zeros(B)
        self.backend = os.environ.get("CPG_WALKER_BACKEND", "auto") if backend is None else backend
        self._wrap_idx: np.ndarray | None = None  # flat indices of the non-harmonic oscillators (None: none)
        self.set_nonharmonic(nonharmonic)

    # ---------------------------------------------------------------- backend
    @property
    def backend(self) -> str:
        """The requested backend ("auto", "numpy" or "numba"); `uses_numba` says which one runs."""
        return self._backend

    @backend.setter
    def backend(self, value: str) -> None:
        if value not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {value!r}")
        kernels = None if value == "numpy" else _load_kernels()
        if value == "numba" and kernels is None:
            raise ImportError("backend 'numba' requested but numba is not installed (pip install numba)")
        self._backend = value
        self._kern = kernels

    @property
    def uses_numba(self) -> bool:
        """True if `step` runs the compiled kernels (kernels.py), False if numpy."""
        return self._kern is not None

    # ---------------------------------------------------------------- state access
    @property
    def x(self) -> np.ndarray:
        return self._s[0]

    @property
    def y(self) -> np.ndarray:
        return self._s[1]

    @property
    def omega(self) -> np.ndarray:
        """Learned ω (internal units), without the ζ modulation."""
        return self._s[2]

    @property
    def alpha(self) -> np.ndarray:
        """Current α (normalised units; during amplitude modulation, the relaxing value)."""
        return self._s[3]

    @property
    def phi(self) -> np.ndarray:
        return self._s[4]

    @property
    def state(self) -> np.ndarray:
        """The (5, B, N) state array [x, y, ω, α, φ] (a view: writing to it changes the network)."""
        return self._s

    def frequencies(self) -> np.ndarray:
        """Physical frequencies (rad/s) of the oscillators, (B, N): time_scale·ζ·ω."""
        zeta = 1.0 if self.learning else self._zeta[:, None]
        return self._s[2] * self.time_scale[:, None] * zeta

    def amplitudes(self) -> np.ndarray:
        """Physical amplitudes gain·α, (B, N) (α as currently applied)."""
        return self._s[3] * self.gain[:, None]

    def phases(self) -> np.ndarray:
        """θ of every oscillator (eq 9), (B, N)."""
        return phase(self._s[0], self._s[1])

    def output(self) -> np.ndarray:
        """Q_b = offset_b + gain_b·Σ_i α_{b,i} x_{b,i} (eq 11 in physical units), shape (B,)."""
        return self.offset + self.gain * np.einsum("bi,bi->b", self._s[3], self._s[0])

    # ---------------------------------------------------------------- coupling hooks (eqs 12–13)
    def couple_cpgs(
        self,
        child: int,
        parent: int,
        strength: float | None = None,
        phase_offset: float | None = None,
        learn_phase: bool = True,
    ) -> None:
        """Couple main oscillator (child, 0) to main oscillator (parent, 0) (eqs 12–13).

        Adds τ'·sin(θ_{parent,0} − φ_{child,0}) to ẋ_{child,0} (τ' = `strength`, default τ) and, while
        learning and if `learn_phase`, φ̇_{child,0} = sin(θ_{parent,0} − θ_{child,0} − φ_{child,0})
        (eq 13). With `learn_phase=False` the link is fixed: φ_{child,0} stays at `phase_offset` (eq 12
        only; e.g. π for the legs' antisymmetric coupling, a design constant). `phase_offset` sets
        φ_{child,0} (None keeps the current value). For two oscillators referencing each other, call it
        both ways."""
        for name, value in (("child", child), ("parent", parent)):
            if not 0 <= value < self.B:
                raise ValueError(f"{name} CPG index {value} out of range 0..{self.B - 1}")
        if child == parent:
            raise ValueError("a CPG cannot be coupled to itself")
        k = self.params.tau if strength is None else float(strength)
        if not np.isfinite(k) or k < 0:
            raise ValueError(f"coupling strength must be finite and >= 0, got {strength}")
        self._ref[child, 0] = parent * self.N
        self._ref_omega[child, 0] = child * self.N  # ρ = 1
        self._k[child, 0] = k
        self._learn_phi[child, 0] = 1.0 if k > 0 and learn_phase else 0.0
        if phase_offset is not None:
            self._s[4, child, 0] = float(phase_offset)
        if not self.learning:
            self._prepare_playback()

    # ---------------------------------------------------------------- non-harmonic oscillators (eq 8)
    def set_nonharmonic(self, mask: bool | np.ndarray) -> None:
        """Flag the oscillators (mask broadcast to (B, N)) whose eq 8 reference R_i = ρ·θ_ref gets the
        wrap correction (module docstring); unflagged oscillators follow the printed eq 8. Oscillator 0
        of a CPG is a phase reference, not referenced through eq 8: it cannot be flagged."""
        m = np.broadcast_to(np.asarray(mask), (self.B, self.N))
        if m.dtype != bool:
            raise ValueError(f"nonharmonic must be booleans, got dtype {m.dtype}")
        if m[:, 0].any():
            raise ValueError("oscillator 0 of a CPG is the eq 8 phase reference and cannot be non-harmonic")
        self._nonharmonic = m.copy()
        idx = np.flatnonzero(m)
        self._wrap_idx = idx if idx.size else None

    @property
    def nonharmonic(self) -> np.ndarray:
        """(B, N) booleans: oscillators with the eq 8 wrap correction (a copy; see `set_nonharmonic`)."""
        return self._nonharmonic.copy()

    def _reference_phases(self) -> np.ndarray:
        """θ (eq 9) of the reference oscillators of the non-harmonic oscillators (flat)."""
        i = self._ref.ravel()[self._wrap_idx]
        return np.arctan2(self._s[0].ravel()[i], -self._s[1].ravel()[i])

    def _absorb_reference_wraps(self, before: np.ndarray, dt: float) -> None:
        """After a step: where θ_ref wrapped (by ±2π between `before` and now), φ_i absorbs the jump of
        R_i = ρ·θ_ref modulo 2π, δ = ±2π(ρ − round ρ), so R_i − φ_i stays continuous. A step moves θ by
        at most MAX_RATE_STEP < π (check_step), so a change beyond ±π is a wrap: −π forward (θ from π to
        −π), +π backward (ω_ref < 0 or ζ < 0). Applied while learning and while frozen (φ is then the
        frozen offset to the unwrapped reference; `_phi_play` follows).

        The RK4 stages after the crossing saw the jumped target; their share of the step's increments of
        x_i (eq 4's coupling term) and, while learning, of φ_i (eq 8) is replaced by the continuous
        target's (first order, with the target at the end of the step and the crossing located by linear
        interpolation of θ_ref), so the error per wrap is O(dt²), as without wraps, not O(dt)."""
        d = self._reference_phases() - before
        turns = (d < -np.pi).astype(float) - (d > np.pi)
        hit = np.flatnonzero(turns)
        if hit.size == 0:
            return
        idx, turns = self._wrap_idx[hit], turns[hit]
        om = self._s[2].ravel()
        rho = om[idx] / om[self._ref_omega.ravel()[idx]]
        delta = 2 * np.pi * turns * (rho - np.round(rho))
        phi = self._s[4].reshape(-1)  # a view
        new = phi[idx] - delta
        new -= 2 * np.pi * np.round(new / (2 * np.pi))  # keep φ in [−π, π]
        # RK4 weight of the stages (at 0, h/2, h/2, h) that came after the crossing at fraction f of the step
        f = (np.pi * turns - before[hit]) / (d[hit] + 2 * np.pi * turns)
        late = np.where(f < 0.5, 5 / 6, 1 / 6) * dt
        i_ref = self._ref.ravel()[idx]
        x, y = self._s[0].reshape(-1), self._s[1].reshape(-1)
        target = rho * np.arctan2(x[i_ref], -y[i_ref]) - new  # continuous Θ_i at the end of the step
        if self.learning:
            ts = self.time_scale[idx // self.N]
            k = self._k.ravel()[idx] * ts
            theta = np.arctan2(x[idx], -y[idx])
            learn = self._learn_phi.ravel()[idx] * ts
            new += late * learn * (np.sin(target - theta) - np.sin(target - delta - theta))  # (8)
        else:
            k = self._k_play.ravel()[idx]
        x[idx] += late * k * (np.sin(target) - np.sin(target - delta))  # (4)
        phi[idx] = new
        if not self.learning:
            self._phi_play.reshape(-1)[idx] = new

    # ---------------------------------------------------------------- right-hand sides
    def learning_rhs(self, s: np.ndarray, Pn: np.ndarray, out: np.ndarray) -> None:
        """d[x, y, ω, α, φ]/dt: eqs 4–11 (+16–17), written into `out` (5, B, N).

        `Pn` is the *normalised* teaching input (P_teach − offset)/gain, shape (B,). Written for speed
        (numpy's per-call overhead dominates at these sizes): in-place operations, x and y stacked."""
        p = self.params
        xy = s[:2]
        x, y, om, al, ph = s
        F = Pn - (al * x).sum(axis=1)  # (10), (11): F = P_teach − Σ_i α_i x_i  (sum over all i)
        eF = (p.epsilon * F)[:, None]
        r2 = x * x + y * y
        radial = self._gmu_l - p.gamma * r2  # γ(μ − r_i²)
        theta = np.arctan2(x, -y)  # (9): θ_i = sgn(x_i)·arccos(−y_i/r_i)
        target = om / om.take(self._ref_omega)  # ρ = ω_i/ω_0 (8); 1 for eq-13 links
        target *= theta.take(self._ref)
        target -= ph  # Θ_i = R_i − φ_i, R_i = ρ·θ_ref
        np.multiply(xy, radial, out=out[:2])
        out[0] -= om * y
        out[0] += eF
        out[0] += self._k * np.sin(target)  # (4) [(12)]: ẋ_i = γ(μ−r_i²)x_i − ω_i y_i + εF + τ·sin(R_i − φ_i)
        out[1] += om * x  # (5): ẏ_i = γ(μ − r_i²)y_i + ω_i x_i
        r = np.sqrt(r2)
        np.maximum(r, R_FLOOR, out=r)  # hopf.R_FLOOR: r = 0 gives 0, not NaN
        np.divide(y, r, out=out[2])
        out[2] *= -eF  # (6): ω̇_i = −εF·y_i/r_i
        np.multiply(x, (p.eta * F)[:, None], out=out[3])  # (7): α̇_i = η x_i F
        np.subtract(target, theta, out=out[4])
        np.sin(out[4], out=out[4])
        out[4] *= self._learn_phi  # (8): φ̇_i = sin(R_i − θ_i − φ_i)  [(13): R = θ_ref]
        if self._g is not None:  # (16), (17): + g_k·(x_i, y_i)/r_i
            out[:2] += xy * (self._g[:, None] / r)
        if self._scaled_h:
            out *= self._ts3

    def playback_rhs(self, s: np.ndarray, om: np.ndarray | None, out: np.ndarray) -> None:
        """d[x, y]/dt of the frozen network (F = 0; ω, α, φ constant): eqs 4, 5 (+16, 17) with ζ·ω.

        Coefficients precomputed by `_prepare_playback` (time scale folded in); ``om`` (B, N): other
        ζ·ω coefficients (time scale folded in) than the applied ones (`forecast`), None = those."""
        om = self._om_play if om is None else om
        x, y = s
        r2 = x * x + y * y
        radial = self._gmu - self._gamma * r2
        theta_ref = np.arctan2(x, -y).take(self._ref)  # (9) of the reference oscillators
        theta_ref *= self._rho
        theta_ref -= self._phi_play
        np.multiply(s, radial, out=out)
        out[0] -= om * y
        out[0] += self._k_play * np.sin(theta_ref)  # (4)/(12)
        out[1] += om * x  # (5)
        if self._g is not None:  # (16), (17)
            out += s * ((self._g[:, None] * self._ts_play) / np.maximum(np.sqrt(r2), R_FLOOR))

    def playback_derivative(self, out: np.ndarray, state: np.ndarray | None = None,
                            om: np.ndarray | None = None) -> None:
        """d[x, y]/dt of the frozen network at its state (and the `feedback` of the last step) into `out`
        (2, B, N): `playback_rhs`, by the compiled kernel when `uses_numba` (same expressions).
        ``state`` (5, B, N) and ``om`` (as in `playback_rhs`): another state and ζ·ω than the network's
        (`forecast`)."""
        kern, g = self._kern, self._g
        s = self._s if state is None else state
        if kern is None:
            self.playback_rhs(s[:2], om, out)
        else:
            kern.playback_derivative(s, self._ref, self._rho, self._phi_play,
                                     self._om_play if om is None else om, self._k_play, self._pb_gamma,
                                     self._pb_gmu, self._g_none if g is None else g * self._pb_ts,
                                     g is not None, out)

    def forecast(self, offsets: np.ndarray, zeta: np.ndarray | None = None,
                 amplitude: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The frozen network's future output Q_b (eq 11) and its time derivative at ``offsets`` (physical
        s ahead, non-decreasing, >= 0), from a copy of x, y stepped with RK4 (eqs 4, 5, 12 with ζ·ω; the
        feedback g of the last step held): the future the network will have, up to the step size.
        Intervals are split so that each step respects `check_step`'s guard (coarser than a control
        period: the RK4 error over the horizon stays ~1e-5 rad at 20 ms steps). The network itself is
        not changed. ``zeta``: (K,) or (K, B) ζ over the interval ending at each offset (None: ζ as
        applied now); ``amplitude``: (K,) or (K, B) amplitude scale s_b of α = s_b·α_learned at each
        offset (None: α as now). Returns two (K, B) arrays. Not for networks with non-harmonic
        oscillators (their φ wrap correction is not replayed)."""
        self._require_frozen("forecast")
        if self._wrap_idx is not None:
            raise ValueError("forecast: networks with non-harmonic oscillators are not supported")
        offsets = np.asarray(offsets, dtype=float).reshape(-1)
        K, B = offsets.size, self.B
        if K == 0 or not np.all(np.isfinite(offsets)) or offsets[0] < 0 or np.any(np.diff(offsets) < 0):
            raise ValueError("forecast offsets must be finite, >= 0 and non-decreasing (at least one)")

        def per_point(values: np.ndarray | None, name: str) -> np.ndarray | None:
            if values is None:
                return None
            arr = np.asarray(values, dtype=float)
            arr = arr.reshape(-1, 1) if arr.ndim == 1 else arr
            if arr.shape not in ((K, 1), (K, B)) or not np.all(np.isfinite(arr)):
                raise ValueError(f"forecast {name}: expected {K} finite values, or {K} x {B}")
            return np.broadcast_to(arr, (K, B))

        zeta_k, amp_k = per_point(zeta, "zeta"), per_point(amplitude, "amplitude")
        zeta_max = np.abs(self._zeta[None] if zeta_k is None else zeta_k).max(axis=0)  # (B,)
        h_max = MAX_RATE_STEP / fastest_rate(self.params, self._s[2] * zeta_max[:, None], self.time_scale)
        s = self._s.copy()
        gaps = np.diff(offsets, prepend=0.0)
        nsub = np.where(gaps > 0, np.maximum(1, np.ceil(gaps / h_max)), 0).astype(np.int64)
        hs = gaps / np.maximum(nsub, 1)
        oms = np.empty((K, B, self.N))  # the ζ·ω coefficients over the interval ending at each point
        if zeta_k is None:
            oms[:] = self._om_play
        else:
            oms[:] = self._s[2][None] * zeta_k[:, :, None]
            if self._scaled_h:
                oms *= self.time_scale[None, :, None]
        x = np.empty((K, B, self.N))  # x and ẋ at each offset
        xd = np.empty((K, B, self.N))
        g = self._g
        if self._kern is not None:  # one compiled call (a Python loop of kernel calls costs ~8x more)
            gts = self._g_none if g is None else g * self._pb_ts
            self._kern.playback_forecast(s, hs, nsub, oms, self._ref, self._rho, self._phi_play, self._k_play,
                                         self._pb_gamma, self._pb_gmu, gts, g is not None,
                                         np.empty_like(self._work), x, xd)
        else:
            rk = RK4((2, B, self.N))
            deriv = np.empty((2, B, self.N))
            for k in range(K):
                for _ in range(nsub[k]):
                    rk.step(self.playback_rhs, s[:2], hs[k], oms[k], oms[k], oms[k])
                self.playback_derivative(deriv, s, oms[k])
                x[k], xd[k] = s[0], deriv[0]
        if amp_k is None:
            alpha = np.broadcast_to(s[3], x.shape)
        else:
            alpha = self._alpha_learned[None] * amp_k[:, :, None]
        q = self.offset + self.gain * np.einsum("kbi,kbi->kb", alpha, x)
        qd = self.gain * np.einsum("kbi,kbi->kb", alpha, xd)
        return q, qd

    # ---------------------------------------------------------------- learning / playback switches
    def freeze(self) -> None:
        """End learning: F = 0, ω, α, φ fixed; the learned signal stays as the limit cycle."""
        self.learning = False
        self._alpha_learned = self._s[3].copy()
        self._alpha_target = self._alpha_learned * self._amp[:, None]
        self._prepare_playback()

    def unfreeze(self) -> None:
        """Resume learning (modulation is reset: α back to its learned value, ζ = 1)."""
        self.learning = True
        self._s[3] = self._alpha_learned
        self._zeta[:] = 1.0
        self._amp[:] = 1.0
        self._alpha_relaxing = False

    def _prepare_playback(self) -> None:
        p = self.params
        self._gamma = p.gamma
        self._gmu = p.gamma * p.mu
        self._om_play = self._s[2] * self._zeta[:, None]
        om = self._s[2]
        self._rho = om / om.take(self._ref_omega)
        self._phi_play = self._s[4].copy()
        self._k_play = self._k.copy()
        self._ts_play: float | np.ndarray = 1.0
        if self._scaled_h:  # fold the time scale into the frozen coefficients (cheaper than scaling h)
            ts = self.time_scale[:, None]
            self._gamma = p.gamma * ts
            self._gmu = p.gamma * p.mu * ts
            self._om_play = self._om_play * ts
            self._k_play = self._k_play * ts
            self._ts_play = ts
        # the same coefficients as (B,) arrays for the numba kernel
        B = self.B
        self._pb_gamma = np.broadcast_to(self._gamma, (B, 1)).ravel().copy()
        self._pb_gmu = np.broadcast_to(self._gmu, (B, 1)).ravel().copy()
        self._pb_ts = np.broadcast_to(self._ts_play, (B, 1)).ravel().copy()

    # ---------------------------------------------------------------- modulation and perturbation
    def set_frequency_scale(self, zeta: float | np.ndarray) -> None:
        """ω_eff = ζ·ω for each CPG (scalar or (B,)); ζ < 0 plays the pattern backwards."""
        self._require_frozen("frequency modulation")
        self._zeta = _per_cpg(zeta, self.B, "frequency scale ζ").copy()
        self._prepare_playback()

    def set_amplitude_scale(self, scale: float | np.ndarray) -> None:
        """α → scale·α_learned per CPG (scalar or (B,)), reached smoothly (module docstring)."""
        self._require_frozen("amplitude modulation")
        self._amp = _per_cpg(scale, self.B, "amplitude scale").copy()
        self._alpha_target = self._alpha_learned * self._amp[:, None]
        if self.params.amplitude_time_constant == 0:
            self._s[3] = self._alpha_target
            self._alpha_relaxing = False
        else:
            self._alpha_relaxing = True

    def perturb(self, dx: float | np.ndarray = 0.0, dy: float | np.ndarray = 0.0) -> None:
        """Add (dx, dy) to the oscillators' states (broadcast to (B, N))."""
        shape = (self.B, self.N)
        self._s[0] += _per_oscillator(dx, shape, "dx")
        self._s[1] += _per_oscillator(dy, shape, "dy")

    def _require_frozen(self, what: str) -> None:
        if self.learning:
            raise ValueError(f"{what} applies to a frozen (learned) network: call freeze() first")

    # ---------------------------------------------------------------- stepping
    def check_step(self, dt: float) -> None:
        """Reject a non-positive, non-finite or too-large step (RK4 accuracy/stability guard)."""
        if not isinstance(dt, (int, float, np.floating)) or not np.isfinite(dt) or dt <= 0:
            raise ValueError(f"integration step must be a finite number > 0, got {dt!r}")
        zeta = 1.0 if self.learning else self._zeta[:, None]
        fastest = fastest_rate(self.params, self._s[2] * zeta, self.time_scale)
        if dt * fastest > MAX_RATE_STEP:
            raise ValueError(
                f"integration step dt={dt:g} s is too large for the fastest rate of this network "
                f"({fastest:.3g} 1/s): need dt <= {MAX_RATE_STEP / fastest:.3g} s"
            )
        self._checked_dt = dt

    def step(
        self,
        dt: float,
        teach: float | np.ndarray | None = None,
        feedback: float | np.ndarray | None = None,
    ) -> None:
        """Advance by dt (physical seconds) with RK4.

        Learning: `teach` is P_teach, either held over the step (scalar or (B,)) or sampled at the three
        RK4 times t, t + dt/2, t + dt (shape (3, B)). Frozen: no teaching input. `feedback` is g_k of
        eqs 16–17, scalar or (B,), held over the step (None = no feedback term)."""
        if dt != self._checked_dt:
            self.check_step(dt)
        theta_ref = None if self._wrap_idx is None else self._reference_phases()  # non-harmonic (eq 8)
        if feedback is None:
            self._g = None
        else:
            g = np.asarray(feedback, dtype=float)
            if g.shape != (self.B,):
                g = _per_cpg(g, self.B, "feedback g")
            elif not np.isfinite(g.sum()):
                raise ValueError("feedback g contains NaN or infinite values")
            self._g = g
        if self.learning:
            if teach is None:
                raise ValueError("a learning network needs a teaching input (or call freeze())")
            Pn = self.normalise_teaching(teach)
            kern = self._kern
            if kern is not None:
                P0, Pm, P1 = (Pn, Pn, Pn) if Pn.ndim == 1 else (Pn[0], Pn[1], Pn[2])
                g = self._g
                kern.learning_step(
                    self._s, float(dt), P0, Pm, P1, self._ref, self._ref_omega, self._k, self._learn_phi,
                    self.time_scale, self._scaled_h, self._g_none if g is None else g, g is not None,
                    self._consts, self._work,
                )
            elif Pn.ndim == 1:
                self._rk_full.step(self.learning_rhs, self._s, dt, Pn, Pn, Pn)
            else:
                self._rk_full.step(self.learning_rhs, self._s, dt, Pn[0], Pn[1], Pn[2])
        else:
            if teach is not None:
                raise ValueError("the network is frozen: it takes no teaching input (unfreeze() to learn)")
            kern = self._kern
            if kern is not None:
                g = self._g
                kern.playback_step(
                    self._s, float(dt), self._ref, self._rho, self._phi_play, self._om_play, self._k_play,
                    self._pb_gamma, self._pb_gmu, self._g_none if g is None else g * self._pb_ts,
                    g is not None, self._work,
                )
            else:
                self._rk_xy.step(self.playback_rhs, self._s[:2], dt, None, None, None)
            if self._alpha_relaxing:
                self._relax_alpha(dt)
        if theta_ref is not None:
            self._absorb_reference_wraps(theta_ref, dt)
        self.t += dt

    def normalise_teaching(self, P: float | np.ndarray) -> np.ndarray:
        """(P − offset)/gain, validated: P is a scalar, (B,) or (k, B); returns (B,) or (k, B)."""
        arr = np.asarray(P, dtype=float)
        if arr.ndim == 0:
            arr = np.full(self.B, float(arr))
        if arr.shape[-1:] != (self.B,) or arr.ndim > 2:
            raise ValueError(
                f"teaching signal has shape {arr.shape}; expected a scalar, ({self.B},) or (k, {self.B})"
            )
        if not np.isfinite(arr.sum()):
            raise ValueError("teaching signal contains NaN or infinite values")
        out = arr - self.offset
        out /= self.gain
        return out

    def _relax_alpha(self, dt: float) -> None:
        T = self.params.amplitude_time_constant
        decay = np.exp(-dt / T)
        al = self._s[3]
        al -= self._alpha_target
        al *= decay
        al += self._alpha_target
        if np.max(np.abs(al - self._alpha_target)) <= 1e-12 * (1.0 + np.max(np.abs(self._alpha_target))):
            al[...] = self._alpha_target
            self._alpha_relaxing = False


def stack_networks(nets: list[CPGNetwork]) -> CPGNetwork:
    """One network holding ``nets`` side by side (B = ΣB_k CPGs, e.g. R robots' controllers), so that one
    `step` advances them all: each keeps its own state, coefficients, coupling links (re-indexed into
    the stack), ζ/α modulation and non-harmonic flags; the equations are per oscillator, so stepping the
    stack equals stepping each network (test_cpg_stack.py). All must share N, params and learning state
    (frozen or learning); the stack uses the first one's backend. Returns a new network (no views)."""
    if not nets:
        raise ValueError("stack_networks needs at least one network")
    first = nets[0]
    for net in nets[1:]:
        if net.N != first.N or net.params != first.params or net.learning != first.learning:
            raise ValueError("stacked networks must share N, params and learning state")

    def cat(get) -> np.ndarray:
        return np.concatenate([np.asarray(get(n)) for n in nets])

    s = cat(lambda n: n.state.transpose(1, 0, 2))  # (ΣB, 5, N)
    out = CPGNetwork(s[:, 2], first.params, x0=s[:, 0], y0=s[:, 1], alpha0=s[:, 3], phi0=s[:, 4],
                     time_scale=cat(lambda n: n.time_scale), offset=cat(lambda n: n.offset),
                     gain=cat(lambda n: n.gain), backend=first.backend,
                     nonharmonic=cat(lambda n: n.nonharmonic))
    base = np.cumsum([0] + [n.B * n.N for n in nets[:-1]])
    out._ref = np.concatenate([n._ref + b for n, b in zip(nets, base, strict=True)])
    out._ref_omega = np.concatenate([n._ref_omega + b for n, b in zip(nets, base, strict=True)])
    out._k = cat(lambda n: n._k)
    out._learn_phi = cat(lambda n: n._learn_phi)
    out.t = first.t
    if not first.learning:
        out.freeze()
        out._alpha_learned = cat(lambda n: n._alpha_learned)
        out._zeta = cat(lambda n: n._zeta)
        out._amp = cat(lambda n: n._amp)
        out._alpha_target = cat(lambda n: n._alpha_target)
        out._alpha_relaxing = any(n._alpha_relaxing for n in nets)
        out._prepare_playback()
    return out
