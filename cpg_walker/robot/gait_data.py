"""The recorded HOAP-2 gaits: loader (by joint name, resampling), steady-cycle finder and a playback.

A gait file is a CSV with a header ``time_s,<joint>,<joint>,...`` (HOAP-2 joint names, radians) and one
row per sample at a uniform period. The two packaged recordings are ``walk`` and ``slow`` (see
``data/README.md`` for their source and licence). Every error names the file and the line.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cpg_walker.errors import InputError
from cpg_walker.robot.joints import JOINT_NAMES, LEG_JOINTS

DATA_DIR = Path(__file__).resolve().parent / "data"
PACKAGED: dict[str, str] = {"walk": "walk.csv", "slow": "slow_walk.csv"}


@dataclass(frozen=True)
class Gait:
    """A recorded gait: times ``t`` (s, from 0) and angles ``q`` (rows = samples, columns = ``names``)."""

    name: str
    names: tuple[str, ...]
    t: np.ndarray
    q: np.ndarray
    source: str

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    @property
    def duration(self) -> float:
        """Time of the last sample (the recording covers [0, duration])."""
        return float(self.t[-1])

    def column(self, joint: str) -> np.ndarray:
        """The angle series of one joint by name."""
        if joint not in self.names:
            have = ", ".join(self.names)
            raise KeyError(f"{self.name}: no joint {joint!r} in the recording; it has {have}")
        return self.q[:, self.names.index(joint)]

    def at(self, t: float | np.ndarray) -> np.ndarray:
        """Angles at time(s) ``t`` by linear interpolation, clamped to the recording's ends."""
        tt = np.clip(np.asarray(t, dtype=float), 0.0, self.duration)
        idx = tt / self.dt
        i0 = np.clip(np.floor(idx).astype(int), 0, len(self.t) - 1)
        i1 = np.minimum(i0 + 1, len(self.t) - 1)
        w = (idx - i0)[..., None]
        return self.q[i0] * (1.0 - w) + self.q[i1] * w

    def resample(self, dt: float) -> Gait:
        """The same gait sampled every ``dt`` seconds (linear interpolation)."""
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"resample: dt must be a positive number, got {dt!r}")
        t = np.arange(0.0, self.duration + 1e-9, dt)
        return Gait(self.name, self.names, t, self.at(t), self.source)

    def velocities(self, smooth_s: float = 0.02) -> np.ndarray:
        """Joint velocities (rad/s) by central differences of the angles smoothed over ``smooth_s``.

        The recordings hold some values for 2-3 ms (repeated rows), so raw differences are spiky."""
        n = max(1, round(smooth_s / self.dt))
        if n > 1:
            kernel = np.ones(n) / n
            pad = np.pad(self.q, ((n, n), (0, 0)), mode="edge")
            qs = np.stack([np.convolve(pad[:, j], kernel, mode="same") for j in range(pad.shape[1])], 1)[n:-n]
        else:
            qs = self.q
        return np.gradient(qs, self.dt, axis=0)


def gait_path(name_or_path: str | Path) -> Path:
    """Path of a packaged gait (``walk``, ``slow``) or of a user's file."""
    key = str(name_or_path)
    if key in PACKAGED:
        return DATA_DIR / PACKAGED[key]
    return Path(name_or_path)


def load_gait(name_or_path: str | Path, min_rows: int = 2) -> Gait:
    """Load a packaged gait by name (``walk``, ``slow``) or a CSV in the same layout.

    Raises FileNotFoundError for a missing file and ValueError ``"<file>:<line>: <what>"`` for a broken one
    (no/unknown/duplicate header names, wrong field count, non-numeric or non-finite value, time not
    increasing or not uniformly sampled, too few rows). The same file content loads once per process:
    later calls return the same Gait, whose arrays are read-only."""
    path = gait_path(name_or_path)
    if not path.is_file():
        known = ", ".join(PACKAGED)
        raise FileNotFoundError(f"gait file not found: {path} (packaged gaits: {known})")
    name = str(name_or_path) if str(name_or_path) in PACKAGED else path.stem
    raw = path.read_bytes()
    key = (hashlib.blake2b(raw, digest_size=16).digest(), str(path), name, min_rows)
    return _cached(_GAITS, key, lambda: _parse_gait(raw, path, name, min_rows))


