"""Learn sampled signals into CPGs (`cpg-walker fit`; Section II's "beyond the paper" runs).

`fit_signal` is the reusable part: plan (teaching.plan_teaching) -> learn in chunks until converged or
the time budget is spent -> freeze -> free run against the (looped) teaching signal. One CPG per column.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from cpg_walker.cpg import teaching as tch
from cpg_walker.cpg.network import CPGNetwork, CPGParams
from cpg_walker.errors import InputError
from cpg_walker.paths import config_path


def load_config(name: str = "cpg_section2.yaml") -> dict:
    with open(config_path(name)) as fh:
        return yaml.safe_load(fh)


def params_from(cfg: dict) -> CPGParams:
    return CPGParams(**{k: float(v) for k, v in cfg["cpg"].items()})


@dataclass
class FitResult:
    net: CPGNetwork  # frozen
    plan: tch.TeachingPlan
    record: tch.LearningRecord
    learn_time: float  # s (physical) of learning
    convergence_time: np.ndarray  # (B,), s (NaN if not converged)
    free_t: np.ndarray
    free_q: np.ndarray
    free_p: np.ndarray
    free_run_rms_error: np.ndarray  # (B,)
    teaching_rms: np.ndarray  # (B,)


def fit_signal(
    t: np.ndarray,
    values: np.ndarray,
    n_oscillators: int | None = None,
    cfg: dict | None = None,
    progress_label: str | None = None,
    duration_internal: float | None = None,
    free_run_internal: float | None = None,
) -> FitResult:
    """Learn `values` (n,) or (n, B) sampled at times `t` (s); returns the frozen network and metrics."""
    from cpg_walker.progress import Progress

    cfg = cfg or load_config()
    fc = cfg["fit"]
    settings = tch.settings_from_dict(cfg["teaching"])
    params = params_from(cfg)
    plan = tch.plan_teaching(t, values, n_oscillators, settings, params)
    net = tch.make_network(plan)
    c_min = float(plan.time_scale.min())
    budget = float(duration_internal or fc["duration_internal"]) / c_min  # physical seconds
    period = 2 * np.pi / (plan.time_scale * settings.reference_omega)  # lowest component's period (B,)
    window = float(fc["convergence_window_periods"]) * float(period.max())
    frac = float(fc["convergence_fraction"])
    free_len = max(10.0, float(free_run_internal or fc["free_run_internal"]) / c_min)
    # a frequency still moving by dω per chunk would shift the free run's phase by ~dω·free_len: stop only
    # when that stays below the configured phase drift (a per-chunk *relative* bound let the weakest
    # component stop 4e-4 off, a 0.5 rad slip over the free run)
    max_step = float(fc["convergence_phase_drift"]) / free_len  # rad/s per chunk
    chunk = max(20.0 / c_min, 4 * window)
    record_dt = max(plan.dt, float(period.min()) / 20)
    progress = Progress(budget, progress_label or "learning", enabled=progress_label is not None)
    records: list[tch.LearningRecord] = []
    good_chunks = 0
    last_omega = net.frequencies().copy()
    while budget - net.t >= plan.dt:  # a remainder shorter than one step would record nothing
        rec = tch.learn(net, plan.sample, plan.dt, min(chunk, budget - net.t), record_dt=record_dt)
        records.append(rec)
        progress.update(net.t)
        err = rec.P - rec.Q
        n_w = max(1, round(window / record_dt))
        recent = np.sqrt(np.mean(err[-n_w:] ** 2, axis=0)) / (plan.gain * settings.normalised_rms)
        om = net.frequencies()
        step = np.max(np.abs(om - last_omega))
        last_omega = om.copy()
        good_chunks = good_chunks + 1 if (np.all(recent < frac) and step < max_step) else 0
        if good_chunks >= 2:
            break
    progress.close()
    record = tch.LearningRecord(*(np.concatenate([getattr(r, f) for r in records]) for f in
                                ("t", "P", "Q", "omega", "alpha", "phi")))
    teach_rms = plan.gain * settings.normalised_rms
    conv = np.array([
        tch.convergence_time(record.t, record.P[:, b] - record.Q[:, b], teach_rms[b], window, frac)
        for b in range(net.B)
    ])
    learn_time = net.t
    net.freeze()
    ft, fQ = tch.free_run(net, plan.dt, free_len)
    fP = plan.sample(ft)
    rms_err = np.sqrt(np.mean((fQ - fP) ** 2, axis=0))
    return FitResult(net, plan, record, learn_time, conv, ft, fQ, fP, rms_err, teach_rms)


# ------------------------------------------------------------------------------------------- CSV input
TIME_NAMES = ("time", "t", "time_s", "t_s", "timestamp", "seconds", "sec", "s")


def pick_time_column(header: list[str], time_column: str | None = None) -> int:
    """Index of the time column: the one named `time_column`; else the first header that names time
    (`time`, `t`, `time_s`, `timestamp`, `seconds`, … or any name starting with "time", any case, units in
    brackets ignored); else the first column."""
    if time_column is not None:
        if time_column not in header:
            raise InputError(f"no time column named {time_column!r} (columns: {', '.join(header)})")
        return header.index(time_column)
    for i, name in enumerate(header):
        bare = name.split("[")[0].split("(")[0].strip().lower()
        if bare in TIME_NAMES or bare.startswith("time"):
            return i
    return 0


def read_csv(
    path: str | Path, column: str | None, time_column: str | None = None
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Read a CSV with a header: a time column (s; see `pick_time_column`) and signal columns.
    Returns t, values, names. `column` selects one signal column by name (default: all the others).
    Errors name the file and line."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"CSV file not found: {path}")
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    rows = [r for r in rows if any(cell.strip() for cell in r)]
    if not rows:
        raise InputError(f"{path}: the file is empty")
    header = [h.strip() for h in rows[0]]
    if len(header) < 2:
        raise InputError(f"{path}:1: need a header with a time column and at least one signal column")
    try:
        tcol = pick_time_column(header, time_column)
    except ValueError as exc:
        raise InputError(f"{path}: {exc}") from None
    signals = [name for i, name in enumerate(header) if i != tcol]
    if column is not None:
        if column not in signals:
            raise InputError(f"{path}: no column named {column!r} (columns: {', '.join(signals)})")
        cols = [header.index(column)]
    else:
        cols = [i for i in range(len(header)) if i != tcol]
    data = np.empty((len(rows) - 1, 1 + len(cols)))
    for i, row in enumerate(rows[1:]):
        line = i + 2
        if len(row) != len(header):
            raise InputError(f"{path}:{line}: {len(row)} fields, the header has {len(header)}")
        for j, c in enumerate([tcol, *cols]):
            cell = row[c].strip()
            try:
                value = float(cell)
            except ValueError:
                raise InputError(f"{path}:{line}: column {header[c]!r}: {cell!r} is not a number") from None
            if not np.isfinite(value):
                raise InputError(f"{path}:{line}: column {header[c]!r}: {cell!r} is not a finite number")
            data[i, j] = value
    if data.shape[0] == 0:
        raise InputError(f"{path}: no data rows after the header")
    steps = np.diff(data[:, 0])
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        raise InputError(
            f"{path}:{i + 3}: time {data[i + 1, 0]} does not increase (previous row: {data[i, 0]})"
        )
    return data[:, 0], data[:, 1:], [header[c] for c in cols]


# ------------------------------------------------------------------------------------------- CLI job
def run_fit(csv_path: Path, column: str | None, n_oscillators: int | None, out_dir: Path,
            time_column: str | None = None) -> int:
    """Read, learn, write DIR/fit.json and DIR/fit.png; print the numbers."""
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, values, names = read_csv(csv_path, column, time_column)
    res = fit_signal(t, values, n_oscillators, progress_label="fit: learning")
    out_dir.mkdir(parents=True, exist_ok=True)
    freqs = res.net.frequencies()
    amps = res.net.amplitudes() * _radius(res.net)
    order = np.argsort(freqs, axis=1)

    def per_col(a: np.ndarray) -> list:
        rows = [a[b, order[b]].tolist() for b in range(a.shape[0])]  # Python floats (or bools)
        return rows[0] if len(rows) == 1 else rows

    def scalar(a: np.ndarray) -> float | list:
        return float(a[0]) if a.size == 1 else [float(v) for v in a]

    result = {
        "csv": str(csv_path),
        "columns": names,
        "oscillators": int(res.net.N),
        "learned_frequencies": per_col(freqs),
        "learned_amplitudes": per_col(amps),
        "learned_phases": per_col(res.net.phi),
        "nonharmonic_oscillators": per_col(res.net.nonharmonic),
        "offset": scalar(res.net.offset),
        "free_run_rms_error": scalar(res.free_run_rms_error),
        "teaching_rms": scalar(res.teaching_rms),
        "convergence_time_s": scalar(res.convergence_time),
        "learning_time_s": float(res.learn_time),
        "spectral_components_rad_s": [[float(w) for w in p] for p in res.plan.peaks],
        "time_scale": scalar(res.plan.time_scale),
        "loop_length_s": float(res.plan.loop),
        "record_length_s": float(t[-1] - t[0]),
        "dt_s": float(res.plan.dt),
        "notes": {
            "learned_amplitudes": "physical amplitude of each oscillator's component: gain·α_i·r_i",
            "learned_phases": "φ_i (eq 8), rad; phase offset of oscillator i to oscillator 0 (for a "
                              "non-harmonic oscillator: to the current wrap of θ_0, see network.py)",
            "nonharmonic_oscillators": "oscillators with eq 8's wrap correction (component not an integer "
                                       "multiple of oscillator 0's; cpg/teaching.py nonharmonic_mask)",
            "repetition": "the record is played in a loop of loop_length_s when learning needs longer",
        },
    }
    (out_dir / "fit.json").write_text(json.dumps(result, indent=2) + "\n")
    _plot(res, names, out_dir / "fit.png", plt)
    for b, name in enumerate(names):
        f = ", ".join(f"{freqs[b, i]:.4g}" for i in order[b])
        a = ", ".join(f"{amps[b, i]:.3g}" for i in order[b])
        print(f"{name}: learned ω = [{f}] rad/s, amplitudes = [{a}]")
        conv = res.convergence_time[b]
        when = (f"converged at {conv:.4g} s" if np.isfinite(conv)
                else "did not converge within the learning budget")
        print(f"{name}: free-run RMS error {res.free_run_rms_error[b]:.4g} vs teaching RMS "
              f"{res.teaching_rms[b]:.4g}; {when} (learned for {res.learn_time:.4g} s)")
    print(f"fit: wrote {out_dir / 'fit.json'} and {out_dir / 'fit.png'}")
    return 0


def _radius(net: CPGNetwork) -> np.ndarray:
    return np.sqrt(net.x ** 2 + net.y ** 2)


def _plot(res: FitResult, names: list[str], path: Path, plt) -> None:
    B = res.net.B
    fig, axes = plt.subplots(B, 2, figsize=(12, 2.6 * B + 0.6), squeeze=False)
    rec = res.record
    span = min(rec.t[-1], 5 * 2 * np.pi / float(np.min(res.plan.time_scale) * 15.0))
    for b in range(B):
        ax = axes[b, 0]
        sel = rec.t >= rec.t[-1] - span
        ax.plot(rec.t[sel], rec.P[sel, b], "k--", lw=1.2, label="teaching P")
        ax.plot(rec.t[sel], rec.Q[sel, b], "C1", lw=1, label="learned Q (learning)")
        ax.set_title(f"{names[b]}: end of learning")
        ax.set_xlabel("t (s)")
        ax.legend(loc="upper right", fontsize=8)
        ax = axes[b, 1]
        sel = res.free_t <= res.free_t[0] + span
        ax.plot(res.free_t[sel], res.free_p[sel, b], "k--", lw=1.2, label="teaching P (continued)")
        ax.plot(res.free_t[sel], res.free_q[sel, b], "C0", lw=1, label="free-running CPG (F = 0)")
        ax.set_title(f"{names[b]}: free run, RMS error {res.free_run_rms_error[b]:.3g} "
                     f"(teaching RMS {res.teaching_rms[b]:.3g})")
        ax.set_xlabel("t (s)")
        ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
