"""Paper Section II: Fig 2 (learning a 4-component signal), Fig 3 (perturbation, modulation), and the
"beyond the paper" runs (square wave vs number of oscillators; fewer oscillators than components)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from cpg_walker.cpg import teaching as tch
from cpg_walker.cpg.network import CPGNetwork
from cpg_walker.experiments.fit import fit_signal, load_config, params_from

COMPONENTS = [(15.0, 0.8, -np.pi / 2), (30.0, 1.0, 0.0), (45.0, 1.4, np.pi / 2), (60.0, 0.5, np.pi)]


def p_teach(t: np.ndarray) -> np.ndarray:
    """Fig 2: P = 0.8 sin 15t + cos 30t − 1.4 sin 45t − 0.5 cos 60t (= Σ a cos(ωt + p), COMPONENTS)."""
    return 0.8 * np.sin(15 * t) + np.cos(30 * t) - 1.4 * np.sin(45 * t) - 0.5 * np.cos(60 * t)


def run_fig2(cfg: dict, progress: bool = True) -> tuple[CPGNetwork, dict, dict]:
    """Learn P_teach with the paper's set-up; returns the frozen network, numbers, and curves."""
    from cpg_walker.progress import Progress

    c = cfg["fig2"]
    lo, hi = c["omega0_range"]
    net = CPGNetwork(np.linspace(lo, hi, int(c["oscillators"])), params_from(cfg))
    pr = Progress(float(c["duration"]), "section2: Fig 2 learning", enabled=progress)
    rec = tch.learn(net, lambda t: p_teach(t)[:, None], float(c["dt"]), float(c["duration"]),
                  record_dt=float(c["record_dt"]), progress=pr)
    pr.close()
    one_period = np.linspace(0.0, 2 * np.pi / 15.0, 4096, endpoint=False)
    teach_rms = float(np.sqrt(np.mean(p_teach(one_period) ** 2)))  # = sqrt(Σ a²/2) = 1.387
    err = rec.P[:, 0] - rec.Q[:, 0]
    conv = tch.convergence_time(rec.t, err, teach_rms, float(c["convergence_window"]),
                              float(c["convergence_fraction"]))
    freqs = net.frequencies()[0].copy()
    amps = (net.amplitudes() * np.hypot(net.x, net.y))[0].copy()  # α_i·r_i: the component's amplitude
    phi = net.phi[0].copy()
    # expected φ_i for the oscillator phases the teaching signal implies (network.py, eq 8 notes)
    k = freqs / freqs[0]
    p = np.array([ph for _, _, ph in COMPONENTS]) + np.where(net.alpha[0] < 0, np.pi, 0.0)
    expected_phi = k * p[0] - p + (k - 1) * np.pi / 2
    phi_err = np.angle(np.exp(1j * (phi - expected_phi)))[1:]
    net.freeze()
    ft, fQ = tch.free_run(net, float(c["dt"]), float(c["free_run"]))
    fP = p_teach(ft)
    free_rms = float(np.sqrt(np.mean((fQ[:, 0] - fP) ** 2)))
    numbers = {
        "learned_frequencies": [float(v) for v in freqs],
        "learned_amplitudes": [float(v) for v in amps],
        "learned_alpha": [float(v) for v in net.alpha[0]],
        "learned_phases": [float(v) for v in phi],
        "phase_error_vs_expected_rad": [float(v) for v in phi_err],
        "convergence_time_s": conv,
        "convergence_definition": (
            "first time after which the RMS of P_teach − Q_learned over a trailing "
            f"{c['convergence_window']} s "
            f"window stays below {c['convergence_fraction']:.0%} of the teaching RMS"),
        "free_run_rms_error": free_rms,
        "teaching_rms": teach_rms,
        "free_run_s": float(c["free_run"]),
        "learning_s": float(c["duration"]),
        "dt_s": float(c["dt"]),
    }
    tail_t = np.linspace(rec.t[-1] - 1.5, rec.t[-1], 1500)
    curves = {"rec": rec, "free_t": ft, "free_Q": fQ[:, 0], "free_P": fP, "tail_t": tail_t,
              "tail_P": p_teach(tail_t)}
    return net, numbers, curves


def _copy_network(net: CPGNetwork, B: int, cfg: dict) -> CPGNetwork:
    """B frozen copies of a learned single CPG (one batched network)."""
    s = net.state[:, 0]
    new = CPGNetwork(np.repeat(s[2][None], B, 0), params_from(cfg), x0=s[0], y0=s[1], alpha0=s[3], phi0=s[4])
    new.freeze()
    return new


