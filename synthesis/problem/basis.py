"""The paper's parameter basis M(ρ) = M0 + Σ ρi Mi1 + ½ Σ ρi² Mi2, in scaled ρ̂ ∈ [−1, 1]³.

The one place that says what the basis functions and their derivatives are: the synthesis LMIs
(:mod:`pressor.synthesis.families.theorem3`), the artifact reconstruction and the Lyapunov matrices of
both analysis LMIs (:mod:`pressor.synthesis.certificates`) all take them from :func:`basis_terms`.

Term order: the constant term, then ρ̂i for each parameter i, then ½ρ̂i² for each; the full basis of
the 3 model parameters has 7 terms ``[M0, M11, M21, M31, M12, M22, M32]``. A p-dependence keeps
the terms up to a degree ("constant" 1, "affine" adds ρ̂i, "quadratic" adds ½ρ̂i²), and the
analyses may keep the terms of only some parameters. The basis is evaluated at the scaled
parameters ρ̂ (see :mod:`pressor.synthesis.problem.scaling`), not the physical ones; this is a deviation
from the paper kept for conditioning (the same span of functions).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

N_BASIS = 7
BASIS_NAME = "M0 + sum_i rho_i Mi1 + 1/2 sum_i rho_i^2 Mi2 (rho scaled to [-1, 1])"
#: the p-dependences, at the index of their degree in ρ̂
P_DEPENDENCES = ("constant", "affine", "quadratic")


def term_parameters(p_dependence: str, params: Sequence[int]) -> tuple[int | None, ...]:
    """The parameter each basis term depends on, in the term order of :func:`basis_terms`.

    Parameters
    ----------
    p_dependence
        One of :data:`P_DEPENDENCES`.
    params
        Indices of the parameters the basis depends on.

    Returns
    -------
    tuple
        None for the constant term, then ``params`` once per degree above 0.

    Raises
    ------
    ValueError
        ``p_dependence`` not one of :data:`P_DEPENDENCES`.
    """
    return (None, *(i for i, _power in _non_constant_terms(p_dependence, params)))


def basis_terms(
    rho_hat: np.ndarray, p_dependence: str = "quadratic", params: Sequence[int] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Basis weights and their derivatives at scaled parameters.

    Parameters
    ----------
    rho_hat
        (G, s) scaled parameters (a single point may be given as (s,)).
    p_dependence
        One of :data:`P_DEPENDENCES`: the highest degree kept.
    params
        Indices of the parameters the basis depends on (default all s).

    Returns
    -------
    weights : numpy.ndarray
        (G, n_p): 1, then ρ̂i (affine and quadratic), then ½ρ̂i² (quadratic), for i in ``params``;
        the terms in the order of :func:`term_parameters`.
    derivatives : numpy.ndarray
        (G, n_p, s): entry [g, b, i] is ∂w_b/∂ρ̂_i at point g (1 for ρ̂i, ρ̂i for ½ρ̂i², else 0).

    Raises
    ------
    ValueError
        ``p_dependence`` not one of :data:`P_DEPENDENCES`.
    """
    r = np.atleast_2d(np.asarray(rho_hat, dtype=float))
    m, s = r.shape
    w, dw = [np.ones(m)], [np.zeros((m, s))]
    for i, power in _non_constant_terms(p_dependence, range(s) if params is None else params):
        d = np.zeros((m, s))
        d[:, i] = r[:, i] ** (power - 1)
        w.append(r[:, i] ** power / power)
        dw.append(d)
    return np.stack(w, axis=1), np.stack(dw, axis=1)


def _non_constant_terms(p_dependence: str, params: Sequence[int]) -> list[tuple[int, int]]:
    """(parameter, power) of every term after the constant one, in term order."""
    degree = P_DEPENDENCES.index(p_dependence)
    return [(i, power) for power in range(1, degree + 1) for i in params]


def basis_weights(rho_hat: np.ndarray) -> np.ndarray:
    """Weights of the full quadratic basis at scaled parameters.

    Parameters
    ----------
    rho_hat
        (G, 3) scaled parameters.

    Returns
    -------
    numpy.ndarray
        (G, 7) weights ``[1, ρ̂1, ρ̂2, ρ̂3, ½ρ̂1², ½ρ̂2², ½ρ̂3²]``.
    """
    return basis_terms(rho_hat)[0]


def basis_derivatives(rho_hat: np.ndarray) -> np.ndarray:
    """∂(weights)/∂ρ̂i of the full quadratic basis.

    Parameters
    ----------
    rho_hat
        (G, 3) scaled parameters.

    Returns
    -------
    numpy.ndarray
        (G, 3, 7): entry [g, i, b] is ∂w_b/∂ρ̂_i at point g.
    """
    # contiguous like the weights: the synthesis contracts it in einsum, whose summation order
    # (and so its last bits) may follow the memory layout
    return np.ascontiguousarray(np.swapaxes(basis_terms(rho_hat)[1], 1, 2))


def evaluate(coeffs: np.ndarray, rho_hat: np.ndarray) -> np.ndarray:
    """Evaluate M(ρ̂) from coefficients ``(7, r, c)`` (or ``(1, r, c)`` for a constant) -> (G, r, c)."""
    w = basis_weights(rho_hat)
    c = np.asarray(coeffs, dtype=float)
    if c.shape[0] == 1:
        return np.broadcast_to(c[0], (w.shape[0], *c.shape[1:])).copy()
    return np.einsum("gb,brc->grc", w, c)
