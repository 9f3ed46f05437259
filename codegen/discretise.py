"""Exact sampled-data (ZOH) discretisation of the delayed controller, input filter and integrator.

The synthesis controller (``pressor.synthesis.problem.reconstruct.controller_at``, physical units, time in
s) is::

    dx_k/dt = Ak x_k + Adk x_k(t - tau) + Bk y,      y = [e_mmhg, x_e_mmhg_s]
    u_a     = Ck x_k + Cdk x_k(t - tau) + Dk y
    du/dt   = -Lambda u + Omega u_a                  (u: infusion command, ml/h)
    dx_e/dt = e                                      (x_e: mmHg*s)

At every tabulation node it is folded into one composite system with state
``z = [x_k (n_k), u, x_e]`` and input ``v = [x_d (n_k), e]`` where ``x_d = x_k(t - tau)``::

    dz/dt = Ac z + Bc v

and discretised exactly for inputs held over a sample (ZOH, period Ts). The result is stored in the
*increment* (delta-operator) realisation::

    z[k+1] = z[k] + M @ [z[k]; v[k]],     M = [Phi - I, Gamma] = Ts * [A_delta, B_delta]

Storing ``Phi - I`` instead of the near-identity ``Phi = exp(Ac Ts)`` keeps the small per-sample
increments representable in fixed point: at Ts = 0.1 s the diagonal of Phi is 1 - O(1e-2..1e-5),
which a Q15 (or even Q31) coefficient would round to 1 and lose the slow dynamics entirely.

Every node uses the same state coordinates (the artifact's reconstruction shares them across the
box; this module never transforms a node on its own), so the tables can be interpolated entrywise.

Deviations from the continuous controller (the documented discretisation error):

* ``e`` is sampled and held (ZOH) — exact for the sampled loop the runtime actually runs;
* ``x_d`` is held over the sample at its value at t_k - tau (read from a ring buffer of past x_k,
  linearly interpolated for fractional delays); the continuous controller sees it vary within the
  sample, an O(Ts * |dx_k/dt|) difference;
* the x_e row is exact (a ramp under ZOH ``e``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import expm

__all__ = [
    "ContinuousController",
    "DelayedControllerMatrices",
    "composite_continuous",
    "discretise_node",
]

Matrix = NDArray[np.float64]


class ContinuousController(Protocol):
    """Anything with the ``pressor.synthesis.problem.reconstruct.DelayedController`` matrices.

    Time in s.
    """

    Ak: Matrix
    Adk: Matrix
    Bk: Matrix
    Ck: Matrix
    Cdk: Matrix
    Dk: Matrix


@dataclass(frozen=True)
class DelayedControllerMatrices:
    """A plain delayed controller (the same fields as ``DelayedController``), e.g. for tests."""

    Ak: Matrix
    Adk: Matrix
    Bk: Matrix
    Ck: Matrix
    Cdk: Matrix
    Dk: Matrix


def composite_continuous(
    controller: ContinuousController, omega: float, lambda_: float
) -> tuple[Matrix, Matrix]:
    """Continuous composite ``(Ac, Bc)`` for state ``[x_k, u, x_e]`` and input ``[x_d, e]``.

    Parameters
    ----------
    controller
        Delayed controller matrices (time in s); ``Bk`` is n_k x 2, ``Ck``/``Cdk`` 1 x n_k,
        ``Dk`` 1 x 2, the y channels being [e (mmHg), x_e (mmHg*s)].
    omega, lambda_
        Input filter u = omega/(s + lambda_) u_a, in 1/s.

    Returns
    -------
    Ac, Bc
        ``(n_k+2) x (n_k+2)`` and ``(n_k+2) x (n_k+1)`` matrices in 1/s.
    """
    Ak = np.atleast_2d(np.asarray(controller.Ak, float))
    Adk = np.atleast_2d(np.asarray(controller.Adk, float))
    Bk = np.atleast_2d(np.asarray(controller.Bk, float))
    Ck = np.asarray(controller.Ck, float).reshape(1, -1)
    Cdk = np.asarray(controller.Cdk, float).reshape(1, -1)
    Dk = np.asarray(controller.Dk, float).reshape(1, 2)
    n = Ak.shape[0]
    if Adk.shape != (n, n) or Bk.shape != (n, 2) or Ck.shape[1] != n or Cdk.shape[1] != n:
        raise ValueError(
            f"controller shapes Ak{Ak.shape} Adk{Adk.shape} Bk{Bk.shape} Ck{Ck.shape} "
            f"Cdk{Cdk.shape}: expected n x n, n x n, n x 2, 1 x n, 1 x n"
        )
    nz = n + 2
    Ac = np.zeros((nz, nz))
    Bc = np.zeros((nz, n + 1))
    Ac[:n, :n] = Ak
    Ac[:n, n + 1] = Bk[:, 1]
    Ac[n, :n] = omega * Ck[0]
    Ac[n, n] = -lambda_
    Ac[n, n + 1] = omega * Dk[0, 1]
    Bc[:n, :n] = Adk
    Bc[:n, n] = Bk[:, 0]
    Bc[n, :n] = omega * Cdk[0]
    Bc[n, n] = omega * Dk[0, 0]
    Bc[n + 1, n] = 1.0
    return Ac, Bc


def discretise_node(
    controller: ContinuousController, omega: float, lambda_: float, sample_period_s: float
) -> Matrix:
    """Increment matrix ``M = [Phi - I, Gamma]`` of one node (ZOH, period ``sample_period_s``).

    ``Phi - I`` is computed from the series ``Ts*Ac*(I + Ts*Ac/2 + ...)`` through the augmented
    exponential (no cancellation from subtracting I from a near-identity matrix): the top-right
    block of ``expm([[Ac, I, Bc], [0, 0, 0], [0, 0, 0]] * Ts)`` is ``int_0^Ts exp(Ac s) ds`` = Psi,
    and ``Phi - I = Ac Psi``, ``Gamma = Psi Bc``.

    Returns
    -------
    ndarray
        ``(n_k+2) x (2 n_k + 3)``: columns ``[z (n_k+2), x_d (n_k), e]``. The x_e row is
        ``[0, ..., 0, Ts]`` exactly.
    """
    if not (sample_period_s > 0.0 and np.isfinite(sample_period_s)):
        raise ValueError(f"sample_period_s={sample_period_s!r} must be a positive finite time (s)")
    Ac, Bc = composite_continuous(controller, omega, lambda_)
    nz = Ac.shape[0]
    big = np.zeros((2 * nz, 2 * nz))
    big[:nz, :nz] = Ac
    big[:nz, nz:] = np.eye(nz)
    psi = expm(big * sample_period_s)[:nz, nz:]
    m = np.hstack([Ac @ psi, psi @ Bc])
    # The integrator row is structurally exact; remove expm round-off there.
    m[nz - 1, :] = 0.0
    m[nz - 1, -1] = sample_period_s
    return m
