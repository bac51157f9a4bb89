"""Benchmark of the CPG core: µs per RK4 step, learning speed, and a solve_ivp (RK45) baseline.

Configurations: Fig 2's single CPG (1×4, learning at dt = 4 ms) and the humanoid's 10×3 network
(learning at dt = 10 ms, adequate for a ~0.4 Hz gait: fastest component ~3·2.5 rad/s, ω·dt ≈ 0.08;
playback at the ROS node's 1 kHz). Baseline: the same right-hand side (CPGNetwork.learning_rhs)
integrated by scipy.integrate.solve_ivp(RK45, rtol=1e-6, atol=1e-9), timed over the same simulated
span; `max_state_difference_vs_solve_ivp` reports how far the two end states are apart (the learning
transient amplifies small integration differences, so this is ~1e-3..1e-1, not round-off).

Both CPGNetwork backends (numpy RK4, and the numba kernels if numba is installed) are measured in the
same run, interleaved (numpy, numba, numpy, numba, … per repeat) so that machine noise hits both alike.
"""

from __future__ import annotations

import time

import numpy as np

from cpg_walker.cpg import kernels
from cpg_walker.cpg.network import CPGNetwork

BACKENDS = ("numpy", "numba") if kernels.AVAILABLE else ("numpy",)


def _median_step_us(
    nets: dict[str, CPGNetwork], dt: float, teach: np.ndarray | None, n: int, repeats: int
) -> dict[str, float]:
    """Median µs per step of each network, the backends interleaved repeat by repeat."""
    times: dict[str, list[float]] = {name: [] for name in nets}
    for net in nets.values():  # warm-up (JIT compilation or cache load happens here, untimed)
        net.step(dt) if teach is None else net.step(dt, teach)
    for _ in range(repeats):
        for name, net in nets.items():
            t0 = time.perf_counter()
            if teach is None:
                for _ in range(n):
                    net.step(dt)
            else:
                for _ in range(n):
                    net.step(dt, teach)
            times[name].append((time.perf_counter() - t0) / n * 1e6)
    return {name: float(np.median(v)) for name, v in times.items()}


def _signals(B: int, w0: float):
    rng = np.random.default_rng(0)
    ph = rng.uniform(0, 2 * np.pi, (B, 3))
    amp = rng.uniform(0.2, 1.0, (B, 3))

    def signal(t):
        t = np.atleast_1d(t)[:, None, None]
        return (amp * np.sin(w0 * np.arange(1, 4) * t + ph)).sum(-1)
    return signal


def case(shape: tuple[int, int], w_base: float, dt_learn: float, span: float, quick: bool,
         reps_n: tuple[int, int] | None = None) -> dict:
    """One network shape (B, N): step costs of each backend (median of ``reps_n`` = (repeats, steps);
    None: by ``quick``), learning over ``span`` s vs solve_ivp."""
    from scipy.integrate import solve_ivp

    B, N = shape
    P = _signals(B, w_base)
    w0 = np.tile(w_base * np.arange(1, N + 1) * 0.97, (B, 1))
    reps, n = reps_n or ((3, 300) if quick else (7, 2000))
    teach = P(np.array([0.0, dt_learn / 2, dt_learn]))
    learn_us = _median_step_us({b: CPGNetwork(w0, backend=b) for b in BACKENDS}, dt_learn, teach, n, reps)
    frozen = {b: CPGNetwork(w0, backend=b) for b in BACKENDS}
    for net in frozen.values():
        net.freeze()
    play_us = _median_step_us(frozen, 1e-3, None, n, reps)
    # learning speed over `span` simulated seconds, ours vs solve_ivp, same equations and teaching
    steps = round(span / dt_learn)
    times = np.arange(2 * steps + 1) * dt_learn / 2
    Pg = P(times)
    ours: dict[str, float] = {}
    end: dict[str, np.ndarray] = {}
    for b in BACKENDS:
        net = CPGNetwork(w0, backend=b)
        net.step(dt_learn, Pg[0:3])  # warm-up, then restart from the initial state
        net = CPGNetwork(w0, backend=b)
        t0 = time.perf_counter()
        for k in range(steps):
            net.step(dt_learn, Pg[2 * k : 2 * k + 3])
        ours[b] = time.perf_counter() - t0
        end[b] = net.state.ravel().copy()
    ref = CPGNetwork(w0)
    out = np.empty_like(ref.state)

    def f(t, s):
        ref.learning_rhs(s.reshape(ref.state.shape), P(t)[0], out)
        return out.ravel().copy()

    t0 = time.perf_counter()
    sol = solve_ivp(f, (0.0, span), ref.state.ravel().copy(), method="RK45", rtol=1e-6, atol=1e-9)
    ivp = time.perf_counter() - t0
    out_case: dict = {"oscillators": f"{B}x{N}", "learning_dt_s": dt_learn, "span_s": span}
    for b in BACKENDS:
        out_case[b] = {
            "learning_step_us": learn_us[b],
            "playback_step_us_at_1kHz": play_us[b],
            "learning_sim_s_per_wall_s": span / ours[b],
            "speedup_vs_solve_ivp": ivp / ours[b],
            "max_state_difference_vs_solve_ivp": float(np.max(np.abs(sol.y[:, -1] - end[b]))),
        }
    if "numba" in end:
        out_case["max_state_difference_numba_vs_numpy"] = float(np.max(np.abs(end["numba"] - end["numpy"])))
    out_case["solve_ivp_rk45_sim_s_per_wall_s"] = span / ivp
    out_case["solve_ivp_nfev"] = int(sol.nfev)
    return out_case


def _checked(entry: dict) -> dict:
    from cpg_walker.experiments.bench_validity import check_run, numbers

    return {**check_run(figures=numbers(entry)), **entry}


def run(quick: bool = False) -> dict:
    return {
        "fig2_1x4": _checked(case((1, 4), 15.0, 0.004, 4.0 if quick else 20.0, quick)),
        "humanoid_10x3": _checked(case((10, 3), 2.5, 0.01, 10.0 if quick else 60.0, quick)),
        "integrator": "fixed-step RK4, backends: numpy (in-place buffers) and numba (compiled whole-step "
        "kernels, cpg/kernels.py); baseline solve_ivp RK45 rtol=1e-6 atol=1e-9",
        "backends": list(BACKENDS),
    }
