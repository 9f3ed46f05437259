"""Constant state transforms of an analysis LMI (congruences: feasibility and gamma unchanged).

The default is a diagonal power-of-two balancing of the centre system (:func:`transform_of`); a
known Lyapunov matrix gives a whitening (:func:`whitening_transform`) and whitening followed by
balancing (:func:`conditioning_transform`, with the measurements that chose it), the transform
``pressor verify`` uses.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from pressor.synthesis.problem.closed_loop import DelaySystem

__all__ = ["conditioning_transform", "transform_of", "whitening_transform"]

Array = NDArray[np.float64]


def _balance(a: Array, ad: Array, time_scale_s: float) -> Array:
    """Diagonal state scaling (powers of two) balancing ``|ts A| + |ts Ad|``."""
    mag = time_scale_s * (np.abs(a) + np.abs(ad)) + 1e-12 * np.eye(a.shape[0])
    _, (scale, _perm) = scipy.linalg.matrix_balance(mag, permute=False, separate=True)
    return np.asarray(scale, dtype=float)


def transform_of(
    systems: Sequence[DelaySystem], time_scale_s: float, state_transform: Array | None
) -> tuple[Array, Array]:
    """The constant state transform (and its inverse): given, or the centre system's balancing."""
    n = systems[0].n
    if state_transform is None:
        mid = systems[len(systems) // 2]  # the centre system
        tx = np.diag(_balance(mid.A, mid.Ad, time_scale_s))
    else:
        tx = np.asarray(state_transform, dtype=float)
        if tx.shape != (n, n) or not np.all(np.isfinite(tx)) or np.linalg.cond(tx) > 1e12:
            raise ValueError(f"state_transform must be a finite, invertible {n}x{n} matrix")
    return tx, np.linalg.inv(tx)


def whitening_transform(p_phys: Array) -> Array:
    """``T = P^(-1/2)`` (symmetric), so that ``T' P T = I``: the state coordinates in which a
    known Lyapunov matrix P is the identity (well-conditioned starting point for the solver).

    Parameters
    ----------
    p_phys
        Symmetric positive definite n x n matrix (e.g. :attr:`AnalysisResult.p0_phys`).
    """
    p = 0.5 * (np.asarray(p_phys, dtype=float) + np.asarray(p_phys, dtype=float).T)
    w, v = np.linalg.eigh(p)
    if not np.all(np.isfinite(w)) or w[0] <= 0:
        raise ValueError("whitening_transform needs a positive definite matrix")
    return (v / np.sqrt(w)) @ v.T


def conditioning_transform(p_phys: Array, system: DelaySystem, time_scale_s: float) -> Array:
    """Whitening by a known Lyapunov matrix, then a diagonal power-of-two balancing of the system.

    ``T = P^(-1/2) D`` with D from ``scipy.linalg.matrix_balance`` of ``|ts T0^-1 A T0| +
    |ts T0^-1 Ad T0|`` (T0 = P^(-1/2)). Whitening and balancing are both needed: on the shipped
    design either alone fails (docs/notes/benchmarks.md, "Design measurements").

    Parameters
    ----------
    p_phys
        Lyapunov matrix of a representative point (e.g. the centre), original coordinates.
    system
        The closed loop at that point.
    time_scale_s
        Time unit of the scaled problem (s).
    """
    t0 = whitening_transform(p_phys)
    t0i = np.linalg.inv(t0)
    return t0 @ np.diag(_balance(t0i @ system.A @ t0, t0i @ system.Ad @ t0, time_scale_s))
