"""The paper's parameter basis M(ρ) = M0 + Σ ρi Mi1 + ½ Σ ρi² Mi2, in scaled ρ̂ ∈ [−1, 1]³.

Coefficient order (7 terms): ``[M0, M11, M21, M31, M12, M22, M32]``. The basis is evaluated at the
scaled parameters ρ̂ (see :mod:`synthesis.problem.scaling`), not the physical ones; this is a
deviation from the paper kept for conditioning (the same span of functions).
"""

from __future__ import annotations

import numpy as np

N_BASIS = 7
BASIS_NAME = "M0 + sum_i rho_i Mi1 + 1/2 sum_i rho_i^2 Mi2 (rho scaled to [-1, 1])"


def basis_weights(rho_hat: np.ndarray) -> np.ndarray:
    """Basis weights at scaled parameters.

    Parameters
    ----------
    rho_hat
        (G, 3) scaled parameters.

    Returns
    -------
    numpy.ndarray
        (G, 7) weights ``[1, ρ̂1, ρ̂2, ρ̂3, ½ρ̂1², ½ρ̂2², ½ρ̂3²]``.
    """
    r = np.atleast_2d(np.asarray(rho_hat, dtype=float))
    return np.concatenate([np.ones((r.shape[0], 1)), r, 0.5 * r**2], axis=1)


def basis_derivatives(rho_hat: np.ndarray) -> np.ndarray:
    """∂(weights)/∂ρ̂i.

    Returns
    -------
    numpy.ndarray
        (G, 3, 7): entry [g, i, b] is ∂w_b/∂ρ̂_i at point g.
    """
    r = np.atleast_2d(np.asarray(rho_hat, dtype=float))
    g = r.shape[0]
    d = np.zeros((g, 3, N_BASIS))
    for i in range(3):
        d[:, i, 1 + i] = 1.0
        d[:, i, 4 + i] = r[:, i]
    return d


def evaluate(coeffs: np.ndarray, rho_hat: np.ndarray) -> np.ndarray:
    """Evaluate M(ρ̂) from coefficients ``(7, r, c)`` (or ``(1, r, c)`` for a constant) -> (G, r, c)."""
    w = basis_weights(rho_hat)
    c = np.asarray(coeffs, dtype=float)
    if c.shape[0] == 1:
        return np.broadcast_to(c[0], (w.shape[0], *c.shape[1:])).copy()
    return np.einsum("gb,brc->grc", w, c)
