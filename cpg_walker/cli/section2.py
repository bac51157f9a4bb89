"""`cpg-walker section2 --out DIR`: the paper's Section II experiment (Figs 2-3, and beyond)."""

from __future__ import annotations

import argparse
from pathlib import Path

from cpg_walker.cli.checks import out_dir


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("section2", help="paper Section II: learn Fig 2's signal, perturb/modulate (Fig 3)")
    p.add_argument("--out", required=True, type=out_dir, help="output directory")
    p.set_defaults(func=lambda args: run_section2(Path(args.out)))


def run_section2(out_dir: Path) -> int:
    from cpg_walker.experiments.section2 import run_section2 as run

    r = run(out_dir)
    print("section2: learned frequencies (rad/s):", ", ".join(f"{w:.4f}" for w in r["learned_frequencies"]))
    print("section2: learned amplitudes:", ", ".join(f"{a:.4f}" for a in r["learned_amplitudes"]))
    print("section2: phase error vs expected offsets (rad):",
          ", ".join(f"{e:.4f}" for e in r["phase_error_vs_expected_rad"]))
    conv = r["convergence_time_s"]
    print(f"section2: convergence time {conv:.1f} s" if conv == conv else "section2: not converged",
          f"({r['convergence_definition']})")
    print(f"section2: free-run RMS error over {r['free_run_s']:g} s {r['free_run_rms_error']:.4g} "
          f"vs teaching RMS {r['teaching_rms']:.4g} "
          f"({100 * r['free_run_rms_error'] / r['teaching_rms']:.2f} %)")
    f3 = r["fig3"]

    def changes(items: list) -> str:
        return "; ".join(f"t={a['t']} x{a['scale']}: max step {a['jump']:.3g}, "
                         f"settles in {a['settling_s']:.3f} s" for a in items)

    print(f"section2: Fig 3 perturbation (σ = {f3['perturbation_std']}) at t = 1: max deviation "
          f"{f3['perturbation_max_deviation']:.3g}, back on the learned waveform within "
          f"{f3['tolerance']:.3g} after {f3['perturbation_recovery_s']:.3f} s "
          f"(within 10 % after {f3['perturbation_recovery_10pct_s']:.3f} s; "
          f"lasting time shift {f3['perturbation_time_shift_s']:.4f} s)")
    print(f"section2: Fig 3 amplitude: {changes(f3['amplitude'])}")
    print(f"section2: Fig 3 frequency: {changes(f3['frequency'])}")
    print("section2: Fig 3 max sample-to-sample step of the unmodulated output: "
          f"{f3['max_step_unmodulated']:.3g}")
    for s in r["beyond"]["square_wave_sweep"]:
        print(f"section2: square wave N={s['oscillators']:2d}: free-run RMS error / teaching RMS "
              f"{s['relative_error']:.4f} (best possible with N sinusoids {s['truncation_error_bound']:.4f})")
    fo = r["beyond"]["fewer_oscillators"]
    print(f"section2: {fo['oscillators']} oscillators, blind start, {fo['n_trials']} trials: "
          "components learned "
          f"{fo['times_each_component_learned']} (strength order {fo['components_by_strength']}); "
          f"strongest two both learned in {fo['trials_learning_the_strongest_two']}/{fo['n_trials']}, "
          f"strongest learned in {fo['trials_learning_the_strongest']}/{fo['n_trials']}")
    t0 = fo["trials"][0]
    print(f"section2: paper spread ω(0) = {t0['omega0']} -> ω = {[round(w, 3) for w in t0['frequencies']]}, "
          f"learned components {t0['learned_components']}")
    print(f"section2: wrote {out_dir}/section2.json and PNGs")
    return 0
