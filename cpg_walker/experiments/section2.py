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
    from cpg_walker.cli.progress import Progress

    c = cfg["fig2"]
    lo, hi = c["omega0_range"]
    net = CPGNetwork(np.linspace(lo, hi, int(c["oscillators"])), params_from(cfg))
    pr = Progress(float(c["duration"]), "section2: Fig 2 learning", enabled=progress)
    rec = tch.learn(net, lambda t: p_teach(t)[:, None], float(c["dt"]), float(c["duration"]),
                  record_dt=float(c["record_dt"]), progress=pr)
    pr.close()
    teach_rms = float(np.sqrt(np.mean([a * a / 2 for _, a, _ in COMPONENTS])))
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
    curves = {"rec": rec, "free_t": ft, "free_Q": fQ[:, 0], "free_P": fP}
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
        if k < n:
            b.step(dt)
    ref = Q[:, 0]
    peak = float(np.max(np.abs(ref)))
    tol = float(c["settle_fraction"]) * peak
    out: dict = {"tolerance": tol, "max_step_unmodulated": float(np.max(np.abs(np.diff(ref))))}
    tp = float(c["perturb_time"])
    out["perturbation_recovery_s"] = _settle_time(t, Q[:, 1] - ref, tp, dur, tol)
    out["perturbation_max_deviation"] = float(np.max(np.abs(Q[:, 1] - ref)))
    # amplitude: scaled reference = s·Q_ref (oscillators untouched, α relaxes)
    amp_ref = np.ones(n + 1)
    for tc, s in c["amplitude_changes"]:
        amp_ref[t >= tc] = s
    ach = [float(tc) for tc, _ in c["amplitude_changes"]] + [dur]
    out["amplitude"] = [
        {"t": ach[i], "scale": float(c["amplitude_changes"][i][1]),
         "jump": float(abs(Q[round(ach[i] / dt) + 1, 2] - Q[round(ach[i] / dt), 2])),
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
    out["frequency"] = [
        {"t": fch[i], "scale": float(c["frequency_changes"][i][1]),
         "jump": float(abs(Q[round(fch[i] / dt) + 1, 3] - Q[round(fch[i] / dt), 3])),
         "settling_s": _settle_time(t[valid], (Q[:, 3] - fref)[valid], fch[i], min(fch[i + 1], t[valid][-1]),
                                    tol)}
        for i in range(len(fch) - 1)
    ]
    return out, {"t": t, "Q": Q, "amp_ref": amp_ref * ref, "freq_ref": np.where(valid, fref, np.nan)}


def smoothed_square(cfg: dict) -> tuple[np.ndarray, np.ndarray]:
    c = cfg["beyond"]
    t = np.arange(0, float(c["record"]), 1 / float(c["sample_rate"]))
    return t, np.tanh(float(c["sharpness"]) * np.sin(float(c["base_omega"]) * t))


def run_beyond(cfg: dict) -> tuple[dict, dict]:
    c = cfg["beyond"]
    t, v = smoothed_square(cfg)
    sweep = []
    for N in c["oscillators"]:
        r = fit_signal(t, v, int(N), cfg, duration_internal=float(c["duration_internal"]))
        sweep.append({"oscillators": int(N), "free_run_rms_error": float(r.free_run_rms_error[0]),
                      "teaching_rms": float(r.teaching_rms[0]),
                      "frequencies": sorted(float(w) for w in r.net.frequencies()[0])})
    # fewer oscillators than components: 2 oscillators on Fig 2's signal, via the fit path (seeded at
    # the two strongest detected components, teaching.initial_omegas: what they learn, not a blind race)
    few = int(c["few_oscillators"])
    tt = np.arange(0, 60, 0.005)
    r = fit_signal(tt, p_teach(tt), few, cfg, duration_internal=float(c["duration_internal"]))
    few_out = {"oscillators": few, "frequencies": [float(w) for w in r.net.frequencies()[0]],
               "amplitudes": [float(a) for a in (r.net.amplitudes() * np.hypot(r.net.x, r.net.y))[0]],
               "free_run_rms_error": float(r.free_run_rms_error[0]), "teaching_rms": float(r.teaching_rms[0]),
               "detected_components_by_strength": [float(w) for w in r.plan.peaks[0]]}
    return {"square_wave_sweep": sweep, "fewer_oscillators": few_out}, {"t": t, "v": v}


def run_section2(out_dir: Path, progress: bool = True) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cpg_walker.experiments import section2_plots as plots

    cfg = load_config()
    out_dir.mkdir(parents=True, exist_ok=True)
    net, fig2, curves2 = run_fig2(cfg, progress)
    fig3, curves3 = run_fig3(net, cfg)
    beyond, _ = run_beyond(cfg)
    result = {**fig2, "fig3": fig3, "beyond": beyond}
    (out_dir / "section2.json").write_text(json.dumps(result, indent=2) + "\n")
    plots.fig2(curves2, fig2, out_dir, plt)
    plots.fig3(curves3, fig3, cfg, out_dir, plt)
    plots.beyond(beyond, out_dir, plt)
    return result
