"""`cpg-walker learn`: learn the humanoid CPG from the recorded walk (paper Sec. III-A) and draw Fig 6.

Writes DIR/cpg_humanoid.yaml, DIR/fig6.png (learned vs recorded trajectories of the 10 DOFs) and
DIR/learn.json; with ``install=True`` (``--install``) it also replaces the packaged config/cpg_humanoid.yaml,
the file cpg_node loads by default.

Fig 6 and the RMS errors are measured on the *frozen* network running freely (no teaching input) from
its state at the teaching cycle's phase 0, over `figure.strides` strides, against the recorded steady
stride repeated — i.e. what the controller will actually produce.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from cpg_walker.paths import share_dir
from cpg_walker.robot.joints import paper_name
from cpg_walker.walker import storage
from cpg_walker.walker.controller import CHAIN, DOFS, HumanoidCPG, teaching_cycle
from cpg_walker.walker.learning import DEFAULT_CPG_FILE, learning_settings, load_learning_config


def free_run_errors(ctrl: HumanoidCPG, strides: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Free run of the frozen network from phase 0: t, Q (n, 10), recorded P (n, 10), measured gait Hz."""
    cyc = teaching_cycle(ctrl.meta["teaching"]["gait"])
    ctrl.set_modulation_state(1.0, 1.0)
    ctrl.reset_phase(0.0)
    h = ctrl.settings.control_dt
    n = round(strides * ctrl.period / h)
    Q = np.empty((n, len(DOFS)))
    for k in range(n):
        Q[k] = ctrl.joint_targets()[0]
        ctrl.step(h)
    t = np.arange(n) * h
    P = cyc.sample(t)
    # measured frequency: upward mean crossings of the left Hip2 output
    x = Q[:, DOFS.index("lleg_joint_3")] - Q[:, DOFS.index("lleg_joint_3")].mean()
    up = np.nonzero((x[:-1] < 0) & (x[1:] >= 0))[0]
    tc = t[up] - x[up] * h / (x[up + 1] - x[up])
    freq = float((len(tc) - 1) / (tc[-1] - tc[0])) if len(tc) > 1 else float("nan")
    return t, Q, P, freq


def plot_fig6(t: np.ndarray, Q: np.ndarray, P: np.ndarray, rms_deg: np.ndarray, path: Path,
              title: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(5, 2, figsize=(11, 11), sharex=True)
    for b, joint in enumerate(DOFS):
        ax = axes[b % 5, b // 5]
        ax.plot(t, np.degrees(Q[:, b]), "-", color="C0", lw=1.6, label="CPG output (learned)")
        ax.plot(t, np.degrees(P[:, b]), "--", color="k", lw=1.0, label="recorded (teaching)")
        ax.set_title(f"{paper_name(joint)} ({joint}): RMS error {rms_deg[b]:.2f}°", fontsize=9)
        ax.set_ylabel("angle (deg)")
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    axes[0, 0].legend(fontsize=8, loc="upper right")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def run_learn(out_dir: str, n_oscillators: int | None = None, install: bool = False,
              progress_enabled: bool = True) -> dict:
    from cpg_walker.progress import Progress

    cfg = load_learning_config()
    settings, params = learning_settings(n_oscillators, cfg)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    progress = Progress(settings.max_strides, f"learn N={settings.n_oscillators}", unit="strides",
                        enabled=progress_enabled)
    ctrl, rep = HumanoidCPG.learn(cfg.get("gait", "walk"), settings, params, progress=progress)
    progress.total = float(rep.strides)  # the bar ends where learning stopped
    progress.close("converged" if rep.converged else "budget spent, NOT converged")
    written = [storage.save(ctrl, out / DEFAULT_CPG_FILE)]
    if install:
        written.append(storage.save(ctrl, share_dir() / "config" / DEFAULT_CPG_FILE))
    strides = int(cfg.get("figure", {}).get("strides", 3))
    t, Q, P, measured = free_run_errors(ctrl, strides)
    rms = np.degrees(np.sqrt(np.mean((Q - P) ** 2, axis=0)))
    teach = ctrl.meta["teaching"]
    rec_hz = float(teach["recorded_gait_frequency_hz"])
    learned_hz = ctrl.gait_frequency_hz()
    title = (f"Fig 6: learned (N = {ctrl.net.N} oscillators/DOF, frozen, free run) vs recorded walk; "
             f"gait {learned_hz:.4f} Hz learned vs {rec_hz:.4f} Hz recorded")
    fig = plot_fig6(t, Q, P, rms, out / "fig6.png", title)
    om = ctrl.net.omega * ctrl.net.time_scale[:, None]
    report = {
        "gait_frequency_hz": learned_hz,
        "recorded_gait_frequency_hz": rec_hz,
        "gait_frequency_error_rel": learned_hz / rec_hz - 1.0,
        "free_run_gait_frequency_hz": measured if math.isfinite(measured) else None,
        "rms_error_deg": {j: round(float(r), 4) for j, r in zip(DOFS, rms, strict=True)},
        "rms_error_deg_by_paper_name": {paper_name(j): round(float(r), 4)
                                        for j, r in zip(DOFS, rms, strict=True)},
        "max_rms_error_deg": round(float(rms.max()), 4),
        "rms_error_definition": f"frozen network free-running from the teaching cycle's phase 0, over "
                                f"{strides} strides, against the recorded stride repeated",
        "n_oscillators": int(ctrl.net.N),
        "converged": rep.converged,
        "strides_learned": rep.strides,
        "learning_time_s": rep.learn_time_s,
        "learning_dt_s": rep.dt,
        "learning_wall_time_s": round(rep.wall_time_s, 3),
        "convergence_criterion": ctrl.meta["learning"]["criterion"],
        "teaching_window": {"gait": teach["gait"], "start_s": teach["cycle_start_s"],
                            "end_s": teach["cycle_start_s"] + teach["cycle_period_s"],
                            "period_s": teach["cycle_period_s"], "repeated": True},
        "harmonic_ratios": {j: [round(float(w / om[b, 0]), 4) for w in om[b]] for b, j in enumerate(DOFS)},
        "inter_dof_phases_rad": {f"{DOFS[c]}<-{DOFS[p]}": float(ctrl.net.phi[c, 0])
                                 for c, p in CHAIN},
        "last_chunks": rep.history[-3:],
        "files": {"yaml": [str(p) for p in written], "figure": str(fig)},
    }
    (out / "learn.json").write_text(json.dumps(report, indent=2, allow_nan=False) + "\n")
    return report
