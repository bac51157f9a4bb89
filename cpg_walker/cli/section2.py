"""`cpg-walker section2 --out DIR`: the paper's Section II experiment (Figs 2-3, and beyond)."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("section2", help="paper Section II: learn Fig 2's signal, perturb/modulate (Fig 3)")
    p.add_argument("--out", required=True, help="output directory")
    p.set_defaults(func=lambda args: run_section2(Path(args.out)))


def run_section2(out_dir: Path) -> int:
    from cpg_walker.experiments.section2 import run_section2 as run

    r = run(out_dir)
    print("section2: learned frequencies (rad/s):", ", ".join(f"{w:.4f}" for w in r["learned_frequencies"]))
    print("section2: learned amplitudes:", ", ".join(f"{a:.4f}" for a in r["learned_amplitudes"]))
    print("section2: phase error vs expected offsets (rad):",
          ", ".join(f"{e:.4f}" for e in r["phase_error_vs_expected_rad"]))
    print(f"section2: convergence time {r['convergence_time_s']:.1f} s; free-run RMS error "
          f"{r['free_run_rms_error']:.4g} vs teaching RMS {r['teaching_rms']:.4g}")
    f3 = r["fig3"]
    def changes(items: list) -> str:
        return "; ".join(f"t={a['t']}: jump {a['jump']:.3g}, settle {a['settling_s']:.3f} s" for a in items)

    print(f"section2: perturbation recovery {f3['perturbation_recovery_s']:.3f} s; amplitude changes "
          f"{changes(f3['amplitude'])}; frequency changes {changes(f3['frequency'])} "
          f"(max step unmodulated {f3['max_step_unmodulated']:.3g})")
    for s in r["beyond"]["square_wave_sweep"]:
        print(f"section2: square wave N={s['oscillators']}: free-run RMS error {s['free_run_rms_error']:.4g} "
              f"/ teaching RMS {s['teaching_rms']:.4g}")
    fo = r["beyond"]["fewer_oscillators"]
    print(f"section2: {fo['oscillators']} oscillators on Fig 2's signal learn ω = {fo['frequencies']} "
          f"amplitudes {fo['amplitudes']}")
    print(f"section2: wrote {out_dir}/section2.json and PNGs")
    return 0
