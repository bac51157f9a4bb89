"""Optional numba backend: one whole RK4 step of `CPGNetwork` (learning and playback) as compiled loops.

The equations are exactly those of `CPGNetwork.learning_rhs` and `CPGNetwork.playback_rhs`
(network.py), which stay the reference and the place where each equation is documented: the kernels
evaluate the same expressions in the same order, element by element, and combine the RK4 stages as
`integrators.RK4.step` does. They exist because numpy's per-call overhead (~80 calls of ~0.5 µs per
step) dominates at the network's size. The state, buffers and coefficients are the network's own arrays.

numba caches compiled code on disk (`cache=True`). If NUMBA_CACHE_DIR is unset when this module is
imported (and numba is not imported yet) it is set to $XDG_CACHE_HOME/cpg_walker/numba (default
~/.cache/cpg_walker/numba), so the cache also works when the package directory is read-only.
`AVAILABLE` is False if numba is not installed; the network then uses numpy.
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numpy as np

from cpg_walker.cpg.hopf import R_FLOOR


def default_cache_dir() -> Path:
    """Where the compiled kernels are cached unless NUMBA_CACHE_DIR says otherwise."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "cpg_walker" / "numba"


if "numba" not in sys.modules and "NUMBA_CACHE_DIR" not in os.environ:
    os.environ["NUMBA_CACHE_DIR"] = str(default_cache_dir())

try:
    from numba import njit
except ImportError:  # optional dependency: the network falls back to numpy
    njit = None

#: True if numba is importable (the kernels are compiled); False: plain-Python stand-ins, not used.
AVAILABLE = njit is not None


def _jit(fn):
    return njit(cache=True, error_model="numpy")(fn) if njit is not None else fn


@_jit
def _learning_rhs(s, Pn, ref, ref_omega, k, learn_phi, ts, scaled, g, has_g, consts, theta, F, out):
    """`CPGNetwork.learning_rhs` (eqs 4–11, 12–13, 16–17) on flat (5, B·N) arrays; see there."""
    eps, gamma, gmu, eta = consts[0], consts[1], consts[2], consts[3]
    M = s.shape[1]
    B = F.shape[0]
    N = M // B
    for b in range(B):
        acc = 0.0
        for j in range(N):
            i = b * N + j
            acc += s[3, i] * s[0, i]
        F[b] = Pn[b] - acc  # (10), (11)
    for i in range(M):
        theta[i] = math.atan2(s[0, i], -s[1, i])  # (9)
    for i in range(M):
        b = i // N
        x = s[0, i]
        y = s[1, i]
        om = s[2, i]
        eF = eps * F[b]
        r2 = x * x + y * y
        radial = gmu - gamma * r2
        target = om / s[2, ref_omega[i]]
        target *= theta[ref[i]]
        target -= s[4, i]
        dx = x * radial
        dx -= om * y
        dx += eF
        dx += k[i] * math.sin(target)  # (4) [(12)]
        dy = y * radial
        dy += om * x  # (5)
        r = max(math.sqrt(r2), R_FLOOR)  # hopf.R_FLOOR: r = 0 gives 0, not NaN
        dom = y / r
        dom *= -eF  # (6)
        dal = x * (eta * F[b])  # (7)
        dph = math.sin(target - theta[i]) * learn_phi[i]  # (8) [(13)]
        if has_g:  # (16), (17)
            c = g[b] / r
            dx += x * c
            dy += y * c
        if scaled:
            h = ts[b]
            dx *= h
            dy *= h
            dom *= h
            dal *= h
            dph *= h
        out[0, i] = dx
        out[1, i] = dy
        out[2, i] = dom
        out[3, i] = dal
        out[4, i] = dph


@_jit
def _playback_rhs(s, ref, rho, phi, om, k, gamma, gmu, gts, has_g, theta, out):
    """`CPGNetwork.playback_rhs` (eqs 4, 5, 12, 16, 17 with ζ·ω, time scale folded in); see there."""
    M = s.shape[1]
    B = gamma.shape[0]
    N = M // B
    for i in range(M):
        theta[i] = math.atan2(s[0, i], -s[1, i])  # (9)
    for i in range(M):
        b = i // N
        x = s[0, i]
        y = s[1, i]
        r2 = x * x + y * y
        radial = gmu[b] - gamma[b] * r2
        target = theta[ref[i]] * rho[i]
        target -= phi[i]
        dx = x * radial
        dx -= om[i] * y
        dx += k[i] * math.sin(target)  # (4)/(12)
        dy = y * radial
        dy += om[i] * x  # (5)
        if has_g:  # (16), (17)
            c = gts[b] / max(math.sqrt(r2), R_FLOOR)
            dx += x * c
            dy += y * c
        out[0, i] = dx
        out[1, i] = dy


@_jit
def _combine(s, k1, k2, k3, k4, h, rows):
    """RK4's final combination, in the operation order of `integrators.RK4.step`."""
    h6 = h / 6.0
    for c in range(rows):
        for i in range(s.shape[1]):
            s[c, i] += (k1[c, i] + (k2[c, i] + k3[c, i]) * 2.0 + k4[c, i]) * h6


