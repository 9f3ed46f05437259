"""Rightmost characteristic roots of a linear system with one constant (frozen) delay.

For ``dx/dt = A x(t) + Ad x(t - tau)`` (any consistent time unit; the roots come out in 1/that
unit) the characteristic roots are the zeros of ``det(s I - A - Ad exp(-s tau))``. The system is
exponentially stable iff every root has a negative real part (the spectral abscissa is < 0).

Method (Breda, Maset & Vermiglio, SIAM J. Sci. Comput. 27(2), 2005):

1. Discretise the infinitesimal generator of the solution semigroup on the history interval
   [-tau, 0] with a Chebyshev pseudospectral collocation of degree N: the history is represented by
   its values at the N+1 Chebyshev-Lobatto nodes; the rows for the interior/left nodes apply the
   Chebyshev differentiation matrix, the row for theta = 0 applies the right-hand side
   ``A x(0) + Ad x(-tau)``. The eigenvalues of this n(N+1) matrix approximate the rightmost
   characteristic roots with spectral accuracy.
2. Refine the rightmost approximations with Newton's method on ``f(s) = det M(s)``,
   ``M(s) = s I - A - Ad exp(-s tau)``, using ``f'/f = trace(M^{-1} M'(s))`` with
   ``M'(s) = I + tau Ad exp(-s tau)``; a refined root is accepted only if it stays close to its
   seed (otherwise the seed is kept, flagged unrefined).

This module takes plain matrices; it knows nothing about the MAP model or the artifact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DelayRoots",
    "chebyshev_differentiation",
    "characteristic_matrix",
    "refine_root",
    "rightmost_roots",
    "spectral_abscissa",
]


@dataclass(frozen=True)
class DelayRoots:
    """Rightmost characteristic roots of a frozen delay system.

    Attributes
    ----------
    roots
        Complex roots sorted by decreasing real part (1/time unit of A).
    residuals
        ``|det M(s)| / (1 + |s|)^n`` at each root after refinement (scale-free check).
    refined
        Whether Newton converged for each root (False: the spectral estimate is kept).
    """

    roots: NDArray[np.complex128]
    residuals: NDArray[np.float64]
    refined: NDArray[np.bool_]

    @property
    def abscissa(self) -> float:
        """Largest real part among the roots (the spectral abscissa estimate)."""
        return float(np.max(self.roots.real))


def chebyshev_differentiation(degree: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Chebyshev-Lobatto nodes x_j = cos(j pi / N) on [-1, 1] and the differentiation matrix.

    Parameters
    ----------
    degree
        Polynomial degree N >= 1 (N + 1 nodes).

    Returns
    -------
    nodes, D
        ``nodes[0] = 1`` ... ``nodes[N] = -1``; ``D @ p(nodes) = p'(nodes)`` for polynomials of
        degree <= N (Trefethen, *Spectral Methods in MATLAB*, cheb.m).
    """
    if degree < 1:
        raise ValueError(f"degree={degree!r} must be >= 1")
    j = np.arange(degree + 1)
    nodes = np.cos(np.pi * j / degree)
    c = np.ones(degree + 1)
    c[0] = c[-1] = 2.0
    c *= (-1.0) ** j
    dx = nodes[:, None] - nodes[None, :]
    d = np.outer(c, 1.0 / c) / (dx + np.eye(degree + 1))
    d -= np.diag(d.sum(axis=1))
    return nodes, d


def characteristic_matrix(
    s: complex, a: NDArray[np.float64], ad: NDArray[np.float64], tau: float
) -> NDArray[np.complex128]:
    """``M(s) = s I - A - Ad exp(-s tau)``."""
    n = a.shape[0]
    return s * np.eye(n) - a - ad * np.exp(-s * tau)


def refine_root(
    seed: complex,
    a: NDArray[np.float64],
    ad: NDArray[np.float64],
    tau: float,
    max_iter: int = 30,
    tol: float = 1e-12,
) -> tuple[complex, bool]:
    """Newton's method on ``det M(s)`` started at ``seed``.

    Returns
    -------
    root, converged
        ``converged`` is False when M becomes singular to machine precision at a point that is
        not a root, the iteration diverges, or it does not settle within ``max_iter`` steps.
    """
    n = a.shape[0]
    s = complex(seed)
    eye = np.eye(n)
    for _ in range(max_iter):
        e = np.exp(-s * tau)
        m = s * eye - a - ad * e
        dm = eye + tau * ad * e
        try:
            ratio = np.trace(np.linalg.solve(m, dm))
        except np.linalg.LinAlgError:
            return s, True  # M exactly singular: s is a root
        if ratio == 0 or not np.isfinite(ratio):
            return s, False
        step = 1.0 / ratio
        s -= step
        if abs(step) <= tol * max(1.0, abs(s)):
            return s, True
    return s, False