def _settle_time(t: np.ndarray, dev: np.ndarray, t_change: float, t_end: float, tol: float) -> float:
    sel = (t >= t_change) & (t < t_end)
    bad = np.nonzero(np.abs(dev[sel]) >= tol)[0]
    return 0.0 if bad.size == 0 else float(t[sel][bad[-1]] + (t[1] - t[0]) - t_change)


def run_fig3(net: CPGNetwork, cfg: dict) -> tuple[dict, dict]:
    """Perturbation and modulation of the learned CPG: 4 copies stepped together (B = 4):
    0 reference, 1 perturbed at t_p, 2 amplitude-modulated, 3 frequency-modulated."""
    c = cfg["fig3"]
    dt, dur = float(c["dt"]), float(c["duration"])
    n = round(dur / dt)
    b = _copy_network(net, 4, cfg)
    rng = np.random.default_rng(int(c["seed"]))
    events: list[tuple[float, str, float]] = [(float(c["perturb_time"]), "perturb", 0.0)]
    events += [(float(tc), "amp", float(s)) for tc, s in c["amplitude_changes"]]
    events += [(float(tc), "freq", float(s)) for tc, s in c["frequency_changes"]]
    events.sort()
    t = np.arange(n + 1) * dt
    Q = np.empty((n + 1, 4))
    phases = np.empty((n + 1, 4, b.N))
    amp = np.ones(4)
    zeta = np.ones(4)
    ei = 0
    for k in range(n + 1):
        while ei < len(events) and events[ei][0] <= t[k] + 1e-12:
            _, kind, s = events[ei]
            if kind == "perturb":
                mask = np.zeros((4, 1))
                mask[1] = 1.0
                std = float(c["perturbation_std"])
                b.perturb(mask * rng.normal(0, std, (4, b.N)), mask * rng.normal(0, std, (4, b.N)))
            elif kind == "amp":
                amp[2] = s
                b.set_amplitude_scale(amp)
            else:
                zeta[3] = s
                b.set_frequency_scale(zeta)
            ei += 1
        Q[k] = b.output()
        phases[k] = b.phases()
        if k < n:
            b.step(dt)
    ref = Q[:, 0]
    peak = float(np.max(np.abs(ref)))
    tol = float(c["settle_fraction"]) * peak
    base_step = float(np.max(np.abs(np.diff(ref))))
    out: dict = {"tolerance": tol, "max_step_unmodulated": base_step}
    tp = float(c["perturb_time"])
    # A perturbation of an autonomous limit cycle leaves a permanent phase (time) shift: "returning to the
    # learned output" means returning to the learned waveform, shifted by the phase oscillator 0 keeps.
    th = phases[:, 1, 0] - phases[:, 0, 0]
    shift = float(np.angle(np.exp(1j * th[-1])))
    delay = shift / float(b.frequencies()[1, 0])  # s: Q_pert(t) → Q_ref(t + delay)
    shifted = np.interp(t + delay, t, ref, left=np.nan, right=np.nan)
    ok = np.isfinite(shifted)
    dev = np.where(t < tp, Q[:, 1] - ref, Q[:, 1] - shifted)
    out["perturbation_std"] = float(c["perturbation_std"])
    out["perturbation_max_deviation"] = float(np.max(np.abs(Q[:, 1] - ref)))
    out["perturbation_phase_shift_rad"] = shift
    out["perturbation_time_shift_s"] = delay
    out["perturbation_recovery_s"] = _settle_time(t[ok], dev[ok], tp, float(t[ok][-1]), tol)
    out["perturbation_recovery_10pct_s"] = _settle_time(t[ok], dev[ok], tp, float(t[ok][-1]), 5 * tol)
    out["perturbation_recovery_definition"] = (
        f"time after t = {tp} s after which |Q_perturbed(t) − Q_unperturbed(t + time_shift)| stays below "
        f"{c['settle_fraction']:.0%} of max|Q| (time_shift: the phase shift oscillator 0 keeps, as any "
        "autonomous limit cycle does)")

    def jump(col: int, tc: float) -> float:
        """max |ΔQ| between consecutive samples within ±0.05 s of a change at tc"""
        sel = (t[:-1] >= tc - 0.05) & (t[:-1] <= tc + 0.05)
        return float(np.max(np.abs(np.diff(Q[:, col]))[sel]))

    # amplitude: scaled reference = s·Q_ref (oscillators untouched, α relaxes)
    amp_ref = np.ones(n + 1)
    for tc, s in c["amplitude_changes"]:
        amp_ref[t >= tc] = s
    ach = [float(tc) for tc, _ in c["amplitude_changes"]] + [dur]
    out["amplitude"] = [
        {"t": ach[i], "scale": float(c["amplitude_changes"][i][1]),
         "jump": jump(2, ach[i]),
         "settling_s": _settle_time(t, Q[:, 2] - amp_ref * ref, ach[i], ach[i + 1], tol)}
        for i in range(len(ach) - 1)
    ]
    # frequency: scaled reference = reference output at the warped time τ(t) = ∫ ζ dt
    zeta_t = np.ones(n + 1)
    for tc, s in c["frequency_changes"]:
        zeta_t[t >= tc] = s
    warped = np.concatenate([[0.0], np.cumsum(zeta_t[:-1] * dt)])
    fref = np.interp(warped, t, ref)
    fch = [float(tc) for tc, _ in c["frequency_changes"]] + [dur]
    valid = warped <= t[-1]
    out["jump_definition"] = ("max |Q(t_k+1) − Q(t_k)| over samples within ±0.05 s of the change "
                              f"(dt = {dt} s), vs max_step_unmodulated of the unmodulated output")
    out["frequency"] = [
        {"t": fch[i], "scale": float(c["frequency_changes"][i][1]),
         "jump": jump(3, fch[i]),
         "settling_s": _settle_time(t[valid], (Q[:, 3] - fref)[valid], fch[i], min(fch[i + 1], t[valid][-1]),
                                    tol)}
        for i in range(len(fch) - 1)
    ]
    return out, {"t": t, "Q": Q, "amp_ref": amp_ref * ref, "freq_ref": np.where(valid, fref, np.nan),
                 "shifted_ref": np.where(t < tp, ref, shifted)}