@_jit
def _stage(s, kk, f, tmp, rows):
    for c in range(rows):
        for i in range(s.shape[1]):
            tmp[c, i] = kk[c, i] * f + s[c, i]


@_jit
def learning_step(
    s3, h, P0, Pm, P1, ref2, ref_omega2, k2d, learn_phi2, ts, scaled, g, has_g, consts, work
):
    """One RK4 step of the learning network, in place on `s3` (5, B, N): see `CPGNetwork.step`.

    P0, Pm, P1: normalised teaching input at t, t + h/2, t + h, (B,). `work`: scratch (5, 5, B, N) for
    k1..k4 and the stage state."""
    B, N = s3.shape[1], s3.shape[2]
    M = B * N
    s = s3.reshape(5, M)
    ref = ref2.reshape(M)
    refo = ref_omega2.reshape(M)
    k = k2d.reshape(M)
    lp = learn_phi2.reshape(M)
    k1 = work[0].reshape(5, M)
    k2 = work[1].reshape(5, M)
    k3 = work[2].reshape(5, M)
    k4 = work[3].reshape(5, M)
    tmp = work[4].reshape(5, M)
    theta = np.empty(M)
    F = np.empty(B)
    half = h * 0.5
    _learning_rhs(s, P0, ref, refo, k, lp, ts, scaled, g, has_g, consts, theta, F, k1)
    _stage(s, k1, half, tmp, 5)
    _learning_rhs(tmp, Pm, ref, refo, k, lp, ts, scaled, g, has_g, consts, theta, F, k2)
    _stage(s, k2, half, tmp, 5)
    _learning_rhs(tmp, Pm, ref, refo, k, lp, ts, scaled, g, has_g, consts, theta, F, k3)
    _stage(s, k3, h, tmp, 5)
    _learning_rhs(tmp, P1, ref, refo, k, lp, ts, scaled, g, has_g, consts, theta, F, k4)
    _combine(s, k1, k2, k3, k4, h, 5)


@_jit
def playback_step(s3, h, ref2, rho2, phi2, om2, k2d, gamma, gmu, gts, has_g, work):
    """One RK4 step of the frozen network's x, y (rows 0, 1 of `s3`), in place: see `CPGNetwork.step`."""
    B, N = s3.shape[1], s3.shape[2]
    M = B * N
    s = s3.reshape(5, M)
    ref = ref2.reshape(M)
    rho = rho2.reshape(M)
    phi = phi2.reshape(M)
    om = om2.reshape(M)
    k = k2d.reshape(M)
    k1 = work[0].reshape(5, M)
    k2 = work[1].reshape(5, M)
    k3 = work[2].reshape(5, M)
    k4 = work[3].reshape(5, M)
    tmp = work[4].reshape(5, M)
    theta = np.empty(M)
    half = h * 0.5
    _playback_rhs(s, ref, rho, phi, om, k, gamma, gmu, gts, has_g, theta, k1)
    _stage(s, k1, half, tmp, 2)
    _playback_rhs(tmp, ref, rho, phi, om, k, gamma, gmu, gts, has_g, theta, k2)
    _stage(s, k2, half, tmp, 2)
    _playback_rhs(tmp, ref, rho, phi, om, k, gamma, gmu, gts, has_g, theta, k3)
    _stage(s, k3, h, tmp, 2)
    _playback_rhs(tmp, ref, rho, phi, om, k, gamma, gmu, gts, has_g, theta, k4)
    _combine(s, k1, k2, k3, k4, h, 2)


@_jit
def playback_derivative(s3, ref2, rho2, phi2, om2, k2d, gamma, gmu, gts, has_g, out3):
    """d[x, y]/dt of the frozen network at `s3` into `out3` (2, B, N): `CPGNetwork.playback_rhs`."""
    B, N = s3.shape[1], s3.shape[2]
    M = B * N
    theta = np.empty(M)
    _playback_rhs(s3.reshape(5, M), ref2.reshape(M), rho2.reshape(M), phi2.reshape(M), om2.reshape(M),
                  k2d.reshape(M), gamma, gmu, gts, has_g, theta, out3.reshape(2, M))


@_jit
def playback_forecast(s3, hs, nsub, oms, ref2, rho2, phi2, k2d, gamma, gmu, gts, has_g, work, xs, dxs):
    """`CPGNetwork.forecast` in one call: for each point p, `nsub[p]` RK4 steps of `hs[p]` of the frozen
    network's x, y with the ζ·ω coefficients `oms[p]` (B, N), in place on the copy `s3`, then x into
    `xs[p]` and dx/dt into `dxs[p]` (each (B, N)) — `playback_step` and `playback_derivative` in a loop."""
    B, N = s3.shape[1], s3.shape[2]
    der = np.empty((2, B, N))
    for p in range(hs.shape[0]):
        for _ in range(nsub[p]):
            playback_step(s3, hs[p], ref2, rho2, phi2, oms[p], k2d, gamma, gmu, gts, has_g, work)
        playback_derivative(s3, ref2, rho2, phi2, oms[p], k2d, gamma, gmu, gts, has_g, der)
        xs[p] = s3[0]
        dxs[p] = der[0]
