"""Delay-dependent analysis LMI with an augmented (Wirtinger-based) Lyapunov-Krasovskii functional.

Why a second analysis: the Jensen functional of :mod:`synthesis.analysis_lmi` (Theorem 1) is
nearly tight for the shipped design but nearly blind to delay compensation: a Smith predictor in
the controller class (:mod:`synthesis.smith_lpv`, loop gain 1.5) is infeasible for it at frozen
points with tau = 27.5 and 45 s and bounded at twice its exact norm at the nominal point, while
this functional bounds the same loops at their exact frozen H-infinity norm (within solver
accuracy; measured figures in docs/CERTIFICATE-STRUCTURE.md). Reference: Seuret & Gouaisbaut,
"Wirtinger-based integral inequality: application to time-delay systems", Automatica 49 (2013),
extended here to the LPV grid, a parameter-dependent P and a delay tau(rho) that moves with rho.

Functional, with ``xi = [x; int_{t-tau}^t x ds]`` (2n states)::

    V = xi' P(rho) xi + int_{t-tau}^t x'Sx ds + taubar int_{-taubar}^0 int_{t+theta}^t xdot'R xdot

For ``dx/dt = A x + Ad x(t - tau) + B w``, ``z = C x + Cd x(t - tau) + D w`` and
``zeta = [x; x(t - tau); v; w]`` with ``v = (1/tau) int_{t-tau}^t x`` it uses
``d/dt int_{t-tau}^t x = x - (1 - dtau) x(t - tau)`` and Wirtinger's inequality
``tau int_{t-tau}^t xdot'R xdot >= e1'R e1 + 3 e2'R e2`` (``e1 = x - x_tau``,
``e2 = x + x_tau - 2 v``); since ``taubar >= tau`` the double integral's derivative is bounded by
``taubar^2 xdot'R xdot - (taubar/tau)(e1'R e1 + 3 e2'R e2)``. The condition, at every grid point
and rate vertex, rescaled by gamma as in :mod:`synthesis.analysis_lmi` (mu = gamma^2)::

    He(G1' P G0) + G1' dP G1 + Ex'S Ex - (1 - dtau) Eh'S Eh + taubar^2 Ga'R Ga
      - (taubar/tau)(E1'R E1 + 3 E2'R E2) - mu Ew'Ew + Gz'Gz  <  0,   P(rho) > 0, S > 0, R > 0

with ``G1 zeta = xi``, ``G0 zeta = dxi/dt``, ``Ga = [A Ad 0 B]``, ``Gz = [C Cd 0 D]`` and the
selectors Ex, Eh, E1, E2, Ew of x, x_tau, e1, e2, w. Then the closed loop is asymptotically stable
for every parameter trajectory in the gridded box with the rate bounds (up to gridding) and its
L2 gain w -> z is below gamma. P(rho) is in the basis of :mod:`synthesis.analysis_lmi`
(constant, affine or quadratic in rho_hat); S, R constant.

Build: the LMI is affine in the decision vector; its exact sparse map is obtained by evaluating
the vectorised numeric LMI at unit vectors in chunks (as :mod:`synthesis.lmi`), then one batched
PSD constraint goes to Clarabel through cvxpy. Scaling, state transform, strictness margins,
the feasibility form (``gamma_cap``) and the floating-point re-check are those of
:func:`synthesis.analysis_lmi.analyse`; the result type is the same.
"""

from __future__ import annotations

import itertools
import time
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from synthesis.analysis_lmi import AnalysisResult, checked_inputs, transform_of
from synthesis.closed_loop import DelaySystem

__all__ = ["analyse_wirtinger"]

Array = NDArray[np.float64]

#: decision-vector columns probed per chunk (bounds the dense probe to ~chunk x LMI-stack size)
_PROBE_CHUNK = 16


def _sym(vec: Array, n: int) -> Array:
    """Symmetric (…, n, n) matrices from their upper-triangle entries (…, n(n+1)/2)."""
    iu = np.triu_indices(n)
    out = np.zeros((*vec.shape[:-1], n, n))
    out[..., iu[0], iu[1]] = vec
    out[..., iu[1], iu[0]] = vec
    return out


def _p_basis(rho_hat: Array, p_dependence: str) -> tuple[Array, Array]:
    """Weights (m, n_p) of the P basis and their derivatives (m, n_p, s) in rho_hat."""
    m, s = rho_hat.shape
    w, dw = [np.ones(m)], [np.zeros((m, s))]
    if p_dependence != "constant":
        for i in range(s):
            d = np.zeros((m, s))
            d[:, i] = 1.0
            w.append(rho_hat[:, i])
            dw.append(d)
    if p_dependence == "quadratic":
        for i in range(s):
            d = np.zeros((m, s))
            d[:, i] = rho_hat[:, i]
            w.append(0.5 * rho_hat[:, i] ** 2)
            dw.append(d)
    return np.stack(w, axis=1), np.stack(dw, axis=1)