def smoothed_square(cfg: dict) -> tuple[np.ndarray, np.ndarray]:
    c = cfg["beyond"]
    t = np.arange(0, float(c["record"]), 1 / float(c["sample_rate"]))
    return t, np.tanh(float(c["sharpness"]) * np.sin(float(c["base_omega"]) * t))


def truncation_error(cfg: dict, n_components: int) -> float:
    """RMS of the smoothed square wave minus its n strongest Fourier components, / its RMS: the best
    any n-oscillator CPG (n sinusoids) can do."""
    c = cfg["beyond"]
    w0 = float(c["base_omega"])
    tt = np.linspace(0, 2 * np.pi / w0, 8192, endpoint=False)
    v = np.tanh(float(c["sharpness"]) * np.sin(w0 * tt))
    a = np.abs(np.fft.rfft(v)[1:]) / tt.size * 2
    rest = np.sort(a)[::-1][n_components:]
    return float(np.sqrt(np.sum(rest ** 2) / 2) / np.sqrt(np.mean(v ** 2)))


def run_sweep(cfg: dict, progress: bool = True) -> list[dict]:
    """Smoothed square wave learned with N = 2..12 oscillators (the fit path: seeded at the periodogram's
    components, strongest first; see teaching.py) — free-run error versus N."""
    from cpg_walker.progress import Progress

    c = cfg["beyond"]
    t, v = smoothed_square(cfg)
    local = {**cfg, "teaching": {**cfg["teaching"], "seed_factor": float(c["seed_factor"])}}
    Ns = [int(N) for N in c["oscillators"]]
    pr = Progress(float(sum(Ns)), "section2: square wave N sweep", unit="osc", enabled=progress)
    sweep = []
    done = 0
    for N in Ns:
        r = fit_signal(t, v, N, local, duration_internal=float(c["duration_internal"]),
                       free_run_internal=float(c["free_run_internal"]))
        sweep.append({"oscillators": N,
                      "free_run_rms_error": float(r.free_run_rms_error[0]),
                      "teaching_rms": float(r.teaching_rms[0]),
                      "relative_error": float(r.free_run_rms_error[0] / r.teaching_rms[0]),
                      "truncation_error_bound": truncation_error(cfg, N),
                      "free_run_s": float(r.free_t[-1] - r.free_t[0]),
                      "learning_s": float(r.learn_time),
                      "frequencies": sorted(float(w) for w in r.net.frequencies()[0])})
        done += N
        pr.update(done)
    pr.close()
    return sweep


