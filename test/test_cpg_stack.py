"""`stack_networks`: R networks stacked into one step exactly as each network stepped alone (the
vectorised robots-at-once CPG of the benchmark), learning and frozen, with coupling, ζ/α modulation,
feedback and non-harmonic flags, on both backends."""

from __future__ import annotations

import numpy as np
import pytest

from cpg_walker.cpg import kernels
from cpg_walker.cpg.network import CPGNetwork, CPGParams, stack_networks

BACKENDS = ["numpy", "numba"] if kernels.AVAILABLE else ["numpy"]


def _net(seed: int, backend: str, B: int = 4, N: int = 3) -> CPGNetwork:
    rng = np.random.default_rng(seed)
    w0 = rng.uniform(1.0, 3.0, (B, 1)) * np.arange(1, N + 1) * rng.uniform(0.95, 1.05, (B, N))
    flags = rng.uniform(size=(B, N)) < 0.3
    flags[:, 0] = False
    net = CPGNetwork(w0, CPGParams(), x0=rng.uniform(-1, 1, (B, N)), y0=rng.uniform(-1, 1, (B, N)),
                     alpha0=rng.uniform(-0.5, 0.5, (B, N)), time_scale=rng.uniform(0.5, 2.0, B),
                     offset=rng.uniform(-1, 1, B), gain=rng.uniform(0.5, 2.0, B), backend=backend,
                     nonharmonic=flags)
    net.couple_cpgs(1, 0)  # a learned chain link and a fixed antisymmetric pair (eqs 12–13)
    net.couple_cpgs(2, 3, 1.5, np.pi, learn_phase=False)
    net.couple_cpgs(3, 2, 1.5, np.pi, learn_phase=False)
    return net


def _teach(k: int, B: int, seed: int) -> np.ndarray:
    t = (k + np.array([0.0, 0.5, 1.0])) * 0.01
    return np.sin(2.0 * t[:, None] + np.arange(B) + seed)


@pytest.mark.parametrize("backend", BACKENDS)
def test_stacked_learning_equals_separate_networks(backend):
    nets = [_net(s, backend) for s in range(3)]
    stack = stack_networks([_net(s, backend) for s in range(3)])
    assert stack.B == 12 and stack.N == 3
    for k in range(200):
        teach = [_teach(k, 4, s) for s in range(3)]
        g = [np.full(4, 0.01 * (s + 1)) for s in range(3)]
        for net, p, gk in zip(nets, teach, g, strict=True):
            net.step(0.01, p, gk)
        stack.step(0.01, np.concatenate(teach, axis=1), np.concatenate(g))
    np.testing.assert_array_equal(stack.state, np.concatenate([n.state for n in nets], axis=1))
    np.testing.assert_array_equal(stack.output(), np.concatenate([n.output() for n in nets]))


@pytest.mark.parametrize("backend", BACKENDS)
def test_stacked_playback_equals_separate_networks(backend):
    def frozen(seed: int) -> CPGNetwork:
        net = _net(seed, backend)
        for k in range(50):
            net.step(0.01, _teach(k, 4, seed))
        net.freeze()
        net.set_frequency_scale(0.8 + 0.2 * seed)  # each robot at its own ζ
        return net

    nets = [frozen(s) for s in range(3)]
    stack = stack_networks([frozen(s) for s in range(3)])
    for _ in range(500):
        for net in nets:
            net.step(0.002)
        stack.step(0.002)
    np.testing.assert_array_equal(stack.state, np.concatenate([n.state for n in nets], axis=1))
    np.testing.assert_array_equal(stack.frequencies(), np.concatenate([n.frequencies() for n in nets]))


def test_stack_rejects_mismatched_networks():
    with pytest.raises(ValueError, match="at least one"):
        stack_networks([])
    with pytest.raises(ValueError, match="share N"):
        stack_networks([_net(0, "numpy", N=3), _net(1, "numpy", N=2)])
