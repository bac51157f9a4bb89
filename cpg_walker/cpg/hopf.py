"""The adaptive-frequency Hopf oscillator (paper eqs 1–3) and its phase (eq 9).

Everything here is elementwise numpy, so `x`, `y`, `omega` may be scalars or arrays of any one shape
(the network uses (B, N): B CPGs of N oscillators).

Phase convention (eq 9, our reading): θ = sgn(x)·arccos(−y/r). Writing the oscillator as
x = r·cos ψ, y = r·sin ψ (ψ = atan2(y, x), which increases at rate ω for ω > 0), one gets
θ = ψ + π/2 wrapped to (−π, π], i.e. θ = atan2(x, −y) — the form used here (one call, no division,
defined for r = 0). Its useful meaning: sin θ = x/r and cos θ = −y/r. So a forcing `τ·sin(Θ*)` added
to ẋ is a unit-amplitude copy of the x-signal an oscillator would have at phase Θ*; averaged over a
cycle it pulls ψ towards Θ* − π/2, i.e. θ towards Θ* (Kuramoto-like locking, see network.py).
"""

from __future__ import annotations

import numpy as np

#: Floor on r in every division by r (y/r, x/r; here, network.py and kernels.py): r = 0 only if a user
#: perturbs an oscillator exactly to the origin; the terms then vanish instead of producing NaN.
R_FLOOR = 1e-12


def phase(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Eq 9: θ = sgn(x)·arccos(−y/r), computed as atan2(x, −y) ∈ (−π, π] (identical for r > 0)."""
    return np.arctan2(x, -y)


def adaptive_hopf_rhs(
    x: np.ndarray,
    y: np.ndarray,
    omega: np.ndarray,
    F: np.ndarray | float,
    *,
    gamma: float,
    mu: float | np.ndarray,
    epsilon: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Right-hand side of eqs 1–3 for the adaptive-frequency Hopf oscillator driven by input F(t).

    ẋ = γ(μ − r²)x − ωy + εF          (1)
    ẏ = γ(μ − r²)y + ωx               (2)
    ω̇ = −εF·y/r                       (3)
    """
    r2 = x * x + y * y
    radial = gamma * (mu - r2)
    eF = epsilon * F
    dx = radial * x - omega * y + eF  # (1)
    dy = radial * y + omega * x  # (2)
    domega = -eF * y / np.maximum(np.sqrt(r2), R_FLOOR)  # (3)
    return dx, dy, domega
