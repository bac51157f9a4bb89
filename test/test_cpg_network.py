"""Unit tests of the CPG core: each equation's right-hand side, step-size independence, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from cpg_walker.cpg import kernels
from cpg_walker.cpg.hopf import adaptive_hopf_rhs, phase
from cpg_walker.cpg.network import CPGNetwork, CPGParams


def test_phase_convention_eq9():
    # θ = sgn(x)·arccos(−y/r)
    for x, y in [(1.0, 0.0), (0.3, -0.7), (-0.5, 0.2), (-0.1, -0.9)]:
        r = np.hypot(x, y)
        assert phase(x, y) == pytest.approx(np.sign(x) * np.arccos(-y / r))
    assert np.sin(phase(0.6, 0.8)) == pytest.approx(0.6)  # sin θ = x/r


def test_adaptive_hopf_rhs_eqs_1_to_3_hand_values():
    x, y, w, F = 0.6, 0.8, 10.0, 0.5  # r = 1
    dx, dy, dw = adaptive_hopf_rhs(x, y, w, F, gamma=8.0, mu=2.0, epsilon=0.9)
    assert dx == pytest.approx(8 * (2 - 1) * 0.6 - 10 * 0.8 + 0.9 * 0.5)
    assert dy == pytest.approx(8 * (2 - 1) * 0.8 + 10 * 0.6)
    assert dw == pytest.approx(-0.9 * 0.5 * 0.8)


def test_learning_rhs_eqs_4_to_11_hand_values():
    p = CPGParams(mu=1.0, gamma=8.0, epsilon=0.9, eta=0.5, tau=2.0)
    net = CPGNetwork(np.array([10.0, 20.0]), p, x0=[0.6, 0.0], y0=[0.8, 2.0], alpha0=[0.3, -0.2],
                     phi0=[0, 0.4])
    out = np.empty_like(net.state)
    P = 1.2
    net.learning_rhs(net.state, np.array([P]), out)
    x, y, w, a, ph = (np.array(v) for v in ([0.6, 0.0], [0.8, 2.0], [10.0, 20.0], [0.3, -0.2], [0.0, 0.4]))
    r = np.hypot(x, y)
    F = P - (a * x).sum()  # eqs 10-11
    theta = np.sign(x) * np.arccos(-y / r)
    theta[1] = np.arctan2(0.0, -2.0)  # x = 0: sgn(0)=0 in the printed form, atan2 gives π
    R1 = (w[1] / w[0]) * theta[0]
    dx = 8 * (1 - r**2) * x - w * y + 0.9 * F + np.array([0.0, 2.0 * np.sin(R1 - ph[1])])  # eq 4
    dy = 8 * (1 - r**2) * y + w * x  # eq 5
    dw = -0.9 * F * y / r  # eq 6
    da = 0.5 * x * F  # eq 7
    dph = np.array([0.0, np.sin(R1 - theta[1] - ph[1])])  # eq 8
    np.testing.assert_allclose(out[:, 0], np.stack([dx, dy, dw, da, dph]), rtol=1e-12, atol=1e-12)


def test_feedback_eqs_16_17_and_inter_cpg_eqs_12_13():
    net = CPGNetwork(np.array([[10.0], [10.0]]), CPGParams(tau=2.0), x0=[[1.0], [0.0]], y0=[[0.0], [1.0]],
                     phi0=[[0.0], [0.3]])
    net.couple_cpgs(child=1, parent=0)
    net._g = np.array([0.0, 0.7])
    out = np.empty_like(net.state)
    net.learning_rhs(net.state, np.zeros(2), out)
    th0, th1 = phase(1.0, 0.0), phase(0.0, 1.0)
    # CPG 1: ẋ = γ(μ−r²)x − ωy + εF + τ sin(θ_0 − φ) + g x/r,  F = 0 (α = 0, P = 0)
    assert out[0, 1, 0] == pytest.approx(-10.0 + 2.0 * np.sin(th0 - 0.3) + 0.0)
    assert out[1, 1, 0] == pytest.approx(0.7 * 1.0)  # ẏ: γ(μ−r²)y + ωx + g y/r with x = 0, r = 1
    assert out[4, 1, 0] == pytest.approx(np.sin(th0 - th1 - 0.3))  # eq 13
    assert out[4, 0, 0] == 0.0  # the root learns no phase


def test_fixed_coupling_link_keeps_phase_offset():
    """couple_cpgs(learn_phase=False): eq 12's term acts, eq 13 does not learn φ (it stays at the given
    offset); the same link with learn_phase=True moves φ towards the actual phase difference."""
    t = np.arange(0, 4.0, 0.002)
    P = np.stack([np.sin(15 * t), np.sin(15 * t - 1.0)], axis=1)  # CPG 1 lags CPG 0 by 1 rad

    def run(learn_phase: bool) -> tuple[CPGNetwork, np.ndarray]:
        net = CPGNetwork(np.array([[14.5], [14.5]]))
        net.couple_cpgs(child=1, parent=0, phase_offset=np.pi, learn_phase=learn_phase)
        out = np.empty_like(net.state)
        net.learning_rhs(net.state, np.zeros(2), out)
        for k in range(len(t) - 1):
            net.step(0.002, P[k])
        return net, out

    fixed, d_fixed = run(False)
    learned, d_learned = run(True)
    assert fixed.phi[1, 0] == np.pi  # exactly: not integrated at all
    assert d_fixed[4, 1, 0] == 0.0 and d_learned[4, 1, 0] != 0.0
    np.testing.assert_array_equal(d_fixed[:4], d_learned[:4])  # same eq 12 coupling term in ẋ
    assert abs(np.angle(np.exp(1j * (learned.phi[1, 0] - np.pi)))) > 0.5


def _learn_state(dt: float, T: float) -> np.ndarray:
    net = CPGNetwork(np.array([14.0, 29.0, 44.0, 58.0]))
    n = round(T / dt)
    t = np.arange(2 * n + 1) * dt / 2
    P = 0.8 * np.sin(15 * t) + np.cos(30 * t) - 1.4 * np.sin(45 * t) - 0.5 * np.cos(60 * t)
    for k in range(n):
        net.step(dt, P[2 * k : 2 * k + 3, None])
    return net.state.copy()


def test_step_size_independence():
    """Learning 20 s of Fig 2's signal at dt = 4 ms and 2 ms: every state variable agrees within 1e-2
    (measured max 3.8e-3, in φ_3; ω within 1.9e-3 rad/s, i.e. 0.003 % — the learning transient
    amplifies the integration error, so the bound is on the learned quantities, not 1e-6)."""
    a, b = _learn_state(0.004, 20.0), _learn_state(0.002, 20.0)
    assert np.max(np.abs(a - b)) < 1e-2
    assert np.max(np.abs(a[2] - b[2]) / b[2]) < 1e-4


def test_frozen_playback_modulation_continuity_and_backwards():
    net = CPGNetwork(np.array([15.0, 30.0]), alpha0=[0.8, 0.5], phi0=[0.0, 0.0])
    net.freeze()
    q = []
    for k in range(3000):
        if k == 1000:
            net.set_frequency_scale(0.5)
        if k == 2000:
            net.set_amplitude_scale(2.0)
        q.append(net.output()[0])
        net.step(0.001)
    jumps = np.abs(np.diff(q))
    assert jumps.max() < 0.1  # 30 rad/s · 1.3 · 1 ms ≈ 0.04 max per sample
    rev = CPGNetwork(np.array([15.0]), alpha0=1.0)
    rev.freeze()
    rev.set_frequency_scale(-1.0)
    th0 = rev.phases()[0, 0]
    for _ in range(100):
        rev.step(0.001)
    assert np.angle(np.exp(1j * (rev.phases()[0, 0] - th0))) == pytest.approx(-1.5, abs=0.01)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: CPGNetwork(np.zeros((2, 0))), "zero oscillators"),
        (lambda: CPGNetwork(np.array([1.0, np.nan])), "NaN"),
        (lambda: CPGNetwork(np.ones((2, 3)), x0=np.ones(4)), "does not fit"),
        (lambda: CPGNetwork(np.ones(3)).step(0.0, 1.0), "step"),
        (lambda: CPGNetwork(np.ones(3)).step(-1e-3, 1.0), "step"),
        (lambda: CPGNetwork(np.full(3, 50.0)).step(0.1, 1.0), "too large"),
        (lambda: CPGNetwork(np.ones(3)).step(1e-3, np.nan), "NaN"),
        (lambda: CPGNetwork(np.ones((2, 3))).step(1e-3, np.ones(3)), "shape"),
        (lambda: CPGNetwork(np.ones((2, 3))).step(1e-3, np.zeros(2), feedback=np.ones(5)), "feedback"),
        (lambda: CPGNetwork(np.ones(3)).set_frequency_scale(2.0), "freeze"),
    ],
)
def test_bad_input_raises_value_error(make, message):
    with pytest.raises(ValueError, match=message):
        make()


BACKENDS = ["numpy"] + (["numba"] if kernels.AVAILABLE else [])


@pytest.mark.parametrize("backend", BACKENDS)
def test_oscillator_at_r_zero_stays_finite(backend):
    """hopf.R_FLOOR in every division by r: an oscillator perturbed exactly to the origin (r = 0) gives
    ω̇ = −εF·y/r = 0 (not 0/0 = NaN) while learning, with and without feedback, and while frozen."""
    net = CPGNetwork(np.array([10.0, 20.0]), x0=[1.0, 0.0], y0=[0.0, 0.0], alpha0=[0.5, 0.5], backend=backend)
    out = np.empty_like(net.state)
    net.learning_rhs(net.state, np.array([1.0]), out)
    assert out[2, 0, 1] == 0.0
    net.step(1e-3, 1.0)
    net.step(1e-3, 1.0, feedback=0.3)
    assert np.all(np.isfinite(net.state))
    net.perturb(dx=[[0.0, -net.x[0, 1]]], dy=[[0.0, -net.y[0, 1]]])
    assert net.x[0, 1] == 0.0 and net.y[0, 1] == 0.0
    net.freeze()
    net.step(1e-3, feedback=0.3)
    assert np.all(np.isfinite(net.state))


def test_nonharmonic_flags_default_and_validation():
    net = CPGNetwork(np.array([[1.0, 2.5], [1.0, 3.0]]))
    assert not net.nonharmonic.any()  # default: the printed eq 8 everywhere
    net.set_nonharmonic([[False, True], [False, False]])
    assert net.nonharmonic.tolist() == [[False, True], [False, False]]
    with pytest.raises(ValueError, match="oscillator 0"):
        net.set_nonharmonic(True)
    with pytest.raises(ValueError, match="booleans"):
        CPGNetwork(np.array([1.0, 2.5]), nonharmonic=[0, 1])
    with pytest.raises(ValueError):
        net.set_nonharmonic([False, True, False])


def _frozen_pair_run(flag: bool, zeta: float, backend: str, dt: float = 0.002, T: float = 20.0,
                     zeta_later: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Frozen network ω = (10, 10√2), oscillator 1 flagged or not; returns θ_0, θ_1, φ_1 per step and ρ."""
    net = CPGNetwork(np.array([10.0, 10.0 * np.sqrt(2)]), alpha0=[1.0, 0.6], phi0=[0.0, 0.7],
                     nonharmonic=[False, flag], backend=backend)
    net.freeze()
    net.set_frequency_scale(zeta)
    n = round(T / dt)
    th = np.empty((n, 2))
    ph = np.empty(n)
    for k in range(n):
        if zeta_later is not None and k == n // 2:
            net.set_frequency_scale(zeta_later)  # rebuilds the playback coefficients from the state
        th[k] = net.phases()[0]
        ph[k] = net.phi[0, 1]
        net.step(dt)
    return th[:, 0], th[:, 1], ph, float(net.omega[0, 1] / net.omega[0, 0])


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * a))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("zeta", [1.0, -1.0])
def test_nonharmonic_reference_is_continuous_and_keeps_the_phase_relation(backend, zeta):
    """Eq 8 with ρ = √2 (network.py, "Non-harmonic oscillators"). Flagged: at every step
    ρ·θ_0 − φ_1 = ρ·(unwrapped θ_0) − φ_1(0) mod 2π (φ_1 absorbs each wrap, forwards and, with ζ < 0,
    backwards), and θ_1 stays locked to that target over 30 cycles. The printed eq 8 (not flagged):
    the target jumps at each wrap of θ_0 and the phase relation is lost."""
    th0, th1, ph, rho = _frozen_pair_run(True, zeta, backend)
    unwrapped = np.unwrap(th0)
    assert abs(unwrapped[-1] - unwrapped[0]) > 30 * 2 * np.pi  # many wraps, in the direction of ζ
    assert np.sign(unwrapped[-1] - unwrapped[0]) == np.sign(zeta)
    np.testing.assert_allclose(_wrap(rho * th0 - ph - (rho * unwrapped - ph[0])), 0.0, atol=1e-9)
    lag = _wrap(th1 - (rho * unwrapped - ph[0]))
    half = lag.size // 2
    assert np.ptp(lag[half:]) < 0.15  # locked (a small periodic wobble from the coupling itself)
    assert abs(lag[half:].mean() - lag[half // 2:half].mean()) < 0.01  # no drift
    th0, th1, ph, rho = _frozen_pair_run(False, zeta, backend)
    assert np.ptp(_wrap(th1 - (rho * np.unwrap(th0) - ph[0]))[half:]) > 0.5


def test_nonharmonic_correction_survives_modulation_and_frozen_phi():
    """Playback: φ is frozen but the correction still applies; a change of ζ (which rebuilds the playback
    coefficients from the state) mid-run keeps the target continuous and the lock."""
    th0, th1, ph, rho = _frozen_pair_run(True, 1.0, "numpy", zeta_later=-0.7)
    unwrapped = np.unwrap(th0)
    np.testing.assert_allclose(_wrap(rho * th0 - ph - (rho * unwrapped - ph[0])), 0.0, atol=1e-9)
    lag = _wrap(th1 - (rho * unwrapped - ph[0]))
    assert np.ptp(lag[3 * lag.size // 4:]) < 0.15


def test_nonharmonic_wrap_step_is_accurate():
    """The step in which θ_0 wraps is corrected to first order, so the wraps keep RK4's accuracy: frozen
    flagged network, 10 s at dt = 4 ms vs 0.5 ms, x and y agree within 1e-4 (measured 4e-6; without the
    stage correction 2e-3, the O(dt) error of one discontinuous step per cycle)."""

    def final(dt: float) -> np.ndarray:
        net = CPGNetwork(np.array([10.0, 10.0 * np.sqrt(2)]), alpha0=[1.0, 0.6], phi0=[0.0, 0.7],
                         nonharmonic=[False, True], backend="numpy")
        net.freeze()
        for _ in range(round(10.0 / dt)):
            net.step(dt)
        return net.state[:2, 0].copy()

    assert np.max(np.abs(final(0.004) - final(0.0005))) < 1e-4
