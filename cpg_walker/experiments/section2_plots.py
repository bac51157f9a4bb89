"""Figures of the Section II experiment (like the paper's Figs 2a, 2b, 3; plus the N sweep)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def fig2(curves: dict, num: dict, out: Path, plt) -> None:
    rec = curves["rec"]
    fig, ax = plt.subplots(2, 1, figsize=(10, 5))
    ax[0].plot(curves["tail_t"], curves["tail_P"], "k")
    ax[0].set_title("Fig 2a: teaching signal P_teach (last 1.5 s of learning)")
    ax[0].set_ylabel("P_teach")
    ax[1].set_ylabel("output")
    ax[1].plot(curves["free_t"][:300], curves["free_P"][:300], "k--", label="P_teach")
    ax[1].plot(curves["free_t"][:300], curves["free_Q"][:300], "C1", label="Q_learned (free run, F = 0)")
    ax[1].set_title(f"learned signal after the teaching signal is removed: free-run RMS error "
                    f"{num['free_run_rms_error']:.3g} (teaching RMS {num['teaching_rms']:.3g})")
    ax[1].legend(loc="upper right")
    ax[1].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(out / "fig2a_teaching_vs_learned.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(4, 1, figsize=(10, 10), sharex=True)
    err = np.abs(rec.P[:, 0] - rec.Q[:, 0])
    ax[0].plot(rec.t, err, "0.6", lw=0.3, label="|P − Q|")
    from cpg_walker.cpg.teaching import windowed_rms

    ax[0].plot(rec.t, windowed_rms(rec.P[:, 0] - rec.Q[:, 0], 50), "k", lw=1, label="RMS over 1 s")
    ax[0].axvline(num["convergence_time_s"], color="C3", ls=":", label="convergence")
    ax[0].set_ylabel("error")
    ax[0].legend(loc="upper right")
    for i, (name, key) in enumerate([("ω_i (rad/s)", "omega"), ("α_i", "alpha"), ("φ_i (rad)", "phi")]):
        data = getattr(rec, key)[:, 0]
        for j in range(data.shape[1]):
            ax[i + 1].plot(rec.t, data[:, j], lw=1, label=f"oscillator {j}")
        ax[i + 1].set_ylabel(name)
    ax[1].legend(loc="right", fontsize=8)
    ax[3].set_xlabel("t (s)")
    ax[0].set_title("Fig 2b: error, frequencies, amplitudes (gain·α) and phases during learning")
    fig.tight_layout()
    fig.savefig(out / "fig2b_learning.png", dpi=110)
    plt.close(fig)


def fig3(curves: dict, num: dict, cfg: dict, out: Path, plt) -> None:
    t, Q = curves["t"], curves["Q"]
    fig, ax = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    ax[0].plot(t, Q[:, 0], "0.6", lw=1, label="unperturbed")
    ax[0].plot(t, curves["shifted_ref"], "k--", lw=1,
               label=f"learned output shifted by {num['perturbation_time_shift_s']:.3f} s")
    ax[0].plot(t, Q[:, 1], "C0", lw=1, label="perturbed at t = 1")
    ax[0].axvline(1.0 + num["perturbation_recovery_s"], color="C3", ls=":", lw=1, label="recovered")
    ax[0].set_title(f"Fig 3a: perturbation of all oscillators; back within tolerance after "
                    f"{num['perturbation_recovery_s']:.3g} s")
    ax[1].plot(t, curves["amp_ref"], "k--", lw=1, label="scaled reference")
    ax[1].plot(t, Q[:, 2], "C1", lw=1, label="output")
    a = num["amplitude"]
    ax[1].set_title(f"Fig 3b: amplitude vector halved at t = 2, tripled at t = 4.5 (max step "
                    f"{max(x['jump'] for x in a):.3g} vs {num['max_step_unmodulated']:.3g} unmodulated)")
    ax[2].plot(t, curves["freq_ref"], "k--", lw=1, label="time-warped reference")
    ax[2].plot(t, Q[:, 3], "C2", lw=1, label="output")
    f = num["frequency"]
    ax[2].set_title(f"Fig 3c: frequency vector halved at t = 2, tripled at t = 5 (max step "
                    f"{max(x['jump'] for x in f):.3g} vs {num['max_step_unmodulated']:.3g} unmodulated)")
    for a_ in ax:
        a_.set_ylabel("Q_learned")
    for a in ax:
        a.legend(loc="upper right", fontsize=7, framealpha=0.9)
    ax[2].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(out / "fig3_perturbation_modulation.png", dpi=110)
    plt.close(fig)


def beyond(num: dict, out: Path, plt) -> None:
    sw = num["square_wave_sweep"]
    fig, ax = plt.subplots(figsize=(7, 4))
    Ns = [s["oscillators"] for s in sw]
    ax.semilogy(Ns, [s["relative_error"] for s in sw], "o-", label="learned CPG, 10 s free run")
    ax.semilogy(Ns, [s["truncation_error_bound"] for s in sw], "k--", lw=1,
                label="best possible: N strongest Fourier components")
    ax.set_xlabel("number of oscillators N")
    ax.set_ylabel("free-run RMS error / teaching RMS")
    ax.set_title("smoothed square wave tanh(6 sin 3t): error versus N")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "beyond_error_vs_oscillators.png", dpi=110)
    plt.close(fig)

    fo = num["fewer_oscillators"]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for k, tr in enumerate(fo["trials"]):
        for w0, w, won in zip(tr["omega0"], tr["frequencies"], tr["learned_components"], strict=True):
            ax.annotate("", xy=(k, w), xytext=(k, w0),
                        arrowprops={"arrowstyle": "->", "color": "C2" if won is not None else "C3", "lw": 1})
            ax.plot(k, w0, "o", color="0.5", ms=3)
    for cw, amp in zip(fo["components_by_strength"], fo["component_amplitudes_by_strength"], strict=True):
        ax.axhline(cw, color="k", lw=0.5, ls=":")
        ax.text(len(fo["trials"]) - 0.4, cw, f"{cw:g} rad/s (amp {amp})", va="center", fontsize=8)
    ax.set_xlim(-0.6, len(fo["trials"]) + 1.8)
    ax.set_xlabel("trial (0: paper's spread linspace(6, 70, 2); others: ω(0) uniform in [6, 70])")
    ax.set_ylabel("ω: start (dot) → after learning (arrow)")
    ax.set_title(f"2 oscillators, 4 components, {fo['duration_s']:g} s: green = locked to a component; "
                 f"strongest two learned in {fo['trials_learning_the_strongest_two']}/{fo['n_trials']}",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "beyond_fewer_oscillators.png", dpi=110)
    plt.close(fig)
