"""The numba backend (kernels.py) against the numpy reference (CPGNetwork.learning_rhs/playback_rhs +
integrators.RK4): same state after many steps, for random networks with every feature switched on
(including non-harmonic oscillators, whose eq 8 wrap correction both backends share)."""

from __future__ import annotations

import numpy as np
import pytest

from cpg_walker.cpg import kernels
from cpg_walker.cpg.network import CPGNetwork, CPGParams

pytestmark = pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed (optional backend)")

#: Both backends evaluate the same expressions in the same order; they differ only by the last-bit
#: rounding of sin/atan2 (numpy's vs libm's), which the dynamics carry along but do not amplify much.
TOL = 1e-12


def _pair(seed: int, B: int, N: int) -> tuple[CPGNetwork, CPGNetwork, np.random.Generator]:
    rng = np.random.default_rng(seed)
    base = rng.uniform(1.0, 3.0, (B, 1))
    w0 = base * np.arange(1, N + 1) * rng.uniform(0.9, 1.1, (B, N))
    kw = dict(
        x0=rng.uniform(-1, 1, (B, N)), y0=rng.uniform(-1, 1, (B, N)), alpha0=rng.uniform(-0.5, 0.5, (B, N)),
        phi0=rng.uniform(-np.pi, np.pi, (B, N)), time_scale=rng.uniform(0.5, 3.0, B),
        offset=rng.uniform(-1, 1, B), gain=rng.uniform(0.5, 2.0, B),
    )
    params = CPGParams(gamma=rng.uniform(4, 10), epsilon=rng.uniform(0.5, 1.0), eta=rng.uniform(0.2, 0.8),
                       tau=rng.uniform(1, 3), amplitude_time_constant=0.05)
    # eq 8's wrap correction (runs after each step, for both backends) on about half the oscillators i >= 1
    flags = np.random.default_rng(seed + 100).uniform(size=(B, N)) < 0.5
    flags[:, 0] = False
    nets = [CPGNetwork(w0, params, backend=be, nonharmonic=flags, **kw) for be in ("numpy", "numba")]
    if B > 1:  # a learned chain link and a fixed antisymmetric pair (eqs 12–13, learn_phase=False)
        links = [(1, 0, None, None, True)]
        if B > 2:
            links += [(2, B - 1, 1.5, np.pi, False), (B - 1, 2, 1.5, np.pi, False)]
        for net in nets:
            for child, parent, k, off, learn in links:
                net.couple_cpgs(child, parent, k, off, learn_phase=learn)
    assert not nets[0].uses_numba and nets[1].uses_numba
    return nets[0], nets[1], rng


@pytest.mark.parametrize("seed,B,N", [(0, 1, 1), (1, 1, 4), (2, 2, 3), (3, 10, 3), (4, 5, 7)])
def test_numba_step_equals_numpy_step(seed: int, B: int, N: int) -> None:
    ref, fast, rng = _pair(seed, B, N)
    dt = 0.2 / np.max(ref.time_scale[:, None] * np.maximum(ref.omega, 2 * ref.params.gamma))
    g = rng.uniform(-0.5, 0.5, B)
    # random periodic teaching signals near each CPG's frequencies (white noise would drive ω_0 through 0,
    # where ρ = ω_i/ω_0 is singular and any rounding difference, numpy vs numpy, is amplified without bound)
    amp, ph = rng.uniform(0.2, 1.0, (B, 3)), rng.uniform(-np.pi, np.pi, (B, 3))
    w = (ref.omega[:, :1] * ref.time_scale[:, None]) * np.arange(1, 4) * rng.uniform(0.9, 1.1, (B, 1))
    for k in range(1500):  # learning: teaching held or sampled at the RK4 times, with and without feedback
        t = k * dt + np.array([0.0, dt / 2, dt])[:, None, None]
        P = (amp * np.sin(w * t + ph)).sum(-1) * ref.gain + ref.offset
        teach = P[0] if k % 3 == 0 else P
        fb = g if k % 2 else None
        ref.step(dt, teach, feedback=fb)
        fast.step(dt, teach, feedback=fb)
    np.testing.assert_allclose(fast.state, ref.state, rtol=0, atol=TOL * (1 + np.max(np.abs(ref.state))))
    assert not np.array_equal(ref.omega, _pair(seed, B, N)[0].omega)  # learning did change ω
    for net in (ref, fast):  # frozen: ζ < 0 (backwards), amplitude relaxation, feedback
        net.freeze()
        net.set_frequency_scale(rng.uniform(-1.5, -0.5, B) if net is ref else ref._zeta)
        net.set_amplitude_scale(0.7)
    for k in range(1500):
        fb = g if k % 2 else None
        ref.step(dt, feedback=fb)
        fast.step(dt, feedback=fb)
    np.testing.assert_allclose(fast.state, ref.state, rtol=0, atol=TOL * (1 + np.max(np.abs(ref.state))))
    Q = ref.output()
    np.testing.assert_allclose(fast.output(), Q, rtol=0, atol=TOL * (1 + np.max(np.abs(Q))))


@pytest.mark.parametrize("seed,B,N", [(5, 1, 1), (6, 10, 3), (7, 4, 6)])
def test_playback_derivative_equals_playback_rhs(seed: int, B: int, N: int) -> None:
    """The frozen network's d[x, y]/dt (joint velocities of the controller) by the kernel and in numpy."""
    ref, fast, rng = _pair(seed, B, N)
    for net in (ref, fast):
        net.freeze()
    zeta = rng.uniform(-1.5, 1.5, B)
    g = rng.uniform(-0.5, 0.5, B)
    for fb in (None, g):
        for net in (ref, fast):
            net.set_frequency_scale(zeta)
            net.step(1e-3, feedback=fb)  # the derivative includes the feedback held over the last step
        fast.state[:] = ref.state
        expected = np.empty((2, B, N))
        ref.playback_rhs(ref.state[:2], None, expected)
        got = np.empty((2, B, N))
        fast.playback_derivative(got)
        np.testing.assert_allclose(got, expected, rtol=0, atol=TOL * (1 + np.max(np.abs(expected))))
        numpy_path = np.empty((2, B, N))
        ref.playback_derivative(numpy_path)
        assert numpy_path.tobytes() == expected.tobytes()


def test_backend_selection(monkeypatch: pytest.MonkeyPatch) -> None:
    w0 = np.array([1.0, 2.0])
    monkeypatch.setenv("CPG_WALKER_BACKEND", "numpy")
    assert not CPGNetwork(w0).uses_numba
    monkeypatch.setenv("CPG_WALKER_BACKEND", "numba")
    assert CPGNetwork(w0).uses_numba
    monkeypatch.delenv("CPG_WALKER_BACKEND")
    net = CPGNetwork(w0)
    assert net.backend == "auto" and net.uses_numba
    net.backend = "numpy"
    assert not net.uses_numba
    with pytest.raises(ValueError, match="backend"):
        CPGNetwork(w0, backend="fortran")