def _residual(s: complex, a: NDArray[np.float64], ad: NDArray[np.float64], tau: float) -> float:
    n = a.shape[0]
    m = characteristic_matrix(s, a, ad, tau)
    # smallest singular value relative to the size of M: scale-free "is M(s) singular" measure
    sv = np.linalg.svd(m, compute_uv=False)
    return float(sv[-1] / max(1.0, sv[0])) if n else 0.0


def rightmost_roots(
    a: NDArray[np.float64],
    ad: NDArray[np.float64],
    tau: float,
    count: int = 6,
    degree: int | None = None,
) -> DelayRoots:
    """Approximate and refine the ``count`` rightmost roots of ``det(sI - A - Ad e^{-s tau})``.

    Parameters
    ----------
    a, ad
        n x n real matrices (1/time unit).
    tau
        The delay (same time unit), >= 0. ``tau == 0`` gives the eigenvalues of A + Ad.
    count
        How many rightmost roots to return (>= 1).
    degree
        Chebyshev degree N of the discretisation; default ``ceil(3 |Ad| tau) + 10`` (spectral
        norm) clipped to [20, 40]. The delayed coupling sets how oscillatory the rightmost
        roots are; |A| is left out on purpose: a fast, well-damped mode of A (e.g. a controller
        pole at -70 1/s) lies far left and needs no resolution, and counting it made the
        discretisation several times larger for nothing. Newton polishes the survivors.

    Returns
    -------
    DelayRoots
        Roots sorted by decreasing real part.
    """
    a = np.atleast_2d(np.asarray(a, dtype=float))
    ad = np.atleast_2d(np.asarray(ad, dtype=float))
    n = a.shape[0]
    if a.shape != (n, n) or ad.shape != (n, n):
        raise ValueError(f"A {a.shape} and Ad {ad.shape} must both be square of the same size")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(ad))):
        raise ValueError("A and Ad must be finite")
    if not (np.isfinite(tau) and tau >= 0.0):
        raise ValueError(f"tau={tau!r} must be finite and >= 0")
    if count < 1:
        raise ValueError(f"count={count!r} must be >= 1")
    if tau == 0.0:
        eig = np.linalg.eigvals(a + ad).astype(complex)
        order = np.argsort(-eig.real, kind="stable")[:count]
        roots = eig[order]
        return DelayRoots(roots, np.zeros(len(roots)), np.ones(len(roots), dtype=bool))
    if degree is None:
        scale = float(np.linalg.norm(ad, 2))
        degree = int(min(40, max(20, np.ceil(3.0 * scale * tau) + 10)))
    nodes, d = chebyshev_differentiation(degree)
    d = d * (2.0 / tau)  # theta = tau (x - 1) / 2 maps [-1, 1] onto [-tau, 0]
    size = n * (degree + 1)
    gen = np.kron(d, np.eye(n))
    gen[:n, :] = 0.0
    gen[:n, :n] = a  # theta = 0 node (x_0 = 1)
    gen[:n, size - n :] += ad  # theta = -tau node (x_N = -1)
    eig = np.linalg.eigvals(gen)
    eig = eig[np.isfinite(eig)]
    order = np.argsort(-eig.real, kind="stable")
    # take extra seeds: the discretisation can misplace a few spurious roots far left only
    seeds = eig[order[: min(len(order), 2 * count + 4)]]
    roots: list[complex] = []
    refined: list[bool] = []
    for seed in seeds:
        root, ok = refine_root(seed, a, ad, tau)
        if not ok or abs(root - seed) > 1e-2 * (1.0 + abs(seed)):
            root, ok = seed, False
        if any(abs(root - r) <= 1e-8 * (1.0 + abs(r)) for r in roots):
            continue  # two seeds converged to the same root
        roots.append(root)
        refined.append(ok)
    arr = np.array(roots, dtype=complex)
    order2 = np.argsort(-arr.real, kind="stable")[:count]
    arr = arr[order2]
    res = np.array([_residual(s, a, ad, tau) for s in arr])
    return DelayRoots(arr, res, np.array(refined, dtype=bool)[order2])


def spectral_abscissa(
    a: NDArray[np.float64], ad: NDArray[np.float64], tau: float, degree: int | None = None
) -> float:
    """Largest real part of the characteristic roots (< 0 means exponentially stable)."""
    return rightmost_roots(a, ad, tau, count=1, degree=degree).abscissa
