"""Teaching signals: validation, normalisation, periodic repetition, initial frequencies, learning loop.

The code path that learns sampled signals into a CPGNetwork, one CPG per column: `plan_teaching` (how
the signal is fed: the rules below), `make_network`, `learn`, `free_run`. Used by `cpg-walker fit`
(experiments/fit.py, `fit_signal`) and Section II's "beyond the paper" runs; the humanoid seeds its
oscillators on the gait's harmonics instead (walker/controller.py). The settings (`TeachingSettings`)
have no defaults here: the caller passes them (cpg_walker reads them from config/cpg_section2.yaml).

Rules (documented choices, not in the paper):

* Mean: the paper's oscillators have zero mean, so a constant offset would be "learned" by no one and
  would stay in F. We remove it explicitly: offset = mean of the (looped) record, added back to the
  output (network.offset). Q = offset + gain·Σ α_i x_i.
* Amplitude: learning speed and stability depend on the size of F (εF drives ẋ and ω̇). Each column is
  scaled so that its RMS (after removing the mean) equals `normalised_rms` (e.g. the RMS of the paper's
  Fig 2 signal, for which the paper's constants were chosen): network.gain = RMS/normalised_rms.
* Time: likewise the constants were chosen for components at 15–60 rad/s. Each column's time axis is
  scaled (network.time_scale) so that its lowest significant spectral component sits at
  `reference_omega` (e.g. Fig 2's fundamental) in internal time. Significant components are the
  periodogram's local maxima with amplitude >= `peak_threshold` of the largest (Hann window, after
  removing the window-weighted mean, so no leakage of the constant shows up as a low component).
* Initial frequencies (`spectral_seed_omegas`): each of the N strongest significant components gets an
  oscillator started at `seed_factor`·ω_peak (a little off: the adaptive rule does the locking and the
  fine tuning). When more oscillators are asked for than there are significant components, the
  extra ones are seeded the same way at the next-strongest *weak* components (periodogram maxima down
  to `weak_peak_floor` of the largest, ignoring maxima within `weak_peak_exclusion_bins` resolution
  bins 2π/T of a stronger one: the Hann window's side lobes), and any still left over are
  spread uniformly over [`spread_low`·ω_lo, `spread_high`·ω_hi]. Why not the paper's blind spread:
  with the paper's constants, Fig 2's spread [6, 70] needs ~950 s for the lowest oscillator to climb
  to 15 rad/s, and a blind spread left a weak component (amplitude 0.3 next to 0.7) unlearned after
  300 internal seconds in our trials. Oscillator 0 — the phase reference of eq 8 — is the one seeded
  at the lowest significant component. The default N is the number of significant components.
* Non-harmonic components (`nonharmonic_mask`): an oscillator seeded at a component whose ratio ρ to
  oscillator 0's is farther than `harmonic_tolerance` (plus the peaks' location uncertainty) from an
  integer gets eq 8's wrap correction (network.py, "Non-harmonic oscillators"); without it such a
  component's frequency is learned but the waveform is lost. Harmonic components keep the printed
  eq 8, which pulls their ratios onto exact integers. In a signal with non-harmonic components the
  oscillators seeded at no component are flagged too.
* Repetition: if the record is shorter than the learning needs, it is played in a loop. The loop
  length L is chosen in [T/2, 0.95·T] (T = record length) to minimise the mean squared difference
  between the record and itself shifted by L (a period, or multiple of it, when the signal has one),
  so the seam is as smooth as the data allows. The looped signal is interpolated with a cubic spline.
* Step: dt = 2π/(`steps_per_fastest_period`·fastest ω), and at most 0.9 of what
  `CPGNetwork.check_step` allows for the network's constants (`network.fastest_rate`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from cpg_walker.cpg.network import MAX_RATE_STEP, CPGNetwork, CPGParams, fastest_rate


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
    """Rules of the module docstring. No defaults here: the values live in the caller's configuration
    (cpg_walker's config/cpg_section2.yaml, `teaching:`), which builds this with `settings_from_dict`."""

    normalised_rms: float  # each column's RMS in normalised units
    reference_omega: float  # internal rad/s of the lowest significant component
    peak_threshold: float  # significant component: amplitude >= this fraction of the largest
    spread_low: float  # oscillators beyond the components: spread over [spread_low·ω_lo, ...
    spread_high: float  # ... spread_high·ω_hi]
    steps_per_fastest_period: float  # dt = 2π/(this·fastest internal ω)
    seed_factor: float  # ω(0) = seed_factor·(detected component)
    weak_peak_floor: float  # extra oscillators: weak components down to this fraction of the largest ...
    weak_peak_exclusion_bins: float  # ... not within this many bins 2π/T of a stronger maximum
    harmonic_tolerance: float  # |ρ − round ρ| above this: a non-harmonic oscillator (nonharmonic_mask)

    def __post_init__(self) -> None:
        for name in _SETTINGS_FIELDS:
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"teaching setting {name} must be a finite number >= 0, got {value!r}")
        for name in ("normalised_rms", "reference_omega", "steps_per_fastest_period", "seed_factor"):
            if getattr(self, name) <= 0:
                raise ValueError(f"teaching setting {name} must be > 0, got {getattr(self, name)!r}")