def _cached(cache: dict, key: tuple, compute):
    """``cache[key]``, computed on a miss; the cache is emptied when it holds 32 entries."""
    value = cache.get(key)
    if value is None:
        value = compute()
        if len(cache) >= 32:
            cache.clear()
        cache[key] = value
    return value


#: load_gait's results by (content digest, path as given, name, min_rows): a process that walks many times
#: (sweeps, gain searches) parses each recording once. A changed file has another digest, so it is read anew.
_GAITS: dict[tuple, Gait] = {}


def _parse_gait(raw: bytes, path: Path, name: str, min_rows: int) -> Gait:
    """The Gait in ``raw`` (the bytes of ``path``), with read-only arrays: `load_gait` shares it."""
    lines = raw.decode("utf-8").splitlines()
    if not lines or not lines[0].strip():
        raise InputError(f"{path}:1: empty file; expected a header 'time_s,<joint>,...'")
    header = [h.strip() for h in lines[0].split(",")]
    if header[0] != "time_s":
        raise InputError(f"{path}:1: the first header field must be 'time_s', got {header[0]!r}")
    names = header[1:]
    if not names:
        raise InputError(f"{path}:1: the header names no joint")
    for n in names:
        if n not in JOINT_NAMES:
            known = ", ".join(JOINT_NAMES)
            raise InputError(f"{path}:1: unknown joint {n!r} in the header (HOAP-2 joints: {known})")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"{path}:1: duplicate joint column(s) {', '.join(dup)}")
    rows: list[list[float]] = []
    while len(lines) > 1 and not lines[-1].strip():
        lines.pop()  # trailing blank lines
    for lineno, line in enumerate(lines[1:], start=2):
        if not line.strip():
            raise InputError(f"{path}:{lineno}: blank line inside the data")
        fields = line.split(",")
        if len(fields) != len(header):
            raise InputError(f"{path}:{lineno}: {len(fields)} fields, the header has {len(header)}")
        try:
            values = [float(f) for f in fields]
        except ValueError:
            bad = next(f for f in fields if not _is_float(f))
            raise InputError(f"{path}:{lineno}: not a number: {bad.strip()!r}") from None
        if not all(math.isfinite(v) for v in values):
            raise InputError(f"{path}:{lineno}: non-finite value (nan/inf)")
        rows.append(values)
    if len(rows) < min_rows:
        raise InputError(f"{path}:{len(lines) + 1}: only {len(rows)} data row(s); need at least {min_rows}")
    data = np.asarray(rows)
    t = data[:, 0]
    steps = np.diff(t)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        raise InputError(f"{path}:{i + 3}: time {t[i + 1]:g} s does not increase (previous {t[i]:g} s)")
    dt = float(np.median(steps))
    off = np.abs(steps - dt) > 0.01 * dt + 1e-9
    if np.any(off):
        i = int(np.argmax(off))
        raise InputError(f"{path}:{i + 3}: non-uniform sampling: step {steps[i]:g} s, expected {dt:g} s")
    t = t - t[0]
    q = data[:, 1:]
    t.setflags(write=False)
    q.setflags(write=False)
    return Gait(name=name, names=tuple(names), t=t, q=q, source=str(path))


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


@dataclass(frozen=True)
class Cycle:
    """One steady gait cycle inside a recording: ``[start, start + period)``, ``mismatch`` at the seam."""

    start: float
    period: float
    mismatch_rad: float  # RMS over leg joints of q(start) - q(start + period)

    @property
    def end(self) -> float:
        return self.start + self.period


def estimate_period(gait: Gait, settle: float | None = None, lo: float = 1.5, hi: float = 4.0,
                   dip: float | None = None, min_correlation: float = 0.8) -> float:
    """Stride period (s) from the normalised autocorrelation of the leg joints after ``settle`` seconds
    (default: the second half of the recording's first 60 %), searched in [lo, hi]; it must correlate at
    least ``min_correlation``. ``dip`` (``autocorrelation_period``'s): only lags past the first one that
    correlates below it count, so a slow drift, which correlates well at every short lag, has no period
    (live teaching's rule; offline learning leaves it off)."""
    legs = [gait.names.index(j) for j in LEG_JOINTS if j in gait.names]
    if not legs:
        raise InputError(f"{gait.source}: no leg joints in the recording; cannot find a gait cycle")
    start = int((settle if settle is not None else 0.25 * gait.duration) / gait.dt)
    period, best = autocorrelation_period(gait.q[start:, legs], gait.dt, lo, hi, keep_s=1.0, dip=dip)
    if period is None and np.isnan(best):
        raise InputError(f"{gait.source}: no periodic gait found between {lo} and {hi} s (it drifts: its "
                         f"autocorrelation never falls below {dip:g})")
    if period is None or best < min_correlation:
        raise InputError(
            f"{gait.source}: no periodic gait found between {lo} and {hi} s (best correlation {best:.2f}, "
            f"at least {min_correlation:g} needed)"
        )
    return period


