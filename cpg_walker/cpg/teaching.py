"""Teaching signals: validation, normalisation, periodic repetition, initial frequencies, learning loop.

This is the one code path that learns a sampled signal into a CPGNetwork (`fit_samples`), used by
`cpg-walker fit` and meant for the humanoid's per-DOF learning (one CPG per column, B columns at once).

Rules (documented choices, not in the paper):

* Mean: the paper's oscillators have zero mean, so a constant offset would be "learned" by no one and
  would stay in F. We remove it explicitly: offset = mean of the (looped) record, added back to the
  output (network.offset). Q = offset + gain·Σ α_i x_i.
* Amplitude: learning speed and stability depend on the size of F (εF drives ẋ and ω̇). Each column is
  scaled so that its RMS (after removing the mean) equals `normalised_rms` (default 1.39, the RMS of the
  paper's Fig 2 signal, for which the paper's constants were chosen): network.gain = RMS/normalised_rms.
* Time: likewise the constants were chosen for components at 15–60 rad/s. Each column's time axis is
  scaled (network.time_scale) so that its lowest significant spectral component sits at
  `reference_omega` (default 15 rad/s, Fig 2's fundamental) in internal time. Significant components
  are the periodogram's local maxima with amplitude >= `peak_threshold` of the largest (Hann window).
* Initial frequencies (`initial_omegas`): each of the N strongest significant components gets an
  oscillator started at `seed_factor`·ω_peak (0.97: 3 % off, the adaptive rule does the locking and
  the fine tuning). When more oscillators are asked for than there are significant components, the
  extra ones are seeded the same way at the next-strongest *weak* components (periodogram maxima down
  to `weak_peak_floor` of the largest, ignoring maxima within `weak_peak_exclusion_bins` resolution
  bins 2π/T of a stronger one: the Hann window's side lobes), and any still left over are spread
  uniformly over [`spread_low`·ω_lo, `spread_high`·ω_hi]. Why not the paper's blind spread: with the paper's
  constants, Fig 2's spread [6, 70] needs ~950 s for the lowest oscillator to climb to 15 rad/s, and a
  blind spread left a weak component (amplitude 0.3 next to 0.7) unlearned after 300 internal
  seconds in our trials. Oscillator 0 — the phase reference — is the lowest. The default N is the
  number of significant components.
* Repetition: if the record is shorter than the learning needs, it is played in a loop. The loop
  length L is chosen in [T/2, T] (T = record length) to minimise the mean squared difference between
  the record and itself shifted by L (a period, or multiple of it, when the signal has one), so the
  seam is as smooth as the data allows. The looped signal is interpolated with a cubic spline.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from cpg_walker.cpg.network import MAX_RATE_STEP, CPGNetwork, CPGParams


# ------------------------------------------------------------------------------------------- validation
def validate_samples(
    t: np.ndarray, values: np.ndarray, what: str = "teaching signal"
) -> tuple[np.ndarray, np.ndarray]:
    """Return (t (n,), values (n, B)) as float arrays, or raise ValueError naming the problem."""
    t = np.asarray(t, dtype=float)
    v = np.asarray(values, dtype=float)
    if v.ndim == 1:
        v = v[:, None]
    if t.ndim != 1:
        raise ValueError(f"{what}: time must be a 1-D array, got shape {t.shape}")
    if t.size == 0 or v.size == 0:
        raise ValueError(f"{what} is empty (no samples)")
    if v.ndim != 2 or v.shape[0] != t.size:
        raise ValueError(f"{what}: {t.size} time samples but values of shape {v.shape} (need ({t.size}, B))")
    if t.size < 4:
        raise ValueError(f"{what} has {t.size} samples; at least 4 are needed")
    bad = ~np.isfinite(t)
    if bad.any():
        raise ValueError(f"{what}: time sample {int(np.argmax(bad))} is NaN or infinite")
    bad_rows = ~np.all(np.isfinite(v), axis=1)
    if bad_rows.any():
        raise ValueError(f"{what}: sample {int(np.argmax(bad_rows))} is NaN or infinite")
    steps = np.diff(t)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        msg = f"{what}: time is not strictly increasing at sample {i + 1}"
        raise ValueError(f"{msg} ({t[i]} then {t[i + 1]})")
    if np.any(np.ptp(v, axis=0) == 0):
        j = int(np.argmax(np.ptp(v, axis=0) == 0))
        raise ValueError(f"{what}: column {j} is constant (nothing to learn)")
    return t, v


# ------------------------------------------------------------------------------------------- analysis
@dataclass(frozen=True)
class TeachingSettings:
    """Rules of the module docstring (values come from config/*.yaml)."""

    normalised_rms: float = 1.39
    reference_omega: float = 15.0
    peak_threshold: float = 0.1
    spread_low: float = 0.8
    spread_high: float = 1.1
    steps_per_fastest_period: float = 30.0  # dt = 2π/(this·fastest internal ω) -> ω·dt ≈ 0.21
    seed_factor: float = 0.97
    weak_peak_floor: float = 5e-4  # extra oscillators: weak components down to this fraction of the largest
    weak_peak_exclusion_bins: float = 12.0  # ... not within this many bins 2π/T of a stronger maximum


def uniform_resample(
    t: np.ndarray, v: np.ndarray, max_points: int = 1 << 16
) -> tuple[np.ndarray, np.ndarray]:
    """Resample (t, v) onto a uniform grid (median sample spacing, at most `max_points`), linear."""
    dt = float(np.median(np.diff(t)))
    n = int(min(max_points, np.floor((t[-1] - t[0]) / dt) + 1))
    tu = np.linspace(t[0], t[-1], n)
    vu = np.stack([np.interp(tu, t, v[:, j]) for j in range(v.shape[1])], axis=1)
    return tu, vu


def spectral_peaks(tu: np.ndarray, vu: np.ndarray, threshold: float) -> list[np.ndarray]:
    """Per column: angular frequencies (rad/s) of the periodogram's significant local maxima."""
    n = tu.size
    dt = (tu[-1] - tu[0]) / (n - 1)
    window = np.hanning(n)
    pad = 1 << int(np.ceil(np.log2(8 * n)))  # zero padding: finer peak location
    spec = np.abs(np.fft.rfft((vu - vu.mean(axis=0)) * window[:, None], n=pad, axis=0))
    w = 2 * np.pi * np.fft.rfftfreq(pad, dt)
    min_w = 2 * 2 * np.pi / (tu[-1] - tu[0])  # below 2 cycles per record: trend, not a component
    peaks = []
    for j in range(vu.shape[1]):
        a = spec[:, j]
        is_max = np.r_[False, (a[1:-1] > a[:-2]) & (a[1:-1] >= a[2:]), False] & (w > min_w)
        if not is_max.any():
            raise ValueError(f"column {j}: no oscillation found (fewer than 2 cycles in the record?)")
        level = threshold * a[is_max].max()
        sel = is_max & (a >= level)
        peaks.append(w[sel][np.argsort(-a[sel])])
    return peaks


def weak_peaks(tu: np.ndarray, vu: np.ndarray, strong: list[np.ndarray], floor: float,
               exclusion_bins: float) -> list[np.ndarray]:
    """Per column: further periodogram maxima (rad/s, strongest first) with amplitude >= floor·largest,
    not in `strong` and not within `exclusion_bins`·2π/T of a stronger maximum (Hann side lobes)."""
    if floor <= 0:
        return [np.empty(0) for _ in strong]
    all_peaks = spectral_peaks(tu, vu, floor)
    width = exclusion_bins * 2 * np.pi / (tu[-1] - tu[0])
    out = []
    for cand, st in zip(all_peaks, strong, strict=True):
        kept: list[float] = list(st)
        extra = []
        for w in cand:  # strongest first
            if kept and np.min(np.abs(np.asarray(kept) - w)) <= width:
                continue
            kept.append(float(w))
            extra.append(float(w))
        out.append(np.asarray(extra))
    return out


def initial_omegas(peaks_internal: np.ndarray, N: int, s: TeachingSettings,
                   weak_internal: np.ndarray | None = None) -> np.ndarray:
    """ω(0) for N oscillators (internal units, ascending; oscillator 0 = lowest = phase reference).

    The N strongest components (peaks sorted by strength, then the weak ones `weak_internal`) each get
    an oscillator started at `seed_factor`·ω_peak (a little off, so the adaptive rule still does the
    locking); if N exceeds the number of components, the rest are spread uniformly over
    [spread_low·ω_lo, spread_high·ω_hi]."""
    ranked = np.asarray(peaks_internal)
    if weak_internal is not None and ranked.size < N:
        ranked = np.concatenate([ranked, np.asarray(weak_internal)])
    chosen = s.seed_factor * ranked[:N]
    extra = N - chosen.size
    if extra > 0:
        lo = s.spread_low * float(np.min(peaks_internal))
        hi = s.spread_high * float(np.max(peaks_internal))
        chosen = np.concatenate([chosen, np.linspace(lo, hi, extra + 2)[1:-1]])
    return np.sort(chosen)


def loop_length(tu: np.ndarray, vu: np.ndarray) -> float:
    """Loop length L in [T/2, T·0.95] minimising mean((v(t) − v(t + L))²) over the overlap (all columns)."""
    n = tu.size
    x = vu - vu.mean(axis=0)
    pad = 1 << int(np.ceil(np.log2(2 * n)))
    X = np.fft.rfft(x, n=pad, axis=0)
    cross = np.fft.irfft(X * np.conj(X), n=pad, axis=0)[:n].sum(axis=1)  # Σ_t x(t)x(t+L)
    sq = (x * x).sum(axis=1)
    c = np.concatenate([[0.0], np.cumsum(sq)])
    lags = np.arange(n)
    head = c[n - lags]  # Σ_{t < n−L} x(t)²
    tail = c[n] - c[lags]  # Σ_{t >= L} x(t)²
    msd = (head + tail - 2 * cross) / np.maximum(n - lags, 1)
    lo, hi = n // 2, max(n // 2 + 1, int(0.95 * n))
    best = lo + int(np.argmin(msd[lo:hi]))
    return float(tu[best] - tu[0])


@dataclass
class TeachingPlan:
    """How a sampled signal is fed to a network: normalisation, time scale, initial ω, loop, step."""

    offset: np.ndarray
    gain: np.ndarray
    time_scale: np.ndarray
    omega0: np.ndarray  # (B, N), internal units
    peaks: list[np.ndarray]  # significant components per column (rad/s)
    loop: float  # loop length (s)
    dt: float  # integration step (physical s)
    t0: float
    spline: Callable[[np.ndarray], np.ndarray] = field(repr=False)

    def sample(self, times: np.ndarray) -> np.ndarray:
        """Teaching values (len(times), B) at physical times (repeating the loop)."""
        return self.spline(self.t0 + np.mod(times, self.loop))


def plan_teaching(
    t: np.ndarray, values: np.ndarray, n_oscillators: int | None, settings: TeachingSettings | None = None
) -> TeachingPlan:
    """Derive offset, gain, time scale, initial frequencies and the loop from the samples."""
    from scipy.interpolate import CubicSpline

    s = settings or TeachingSettings()
    t, v = validate_samples(t, values)
    if n_oscillators is not None and (not isinstance(n_oscillators, (int, np.integer)) or n_oscillators < 1):
        raise ValueError(f"number of oscillators must be an integer >= 1, got {n_oscillators!r}")
    tu, vu = uniform_resample(t, v)
    L = loop_length(tu, vu)
    inside = tu < tu[0] + L - 0.5 * (tu[1] - tu[0])
    vl = vu[inside]
    offset = vl.mean(axis=0)
    rms = np.sqrt(np.mean((vl - offset) ** 2, axis=0))
    gain = rms / s.normalised_rms
    peaks = spectral_peaks(tu, vu, s.peak_threshold)
    w_lo = np.array([p.min() for p in peaks])
    time_scale = w_lo / s.reference_omega
    N = n_oscillators if n_oscillators is not None else max(len(p) for p in peaks)
    if N > min(len(p) for p in peaks):
        weak = weak_peaks(tu, vu, peaks, s.weak_peak_floor, s.weak_peak_exclusion_bins)
    else:
        weak = [np.empty(0) for _ in peaks]
    omega0 = np.stack([initial_omegas(p / c, N, s, wk / c)
                       for p, wk, c in zip(peaks, weak, time_scale, strict=True)])
    hi = omega0.max(axis=1)
    fastest = float(np.max(hi * time_scale))  # rad/s
    dt = 2 * np.pi / (s.steps_per_fastest_period * fastest)
    dt = min(dt, 0.9 * MAX_RATE_STEP / float(np.max(time_scale * 2 * 8.0)))  # radial-rate guard (γμ ≤ 8 typ.)
    # loop: the record from t[0] to t[0] + L, closed with its first sample so the spline is continuous
    t_loop = np.concatenate([tu[inside] - tu[0], [L]])
    v_loop = np.concatenate([vl, vu[:1]], axis=0)
    spline = CubicSpline(t_loop, v_loop, axis=0)
    return TeachingPlan(offset, gain, time_scale, omega0, peaks, L, dt, 0.0, spline)


# ------------------------------------------------------------------------------------------- learning
@dataclass
class LearningRecord:
    """Samples recorded every `every` steps: t (m,), P and Q (m, B), omega/alpha/phi (m, B, N)."""

    t: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    omega: np.ndarray
    alpha: np.ndarray
    phi: np.ndarray


def learn(
    net: CPGNetwork,
    teach: Callable[[np.ndarray], np.ndarray],
    dt: float,
    duration: float,
    record_dt: float | None = None,
    progress: object | None = None,
) -> LearningRecord:
    """Integrate the learning network for `duration` s; `teach(times)` -> (len(times), B) P_teach.

    The teaching signal is evaluated in chunks at the RK4 stage times (t, t + dt/2, t + dt).
    `progress` is a cpg_walker.progress.Progress (or None)."""
    if not np.isfinite(duration) or duration <= 0:
        raise ValueError(f"learning duration must be > 0, got {duration}")
    net.check_step(dt)
    if not net.learning:
        raise ValueError("the network is frozen: call unfreeze() before learning")
    n = round(duration / dt)
    every = max(1, round((record_dt or dt) / dt))
    m = n // every + 1
    B, N = net.B, net.N
    rec = LearningRecord(np.empty(m), np.empty((m, B)), np.empty((m, B)), np.empty((m, B, N)),
                         np.empty((m, B, N)), np.empty((m, B, N)))
    t_start = net.t
    chunk = 4096
    j = 0
    for c0 in range(0, n, chunk):
        c1 = min(n, c0 + chunk)
        times = t_start + np.arange(2 * c0, 2 * c1 + 1) * (dt / 2)
        Pg = np.asarray(teach(times), dtype=float).reshape(times.size, B)
        if not np.isfinite(Pg).all():
            raise ValueError("teaching signal contains NaN or infinite values")
        for k in range(c1 - c0):
            if (c0 + k) % every == 0:
                rec.t[j] = net.t
                rec.P[j] = Pg[2 * k]
                rec.Q[j] = net.output()
                rec.omega[j] = net.frequencies()
                rec.alpha[j] = net.amplitudes()
                rec.phi[j] = net.phi
                j += 1
            net.step(dt, Pg[2 * k : 2 * k + 3])
        if progress is not None:
            progress.update(net.t - t_start)
    for name in ("t", "P", "Q", "omega", "alpha", "phi"):
        setattr(rec, name, getattr(rec, name)[:j])
    return rec


def windowed_rms(x: np.ndarray, n_window: int) -> np.ndarray:
    """RMS of x over a trailing window of n_window samples (same length as x; first values partial)."""
    c = np.concatenate([[0.0], np.cumsum(x * x)])
    idx = np.arange(1, x.size + 1)
    lo = np.maximum(0, idx - n_window)
    return np.sqrt((c[idx] - c[lo]) / (idx - lo))


def convergence_time(
    t: np.ndarray, err: np.ndarray, teach_rms: float, window: float, fraction: float
) -> float:
    """First time after which the trailing-window RMS of err stays below fraction·teach_rms (NaN if never).

    The window must cover at least one period of the signal's fundamental."""
    dt = t[1] - t[0]
    w = windowed_rms(err, max(1, round(window / dt)))
    above = np.nonzero(w >= fraction * teach_rms)[0]
    if above.size == 0:
        return float(t[0])
    if above[-1] == t.size - 1:
        return float("nan")
    return float(t[above[-1] + 1])


def free_run(net: CPGNetwork, dt: float, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """Integrate the (frozen) network; returns t (n+1,) and Q (n+1, B)."""
    n = round(duration / dt)
    net.check_step(dt)
    t = np.empty(n + 1)
    Q = np.empty((n + 1, net.B))
    for k in range(n + 1):
        t[k] = net.t
        Q[k] = net.output()
        if k < n:
            net.step(dt)
    return t, Q


def make_network(plan: TeachingPlan, params: CPGParams) -> CPGNetwork:
    """A learning network set up from a TeachingPlan (offset, gain, time scale, initial ω)."""
    return CPGNetwork(plan.omega0, params, time_scale=plan.time_scale, offset=plan.offset, gain=plan.gain)


_SETTINGS_FIELDS = {f for f in TeachingSettings.__dataclass_fields__}


def settings_from_dict(d: dict) -> TeachingSettings:
    unknown = set(d) - _SETTINGS_FIELDS
    if unknown:
        raise ValueError(f"unknown teaching setting(s): {sorted(unknown)}")
    return TeachingSettings(**{k: float(v) for k, v in d.items()})
