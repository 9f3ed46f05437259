"""The sampled frozen closed loop of a tabulated controller and its stability test.

With ``s_k = [dMAP_k, z_k]`` the sampled loop is ``s_{k+1} = sum_j A_j s_{k-j}`` for lags
``j in {0, N-1, N, N+1}`` (tau = (N + f) Ts). Its characteristic roots are the reciprocals of the
zeros of ``g(w) = det(I - sum_j A_j w^(j+1))``; the loop is stable iff g has no zero in the closed
unit disc, i.e. iff the winding number of g(e^(i theta)) about 0 is zero (argument principle;
g(0) = 1). Sampling is refined until no phase step exceeds pi/4, so a root on or near the circle
cannot be stepped over unnoticed.

The loop is the FOPDT patient K/(T s + 1) e^(-tau s) under ZOH with the discrete controller
reading its delayed state from a shift buffer, exactly what the generated step does
(:func:`frozen_loop_matrices`; the patient's sampling is the one the synthesis-side discrete step
uses, :func:`pressor.synthesis.verification.discrete_step.sampled_fopdt`); :func:`unstable_root_count`
counts its unstable roots.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from pressor.synthesis.verification.discrete_step import sampled_fopdt

__all__ = ["frozen_loop_matrices", "unstable_root_count"]

Matrix = NDArray[np.float64]


def frozen_loop_matrices(
    m: Matrix, rho: Sequence[float], sample_period_s: float
) -> dict[int, Matrix]:
    """Lag matrices ``{j: A_j}`` of the sampled frozen loop ``s_{k+1} = sum_j A_j s_{k-j}``.

    Parameters
    ----------
    m
        Increment matrix ``[Phi - I, Gamma]`` of the controller (columns [z, x_d, e]).
    rho
        (K mmHg/(ml/h), T s, tau s); tau must be at least one sample period.
    sample_period_s
        Ts (s).

    Notes
    -----
    Step k of the generated controller uses e_k = -dMAP_k (target and baseline cancel in the
    linearised loop), reads x_d from the buffer at D = tau/Ts samples back (linear interpolation)
    and returns c_k = u_{k+1}. The patient sees c(t - tau) with c held over each sample.
    """
    K, T, tau = (float(r) for r in rho)
    ts = sample_period_s
    nz = m.shape[0]
    nk = nz - 2
    d = tau / ts
    if d < 1.0:
        raise ValueError(f"tau={tau} s shorter than one sample period {ts} s")
    # The controller reads its buffer at D = tau/Ts split as the generated step splits it; the
    # patient's delay is split by sampled_fopdt, which takes a hair below a whole sample as whole.
    n_lag = int(math.floor(d))
    f = d - n_lag
    ns = nz + 1
    mz, md, me = m[:, :nz], m[:, nz : nz + nk], m[:, nz + nk]
    plant = sampled_fopdt(K, T, tau, ts)  # MAP_{k+1} = a MAP_k + b_new c_{k-W} + b_old c_{k-W-1}
    iu = 1 + nk  # index of u inside s
    lags: dict[int, Matrix] = {}

    def lag(j: int) -> Matrix:
        if j not in lags:
            lags[j] = np.zeros((ns, ns))
        return lags[j]

    a0 = lag(0)
    a0[0, 0] = plant.a
    a0[1:, 0] = -me
    a0[1:, 1:] = np.eye(nz) + mz
    # c_{k-W} = u(z_{k-W+1}): lag W-1; c_{k-W-1} = u(z_{k-W}): lag W.
    lag(plant.whole - 1)[0, iu] += plant.b_new
    lag(plant.whole)[0, iu] += plant.b_old
    lag(n_lag)[1:, 1 : 1 + nk] += (1.0 - f) * md
    if f > 0.0:
        lag(n_lag + 1)[1:, 1 : 1 + nk] += f * md
    return lags


def unstable_root_count(lags: dict[int, Matrix], radius: float = 1.0) -> int:
    """Number of characteristic roots with modulus >= ``radius`` (0 means stable).

    Counts the zeros of ``g(w) = det(I - sum_j A_j w^(j+1))`` inside ``|w| < 1/radius`` by the
    argument principle. The circle is sampled uniformly (>= 4 points per unit of polynomial degree)
    and then refined *adaptively*: only the arcs whose phase step is >= pi/4 are bisected, until no
    step is. Roots close to the circle (the slow patient and integrator modes, |w| ~ 1 - 1e-4) need
    a fine sampling only near theta = 0, so refining only the bad arcs is much cheaper than refining
    the whole circle (docs/notes/benchmarks.md, "Design measurements").
    """
    ns = next(iter(lags.values())).shape[0]
    degree = ns * (max(lags) + 1)
    r = 1.0 / radius
    eye = np.eye(ns, dtype=complex)
    items = sorted(lags.items())

    def g_at(theta: Matrix) -> NDArray[np.complex128]:
        w = r * np.exp(1j * theta)
        mat = np.broadcast_to(eye, (len(theta), ns, ns)).copy()
        for j, aj in items:
            mat -= (w ** (j + 1))[:, None, None] * aj[None, :, :]
        return np.linalg.det(mat)

    n0 = 1 << max(10, math.ceil(math.log2(4 * degree)))
    theta = np.linspace(0.0, 2.0 * math.pi, n0 + 1)
    g = g_at(theta[:-1])
    g = np.append(g, g[0])
    for _ in range(64):  # each pass halves the bad arcs; 64 passes reach machine resolution
        if np.any(g == 0):
            return 1
        steps = np.angle(g[1:] / g[:-1])
        bad = np.abs(steps) >= math.pi / 4
        if not bad.any():
            return int(round(float(np.sum(steps)) / (2.0 * math.pi)))
        where = np.nonzero(bad)[0]
        mid = 0.5 * (theta[where] + theta[where + 1])
        theta = np.insert(theta, where + 1, mid)
        g = np.insert(g, where + 1, g_at(mid))
    return 1  # unresolved phase: treat as unstable (never certify what was not resolved)