def autocorrelation_period(q: np.ndarray, dt: float, lo: float, hi: float, keep_s: float,
                           refine: bool = False, dip: float | None = None,
                           shortest_within: float | None = None) -> tuple[float | None, float]:
    """(period s, its normalised autocorrelation) of uniform samples ``q`` (n, k), the lag in [lo, hi] s
    whose overlap is at least ``keep_s`` long that correlates best (None, -inf when there is none): at lag
    L, Σ q[:-L]·q[L:] / √(Σ q[:-L]² Σ q[L:]²) after removing the mean, every lag at once by FFT.
    ``refine``: the peak placed between samples by a parabola through its neighbours (at most half a
    sample away). ``dip``: only lags past the first one correlating below ``dip`` count (a slowly
    drifting signal, which correlates well at every short lag, then has no period: (None, nan)).
    ``shortest_within``: the shortest lag at a local peak within this of the best (not a multiple of the
    period that happens to correlate a little better)."""
    q = np.asarray(q, dtype=float)
    q = (q - q.mean(0)).reshape(len(q), -1)
    n = len(q)
    first, last = max(1, int(lo / dt)), min(int(hi / dt), n - int(keep_s / dt))
    if last <= first:
        return None, -np.inf
    spec = np.fft.rfft(q, n=2 * n, axis=0)
    cross = np.fft.irfft((spec * spec.conj()).real.sum(axis=1), n=2 * n)[:last + 1]
    energy = np.concatenate(([0.0], np.cumsum((q * q).sum(axis=1))))  # energy[k] = Σ_{t<k} |q_t|²
    lags = np.arange(last + 1)
    corr = cross / np.sqrt(energy[n - lags] * (energy[n] - energy[lags]) + 1e-300)
    if dip is not None:
        below = np.flatnonzero(corr[1:last] < dip)
        first = max(first, 1 + int(below[0]) if below.size else last)
        if first >= last:  # it never decorrelated: a drift, not a period
            return None, float("nan")
    best_lag = first + int(np.argmax(corr[first:last]))
    best = float(corr[best_lag])
    if shortest_within is not None:
        c = corr[first:last]
        peak = np.flatnonzero((c[1:-1] >= c[:-2]) & (c[1:-1] >= c[2:]) & (c[1:-1] >= best - shortest_within))
        if peak.size:
            best_lag = first + 1 + int(peak[0])
            best = float(corr[best_lag])
    lag = float(best_lag)
    if refine and best_lag > 1 and best_lag + 1 <= last:
        left, right = corr[best_lag - 1], corr[best_lag + 1]
        curve = left - 2 * best + right
        if curve < 0:
            lag += min(0.5, max(-0.5, 0.5 * (left - right) / curve))
    return float(lag * dt), best


def find_steady_cycle(gait: Gait, tail: float = 0.8, spread: float = 0.15, window: float = 0.03,
                      lo: float = 1.5, hi: float = 4.0, dip: float | None = None,
                      min_correlation: float = 0.8) -> Cycle:
    """The last full stride of the recording, with its seam where the signal matches best (cached by
    the recording's content and the arguments: the search takes about a second).

    The cycle ends at some ``e`` in the last ``tail`` seconds and starts at ``e - T`` with ``T`` within
    ``spread`` of the autocorrelation period (``estimate_period``: searched in [``lo``, ``hi``] s, past the
    first lag correlating below ``dip`` if given, at least ``min_correlation``); ``(start, T)`` minimise
    the squared mismatch of the leg angles (and of their velocities, weighted by 0.05 s) over a ``window``
    around the seam, so repeating ``[start, start + T)`` after the recording continues it without a jump.
    A recording without such a period raises InputError (not cached)."""
    digest = hashlib.blake2b(digest_size=16)
    head = repr((gait.names, gait.t.shape, gait.t.dtype.str, gait.q.shape, gait.q.dtype.str)).encode()
    for part in (head, gait.t, gait.q):
        digest.update(np.ascontiguousarray(part).data if isinstance(part, np.ndarray) else part)
    key = (digest.hexdigest(), float(tail), float(spread), float(window), float(lo), float(hi),
           None if dip is None else float(dip), float(min_correlation))
    return _cached(_CYCLES, key, lambda: _search_steady_cycle(gait, tail, spread, window, lo, hi, dip,
                                                              min_correlation))