_SETTINGS_FIELDS = tuple(TeachingSettings.__dataclass_fields__)


def settings_from_dict(d: dict) -> TeachingSettings:
    """TeachingSettings from a mapping that names every field (e.g. a YAML section), as floats."""
    unknown = set(d) - set(_SETTINGS_FIELDS)
    if unknown:
        raise ValueError(f"unknown teaching setting(s): {sorted(unknown)}")
    missing = [k for k in _SETTINGS_FIELDS if k not in d]
    if missing:
        raise ValueError(f"missing teaching setting(s): {missing}")
    values = {}
    for k in _SETTINGS_FIELDS:
        try:
            values[k] = float(d[k])
        except (TypeError, ValueError):
            raise ValueError(f"teaching setting {k} must be a number, got {d[k]!r}") from None
    return TeachingSettings(**values)


def uniform_resample(
    t: np.ndarray, v: np.ndarray, max_points: int = 1 << 16
) -> tuple[np.ndarray, np.ndarray]:
    """Resample (t, v) onto a uniform grid (median sample spacing, at most `max_points`), linear."""
    dt = float(np.median(np.diff(t)))
    n = int(min(max_points, np.floor((t[-1] - t[0]) / dt) + 1))
    tu = np.linspace(t[0], t[-1], n)
    vu = np.stack([np.interp(tu, t, v[:, j]) for j in range(v.shape[1])], axis=1)
    return tu, vu


def periodogram_spacing(tu: np.ndarray) -> float:
    """rad/s between the frequencies at which `spectral_peaks` evaluates the periodogram of samples on
    the uniform grid `tu` (zero padding to a power of 2 >= 8n: 1/8 of the resolution 2π/T or finer)."""
    return 2 * np.pi / (_padded_length(tu.size) * (tu[-1] - tu[0]) / (tu.size - 1))


def _padded_length(n: int) -> int:
    return 1 << int(np.ceil(np.log2(8 * n)))


def spectral_peaks(tu: np.ndarray, vu: np.ndarray, threshold: float) -> list[np.ndarray]:
    """Per column: angular frequencies (rad/s) of the periodogram's significant local maxima, located to
    within half the `periodogram_spacing`."""
    n = tu.size
    dt = (tu[-1] - tu[0]) / (n - 1)
    window = np.hanning(n)
    pad = _padded_length(n)  # zero padding: finer peak location
    # the window-weighted mean: the windowed signal has no constant left to leak into the lowest bins
    centred = vu - (window @ vu) / window.sum()
    spec = np.abs(np.fft.rfft(centred * window[:, None], n=pad, axis=0))
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