def analyse_wirtinger(
    systems: Sequence[DelaySystem],
    rho_hat: Array,
    rate_hat_per_s: Array,
    dtau_drho_hat_s: Array,
    tau_max_s: float,
    p_dependence: str = "affine",
    time_scale_s: float | None = None,
    epsilon: float = 1e-6,
    state_transform: Array | None = None,
    gamma_cap: float | None = None,
    solver_options: dict[str, Any] | None = None,
) -> AnalysisResult:
    """Solve the Wirtinger-based analysis LMI over a set of frozen closed loops.

    Parameters are those of :func:`synthesis.analysis_lmi.analyse` (no back-off solve: use
    ``gamma_cap`` for a centred certificate). Every delay must be > 0 (the functional divides by
    tau) and <= ``tau_max_s``.

    Returns
    -------
    AnalysisResult
        ``certificate`` holds ``P`` (n_p, 2n, 2n) on ``xi = [x; int x]``, ``S``, ``R`` (divided by
        gamma), ``transform`` and ``time_scale_s``.
    """
    import cvxpy as cp

    t_start = time.perf_counter()
    rho_hat, rate, dtau, tau_max, taus = checked_inputs(
        systems,
        rho_hat,
        rate_hat_per_s,
        dtau_drho_hat_s,
        tau_max_s,
        p_dependence,
        zero_delay_ok=False,
    )
    m, s = rho_hat.shape
    ts = float(time_scale_s) if time_scale_s is not None else tau_max
    n, nw = systems[0].n, systems[0].B.shape[1]
    tx, txi = transform_of(systems, ts, state_transform)
    a = np.stack([ts * txi @ q.A @ tx for q in systems])
    ad = np.stack([ts * txi @ q.Ad @ tx for q in systems])
    b = np.stack([ts * txi @ q.B for q in systems])
    c = np.stack([q.C @ tx for q in systems])
    cd = np.stack([q.Cd @ tx for q in systems])
    d = np.stack([q.D for q in systems])
    h, hbar = taus / ts, tau_max / ts

    verts = np.array(list(itertools.product((-1.0, 1.0), repeat=s)))
    nv = len(verts)
    kk = m * nv
    w_p, dw_p = _p_basis(rho_hat, p_dependence)
    n_p = w_p.shape[1]
    n2, big = 2 * n, 3 * n + nw
    ns2, ns = n2 * (n2 + 1) // 2, n * (n + 1) // 2
    off_s = n_p * ns2
    off_r = off_s + ns
    var_mu = off_r + ns
    nvar = var_mu + 1

    eye, zero = np.eye(n), np.zeros
    ex = np.hstack([eye, zero((n, 2 * n + nw))])
    eh = np.hstack([zero((n, n)), eye, zero((n, n + nw))])
    e1 = np.hstack([eye, -eye, zero((n, n + nw))])
    e2 = np.hstack([eye, eye, -2.0 * eye, zero((n, nw))])
    ew = np.hstack([zero((nw, 3 * n)), np.eye(nw)])
    ga = np.concatenate([a, ad, zero((m, n, n)), b], axis=2)  # (m, n, big)
    gz = np.concatenate([c, cd, zero((m, c.shape[1], n)), d], axis=2)
    dtau_dt = verts @ (rate * dtau)  # (nv,) s/s
    g1 = np.zeros((m, n2, big))
    g1[:, :n, :n] = eye
    g1[:, n:, 2 * n : 3 * n] = h[:, None, None] * eye
    g0 = np.zeros((m, nv, n2, big))
    g0[:, :, :n, :] = ga[:, None]
    g0[:, :, n:, :n] = eye
    g0[:, :, n:, n : 2 * n] = -(1.0 - dtau_dt)[None, :, None, None] * eye
    dw_v = np.einsum("mjs,vs,s->mvj", dw_p, verts, rate * ts)  # dP/dt_hat weights

    def linear(x: Array) -> Array:
        """The LMI stack's linear part for decision vectors x (J, nvar) -> (J, m, nv, big, big)."""
        j = x.shape[0]
        pc = _sym(x[:, :off_s].reshape(j, n_p, ns2), n2)
        sm, rm, mu = _sym(x[:, off_s:off_r], n), _sym(x[:, off_r:var_mu], n), x[:, var_mu]
        p = np.einsum("mk,Jkab->Jmab", w_p, pc)
        pdot = np.einsum("mvk,Jkab->Jmvab", dw_v, pc)
        he = np.einsum("mra,Jmrs,mvsb->Jmvab", g1, p, g0)
        out = he + np.swapaxes(he, -1, -2) + np.einsum("mra,Jmvrs,msb->Jmvab", g1, pdot, g1)
        out += np.einsum("ra,Jrs,sb->Jab", ex, sm, ex)[:, None, None]
        out -= (1.0 - dtau_dt)[None, None, :, None, None] * np.einsum("ra,Jrs,sb->Jab", eh, sm, eh)[
            :, None, None
        ]
        out += hbar**2 * np.einsum("mra,Jrs,msb->Jmab", ga, rm, ga)[:, :, None]
        wirt = np.einsum("ra,Jrs,sb->Jab", e1, rm, e1) + 3.0 * np.einsum(
            "ra,Jrs,sb->Jab", e2, rm, e2
        )
        out -= (hbar / h)[None, :, None, None, None] * wirt[:, None, None]
        out -= mu[:, None, None, None, None] * (ew.T @ ew)
        return out

    rows, cols, vals = [], [], []
    for j0 in range(0, nvar, _PROBE_CHUNK):
        js = np.arange(j0, min(nvar, j0 + _PROBE_CHUNK))
        unit = np.zeros((len(js), nvar))
        unit[np.arange(len(js)), js] = 1.0
        block = linear(unit).reshape(len(js), -1)
        jj, rr = np.nonzero(block)
        rows.append(rr)
        cols.append(js[jj])
        vals.append(block[jj, rr])
    fmat = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(kk * big * big, nvar),
    )
    const = np.broadcast_to(np.einsum("mra,mrb->mab", gz, gz)[:, None], (m, nv, big, big))
    const = const.reshape(kk, big, big)

    # P(rho_k) on xi, S and R as linear maps of x (unit-vector probes of the same kind)
    def positive(x: Array) -> Array:
        j = x.shape[0]
        pc = _sym(x[:, :off_s].reshape(j, n_p, ns2), n2)
        return np.einsum("mk,Jkab->Jmab", w_p, pc).reshape(j, -1)

    ident = np.eye(nvar)
    pmat = sp.csr_matrix(positive(ident).T)
    smat = sp.csr_matrix(_sym(ident[:, off_s:off_r], n).reshape(nvar, -1).T)
    rmat = sp.csr_matrix(_sym(ident[:, off_r:var_mu], n).reshape(nvar, -1).T)

    x = cp.Variable(nvar)
    lmi = cp.reshape(fmat @ x, (kk, big, big), order="C") + const
    cons = [
        cp.PSD(cp.reshape(pmat @ x, (m, n2, n2), order="C") - epsilon * np.eye(n2)[None]),
        cp.PSD(cp.reshape(smat @ x, (n, n), order="C") - epsilon * np.eye(n)),
        cp.PSD(cp.reshape(rmat @ x, (n, n), order="C") - epsilon * np.eye(n)),
    ]
    if gamma_cap is None:
        cons.append(cp.PSD(-lmi - epsilon * np.eye(big)[None]))
        problem = cp.Problem(cp.Minimize(x[var_mu]), cons)
    else:
        t_m = cp.Variable()
        cons += [cp.PSD(-lmi - t_m * np.eye(big)[None]), x[var_mu] <= float(gamma_cap) ** 2]
        cons.append(t_m <= 1.0)
        problem = cp.Problem(cp.Maximize(t_m), cons)
    notes: list[str] = []
    opts = {"chordal_decomposition_enable": False, **(solver_options or {})}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # cvxpy notes; the re-check decides
            problem.solve(solver=cp.CLARABEL, **opts)
        status = str(problem.status)
    except cp.error.SolverError as exc:
        notes.append(str(exc).splitlines()[0])
        status = "solver_error"
    elapsed = time.perf_counter() - t_start
    if x.value is None or status not in ("optimal", "optimal_inaccurate"):
        nan = np.full(m, np.nan)
        return AnalysisResult(False, status, None, nan, nan, kk, elapsed, p_dependence, notes)
    xv = np.asarray(x.value)
    lmi_val = (fmat @ xv).reshape(kk, big, big) + const
    lmi_val = 0.5 * (lmi_val + np.swapaxes(lmi_val, 1, 2))
    margins = -np.linalg.eigvalsh(lmi_val)[:, -1].reshape(m, nv).max(axis=1)
    p_min = np.linalg.eigvalsh((pmat @ xv).reshape(m, n2, n2))[:, 0]
    sr_min = min(
        np.linalg.eigvalsh(_sym(xv[off_s:off_r], n))[0],
        np.linalg.eigvalsh(_sym(xv[off_r:var_mu], n))[0],
    )
    tol = 1e-10 * max(1.0, float(np.max(np.abs(lmi_val))))
    certified = bool(np.all(margins > tol) and np.all(p_min > 0) and sr_min > 0)
    gamma = float(np.sqrt(max(float(xv[var_mu]), 0.0)))
    g = max(gamma, 1e-300)
    certificate = {
        "P": _sym(xv[:off_s].reshape(n_p, ns2), n2) / g,
        "S": _sym(xv[off_s:off_r], n) / g,
        "R": _sym(xv[off_r:var_mu], n) / g,
        "transform": tx,
        "time_scale_s": ts,
    }
    p0 = _sym(xv[:ns2], n2)[:n, :n]
    return AnalysisResult(
        certified,
        status,
        gamma,
        margins,
        p_min,
        kk,
        elapsed,
        p_dependence,
        notes,
        txi.T @ p0 @ txi,
        certificate,
    )