_CYCLES: dict[tuple, Cycle] = {}  # find_steady_cycle's results by (content digest, arguments)


def _search_steady_cycle(gait: Gait, tail: float, spread: float, window: float, lo: float,
                         hi: float, dip: float | None = None, min_correlation: float = 0.8) -> Cycle:
    period = estimate_period(gait, lo=lo, hi=hi, dip=dip, min_correlation=min_correlation)
    legs = [gait.names.index(j) for j in LEG_JOINTS if j in gait.names]
    q = gait.q[:, legs]
    v = gait.velocities()[:, legs] * 0.05
    n = len(q)
    w = max(1, int(window / gait.dt))
    ends = np.arange(max(n - 1 - int(tail / gait.dt), w), n - w)
    lags = np.arange(int((period - spread) / gait.dt), int((period + spread) / gait.dt) + 1)
    best = (np.inf, 0, 0)
    offsets = np.arange(-w, w + 1)
    for lag in lags:
        starts = ends - lag
        ok = starts - w >= 0
        if not ok.any():
            continue
        e, s = ends[ok], starts[ok]
        cost = np.zeros(len(e))
        for o in offsets[:: max(1, w // 5)]:
            cost += ((q[e + o] - q[s + o]) ** 2).sum(1) + ((v[e + o] - v[s + o]) ** 2).sum(1)
        i = int(np.argmin(cost))
        if cost[i] < best[0]:
            best = (float(cost[i]), int(s[i]), int(lag))
    _, s, lag = best
    mismatch = float(np.sqrt(np.mean((q[s + lag] - q[s]) ** 2)))
    return Cycle(start=s * gait.dt, period=lag * gait.dt, mismatch_rad=mismatch)


class GaitPlayback:
    """A target source: the recording, then its steady cycle repeated for ever.

    ``targets(t)`` returns ``(q, qd)`` over ``names`` (default: all 25 joints); joints the recording lacks
    (hands, head) get ``default`` (zero posture, as the Webots player leaves them)."""

    def __init__(self, gait: Gait, cycle: Cycle | None = None, names: tuple[str, ...] = JOINT_NAMES,
                 default: np.ndarray | None = None):
        self.gait = gait
        self.cycle = cycle if cycle is not None else find_steady_cycle(gait)
        self.names = tuple(names)
        base = np.zeros(len(self.names)) if default is None else np.asarray(default, float).copy()
        cols = [(i, gait.names.index(n)) for i, n in enumerate(self.names) if n in gait.names]
        self._dst = np.array([i for i, _ in cols], dtype=int)
        self._src = np.array([j for _, j in cols], dtype=int)
        self._base = base
        self._vel = gait.velocities()
        # targets(t) interpolates only the played columns (Gait.at's arithmetic, for one scalar time)
        self._q_src = np.ascontiguousarray(gait.q[:, self._src])
        self._vel_src = np.ascontiguousarray(self._vel[:, self._src])
        self._dt, self._duration, self._last = gait.dt, gait.duration, len(gait.t) - 1

    def recording_time(self, t: float) -> float:
        """Time in the recording that plays at time ``t`` (folds times after the cycle's end into it)."""
        c = self.cycle
        if t < c.end:
            return max(0.0, t)
        return c.start + ((t - c.start) % c.period)

    def targets(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        tr = self.recording_time(t)
        q = self._base.copy()
        qd = np.zeros(len(self.names))
        dt, last = self._dt, self._last
        tt = tr if tr > 0.0 else 0.0  # Gait.at: np.clip(t, 0, duration), then linear interpolation
        if not tt < self._duration:
            tt = self._duration
        idx = tt / dt
        i0 = min(max(math.floor(idx), 0), last)
        i1 = min(i0 + 1, last)
        w = idx - i0
        qs = self._q_src
        q[self._dst] = qs[i0] * (1.0 - w) + qs[i1] * w
        qd[self._dst] = self._vel_src[min(round(tr / dt), last)]
        return q, qd

    def standing_posture(self) -> np.ndarray:
        """The recording's first row over ``names`` (other joints at ``default``)."""
        return self.targets(0.0)[0]