def spectral_seed_omegas(peaks_internal: np.ndarray, N: int, s: TeachingSettings,
                         weak_internal: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """ω(0) for N oscillators seeded at spectral components (internal units), and for each the
    component it is seeded at (NaN: not seeded at one).

    The N strongest components (peaks sorted by strength, then the weak ones `weak_internal`) each get
    an oscillator started at `seed_factor`·ω_peak (a little off, so the adaptive rule still does the
    locking); if N exceeds the number of components, the rest are spread uniformly over
    [spread_low·ω_lo, spread_high·ω_hi]. Oscillator 0, the phase reference, is the one seeded at the
    lowest significant component given an oscillator; the others follow in ascending order."""
    strong = np.asarray(peaks_internal)
    ranked = strong
    if weak_internal is not None and ranked.size < N:
        ranked = np.concatenate([ranked, np.asarray(weak_internal)])
    component = ranked[:N]
    chosen = s.seed_factor * component
    extra = N - chosen.size
    if extra > 0:
        lo = s.spread_low * float(np.min(strong))
        hi = s.spread_high * float(np.max(strong))
        chosen = np.concatenate([chosen, np.linspace(lo, hi, extra + 2)[1:-1]])
        component = np.concatenate([component, np.full(extra, np.nan)])
    reference = int(np.argmin(component[: min(N, strong.size)]))
    rest = [i for i in np.argsort(chosen, kind="stable") if i != reference]
    order = np.array([reference, *rest])
    return chosen[order], component[order]


def nonharmonic_mask(component: np.ndarray, tolerance: float, spacing: float) -> np.ndarray:
    """Which oscillators get eq 8's wrap correction (network.py). `component`: per oscillator (0 = the
    phase reference, seeded at a component), the component it is seeded at (NaN: none), located to
    within ±spacing/2 (`periodogram_spacing`, same units).

    Oscillator i >= 1 seeded at a component is non-harmonic if ρ_i = component_i/component_0 is farther
    from the nearest integer than its location uncertainty (1 + ρ_i)·spacing/(2·component_0) plus
    `tolerance` (for the window's bias: components leak into each other's peaks). An oscillator seeded
    at no component (spread) may end on any component: it is flagged if the signal has non-harmonic
    components (on a harmonic one the correction vanishes, ρ − round ρ → 0), and left to the printed
    eq 8 if the signal is harmonic."""
    flags = np.zeros(component.shape, dtype=bool)
    rho = component[1:] / component[0]
    known = np.isfinite(rho)
    r = rho[known]
    flags[1:][known] = np.abs(r - np.round(r)) > tolerance + (1 + r) * spacing / (2 * component[0])
    if flags.any():
        flags[1:][~known] = True
    return flags


def loop_length(tu: np.ndarray, vu: np.ndarray) -> float:
    """Loop length L in [T/2, T·0.95] minimising mean((v(t) − v(t + L))²) over the overlap (all columns),
    located between samples by a parabola through the minimum and its neighbours: a loop a fraction of a
    sample off the period would put a phase jump into every repetition (free-run error growing with
    time against the looped signal)."""
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
    step = (tu[-1] - tu[0]) / (n - 1)
    shift = 0.0
    if lo < best < hi - 1:
        m0, m1, m2 = msd[best - 1], msd[best], msd[best + 1]
        curvature = m0 - 2 * m1 + m2
        if curvature > 0:
            shift = float(np.clip(0.5 * (m0 - m2) / curvature, -0.5, 0.5))
    return float(tu[best] - tu[0] + shift * step)


@dataclass
class TeachingPlan:
    """How a sampled signal is fed to a network: normalisation, time scale, initial ω, loop, step."""

    params: CPGParams  # the network's constants (the step respects their γμ)

    offset: np.ndarray
    gain: np.ndarray
    time_scale: np.ndarray
    omega0: np.ndarray  # (B, N), internal units
    nonharmonic: np.ndarray  # (B, N) booleans: eq 8 wrap correction (nonharmonic_mask)
    peaks: list[np.ndarray]  # significant components per column (rad/s)
    loop: float  # loop length (s)
    dt: float  # integration step (physical s)
    t0: float
    spline: Callable[[np.ndarray], np.ndarray] = field(repr=False)

    def sample(self, times: np.ndarray) -> np.ndarray:
        """Teaching values (len(times), B) at physical times (repeating the loop)."""
        return self.spline(self.t0 + np.mod(times, self.loop))


def plan_teaching(
    t: np.ndarray, values: np.ndarray, n_oscillators: int | None, settings: TeachingSettings,
    params: CPGParams,
) -> TeachingPlan:
    """Derive offset, gain, time scale, initial frequencies, non-harmonic flags, the loop and the step
    (for a network with constants `params`) from the samples."""
    from scipy.interpolate import CubicSpline

    s = settings
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
    seeds = [spectral_seed_omegas(p / c, N, s, wk / c)
             for p, wk, c in zip(peaks, weak, time_scale, strict=True)]
    omega0 = np.stack([om for om, _ in seeds])
    spacing = periodogram_spacing(tu) / time_scale  # internal rad/s, per column
    nonharmonic = np.stack([nonharmonic_mask(comp, s.harmonic_tolerance, sp)
                            for (_, comp), sp in zip(seeds, spacing, strict=True)])
    hi = omega0.max(axis=1)
    fastest = float(np.max(hi * time_scale))  # rad/s
    dt = 2 * np.pi / (s.steps_per_fastest_period * fastest)
    dt = min(dt, 0.9 * MAX_RATE_STEP / fastest_rate(params, omega0, time_scale))  # CPGNetwork.check_step
    # loop: the record from t[0] to t[0] + L, closed with its first sample so the spline is continuous
    t_loop = np.concatenate([tu[inside] - tu[0], [L]])
    v_loop = np.concatenate([vl, vu[:1]], axis=0)
    spline = CubicSpline(t_loop, v_loop, axis=0)
    return TeachingPlan(params, offset, gain, time_scale, omega0, nonharmonic, peaks, L, dt, 0.0, spline)


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


def make_network(plan: TeachingPlan) -> CPGNetwork:
    """A learning network set up from a TeachingPlan (constants, offset, gain, time scale, initial ω,
    non-harmonic oscillators)."""
    return CPGNetwork(plan.omega0, plan.params, time_scale=plan.time_scale, offset=plan.offset,
                      gain=plan.gain, nonharmonic=plan.nonharmonic)