def classify(freqs: np.ndarray, amps: np.ndarray, rtol: float = 0.01, min_amp: float = 0.5) -> list:
    """Which component of P_teach each oscillator learned: its ω within rtol of a component and |amplitude|
    at least min_amp of that component's; None = not (yet) learned."""
    out = []
    for w, a in zip(freqs, amps, strict=True):
        hit = None
        for cw, ca, _ in COMPONENTS:
            if abs(w - cw) <= rtol * cw and abs(a) >= min_amp * ca:
                hit = cw
        out.append(hit)
    return out


def run_fewer(cfg: dict, progress: bool = True) -> dict:
    """Fewer oscillators than components, blind as in the paper: 2 oscillators, ω(0) spread uniformly
    (the paper's rule: linspace(6, 70, 2)) and `trials` − 1 further spreads drawn uniformly from [6, 70];
    all trials are B independent CPGs of one batched network learning Fig 2's signal."""
    from cpg_walker.progress import Progress

    c = cfg["fewer"]
    lo, hi = cfg["fig2"]["omega0_range"]
    n = int(c["oscillators"])
    rng = np.random.default_rng(int(c["seed"]))
    drawn = np.sort(rng.uniform(lo, hi, (int(c["trials"]) - 1, n)), axis=1)
    om0 = np.vstack([np.linspace(lo, hi, n)[None], drawn])
    B = om0.shape[0]
    net = CPGNetwork(om0, params_from(cfg))
    pr = Progress(float(c["duration"]), "section2: 2 oscillators, blind start", enabled=progress)
    tch.learn(net, lambda t: np.repeat(p_teach(t)[:, None], B, 1), float(c["dt"]), float(c["duration"]),
              record_dt=1.0, progress=pr)
    pr.close()
    freqs = net.frequencies()
    amps = net.amplitudes() * np.hypot(net.x, net.y)
    trials = []
    counts = {str(int(cw)): 0 for cw, _, _ in COMPONENTS}
    strongest = sorted(COMPONENTS, key=lambda comp: -comp[1])[:n]
    strongest_set = sorted(cw for cw, _, _ in strongest)
    n_strongest = 0
    n_has_top = 0
    for b in range(B):
        won = classify(freqs[b], amps[b])
        for w in set(won):
            if w is not None:
                counts[str(int(w))] += 1
        n_strongest += sorted(w for w in won if w is not None) == strongest_set
        n_has_top += strongest[0][0] in won
        trials.append({"omega0": [float(w) for w in om0[b]], "frequencies": [float(w) for w in freqs[b]],
                       "amplitudes": [float(a) for a in amps[b]], "learned_components": won})
    return {"oscillators": n, "duration_s": float(c["duration"]), "dt_s": float(c["dt"]),
            "components_by_strength": [cw for cw, _, _ in sorted(COMPONENTS, key=lambda comp: -comp[1])],
            "component_amplitudes_by_strength": [ca for _, ca, _ in
                                                 sorted(COMPONENTS, key=lambda comp: -comp[1])],
            "trials": trials, "times_each_component_learned": counts,
            "trials_learning_the_strongest_two": int(n_strongest),
            "trials_learning_the_strongest": int(n_has_top), "n_trials": B,
            "definition": "a component is learned when an oscillator's ω is within 1 % of it and its "
                          "amplitude α·r is at least half the component's"}


def run_beyond(cfg: dict, progress: bool = True) -> tuple[dict, dict]:
    return {"square_wave_sweep": run_sweep(cfg, progress), "fewer_oscillators": run_fewer(cfg, progress)}, {}


def _no_nan(obj):
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _no_nan(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_no_nan(v) for v in obj]
    return obj


def run_section2(out_dir: Path, progress: bool = True) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cpg_walker.experiments import section2_plots as plots

    cfg = load_config()
    out_dir.mkdir(parents=True, exist_ok=True)
    net, fig2, curves2 = run_fig2(cfg, progress)
    fig3, curves3 = run_fig3(net, cfg)
    beyond, _ = run_beyond(cfg, progress)
    result = {**fig2, "fig3": fig3, "beyond": beyond}
    # strict JSON: a number that could not be obtained is written as null, never as NaN
    (out_dir / "section2.json").write_text(json.dumps(_no_nan(result), indent=2, allow_nan=False) + "\n")
    plots.fig2(curves2, fig2, out_dir, plt)
    plots.fig3(curves3, fig3, cfg, out_dir, plt)
    plots.beyond(beyond, out_dir, plt)
    return result
