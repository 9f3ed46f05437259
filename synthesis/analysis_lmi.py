"""Delay-dependent analysis LMI for a gridded closed-loop LPV delay system (verification side).

Condition: Theorem 1 of the paper (Zope et al. 2012; Jensen-type Lyapunov-Krasovskii functional
``V = x'P(rho)x + int_{t-tau}^t x'Qx + taubar int_{-taubar}^0 int_{t+theta}^t xdot'R xdot``). For the
closed loop ``dx/dt = A x + Ad x(t - tau(rho)) + B w``, ``z = C x + Cd x(t - tau) + D w`` with
0 <= tau <= taubar it requires, at every grid point and every rate vertex sigma in {-1, +1}^s::

    [ He(P A) + dP + Q - R   P Ad + R            P B    C'    taubar A' R  ]
    [ *                      -(1 - dtau) Q - R   0      Cd'   taubar Ad' R ]
    [ *                      *                   -g I   D'    taubar B' R  ]  <  0,   P(rho) > 0
    [ *                      *                   *      -g I  0            ]
    [ *                      *                   *      *     -R           ]

with ``dP = sum_i sigma_i nu_i dP/drho_i`` and ``dtau = sum_i sigma_i nu_i dtau/drho_i`` (the same
vertex for both: tau is one of the scheduling parameters, so its rate is not an independent
vertex). Then the closed loop is asymptotically stable for all parameter trajectories with the
rate bounds that stay in the gridded box (up to gridding) and its L2 gain w -> z is below g.

Solved form: because A, Ad, B, C, Cd, D are data here (not unknowns as in the synthesis), the
-R and the z blocks are removed by exact Schur complements, and P, Q, R, g are rescaled by g, which
gives the equivalent, smaller (2n + n_w instead of 3n + n_w + n_z) LMI linear in (P, Q, R, mu = g^2)::

    [ He(P A) + dP + Q - R   P Ad + R            P B   ]
    [ *                      -(1 - dtau) Q - R   0     ] + taubar^2 Psi' R Psi + Gamma' Gamma < 0
    [ *                      *                   -mu I ]

with Psi = [A Ad B], Gamma = [C Cd D]; the reported gamma is sqrt(mu).

Choices (this module is independent of the synthesis LMI in :mod:`synthesis.lmi`):

* ``P(rho)`` constant, affine, or quadratic in the normalised parameters rho_hat in [-1, 1]^s
  (quadratic = the synthesis basis ``P0 + sum rho_i P_i1 + 1/2 sum rho_i^2 P_i2``, so
  ``dP/dt = sum (P_i1 + rho_i P_i2) rho_i-dot``); Q, R constant. ``verify`` uses quadratic.
* A constant state transform ``state_transform`` (a congruence: feasibility and gamma unchanged)
  may replace the default diagonal balancing. Measured on the shipped designs: the diagonal
  balancing gave a bogus "optimal" (re-check margin -64 on 27 points, gamma 265 on 125),
  whitening by the centre point's own Lyapunov matrix alone a Clarabel NumericalError, whitening
  followed by balancing (:func:`conditioning_transform`) a clean certificate.
* ``gamma_cap``: feasibility form (gamma <= cap, maximise a common strictness margin t <= 1),
  more robust on the dense grid than minimising gamma; ``verify`` uses it.
* ``taubar`` is the largest delay of the box (``tau_max_s``) at every point, as in the paper.
* Numerics (DESIGN.md §4): time is scaled by ``time_scale_s`` and the states by a constant diagonal
  balancing of the centre system (powers of two); both leave the L2 gain unchanged.
* All LMIs are assembled as one sparse affine map (numpy + scipy.sparse, vectorised over points)
  and passed to cvxpy as a single batched PSD constraint; Clarabel solves it.
* Strictness: every LMI <= -epsilon I and P(rho_k) >= epsilon I, Q, R >= epsilon I. Minimise mu;
  only if the re-check below fails, a back-off solve fixes mu a few percent above the optimum and
  maximises a common margin t (LMI <= -t I, t <= 1). Clarabel's chordal decomposition is off (it
  split the cones into many more variables and was slower and less robust here). The solution
  is re-evaluated in floating point; ``margins`` are the smallest ``-lambda_max`` per point over the rate vertices (scaled units).
  ``certified`` means every re-evaluated LMI is negative definite and every P(rho_k) positive
  definite (the solver's own status is reported, but the re-check is the certificate).
* ``gamma`` reported is the value the certificate holds for (the backed-off one).
"""

from __future__ import annotations

import itertools
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from numpy.typing import NDArray

from synthesis.closed_loop import DelaySystem

__all__ = [
    "P_DEPENDENCES",
    "AnalysisResult",
    "analyse",
    "conditioning_transform",
    "whitening_transform",
]

P_DEPENDENCES = ("constant", "affine", "quadratic")

Array = NDArray[np.float64]


@dataclass(frozen=True)
class AnalysisResult:
    """Outcome of :func:`analyse`.

    Attributes
    ----------
    certified
        Status "optimal", every re-evaluated LMI negative definite, every P(rho_k) positive.
    status
        cvxpy/Clarabel status string.
    gamma
        The certified L2-gain bound (None when the solve failed).
    margins
        (m,) smallest ``-lambda_max`` of the LMI at each point over the rate vertices (scaled).
    p_min_eig
        (m,) smallest eigenvalue of P(rho_k) (scaled).
    n_lmis
        Number of matrix inequalities (points x rate vertices).
    solve_time_s
        Wall time of assembly + solve (s).
    p_dependence
        "constant", "affine" or "quadratic".
    p0_phys
        The constant term P0 of the certificate mapped back to the original (unscaled, untransformed)
        state coordinates, up to a positive factor (None when the solve failed); used to whiten
        the state for a better-conditioned second solve (:func:`whitening_transform`).
    certificate
        The Lyapunov-Krasovskii matrices the solve found, divided by gamma (so that they satisfy
        the printed, unrescaled Theorem-1 LMI at gain ``gamma``), in the solved coordinates:
        ``P`` (n_p, n, n) coefficients of the P basis (weights 1, rho_hat_i, and for "quadratic"
        1/2 rho_hat_i^2), ``Q``, ``R`` (n, n), the ``transform`` T (x = T x_solved) and the
        ``time_scale_s``; None when the solve failed.
    """

    certified: bool
    status: str
    gamma: float | None
    margins: Array
    p_min_eig: Array
    n_lmis: int
    solve_time_s: float
    p_dependence: str
    notes: list[str] = field(default_factory=list)
    p0_phys: Array | None = None
    certificate: dict[str, Any] | None = None


def _sym_index(n: int) -> tuple[NDArray[np.int64], int]:
    """Map (c, d) -> index of the symmetric variable entry (c <= d), and the count n(n+1)/2."""
    idx = np.zeros((n, n), dtype=np.int64)
    k = 0
    for c in range(n):
        for d in range(c, n):
            idx[c, d] = idx[d, c] = k
            k += 1
    return idx, k


class _Assembler:
    """Collect sparse coefficients of ``K`` symmetric N x N matrices affine in one vector x."""

    def __init__(self, k: int, size: int, nvar: int) -> None:
        self.k, self.size, self.nvar = k, size, nvar
        self.rows: list[NDArray[np.int64]] = []
        self.cols: list[NDArray[np.int64]] = []
        self.vals: list[Array] = []
        self.const = np.zeros((k, size, size))

    def add_mvn(
        self,
        m: Array,
        n_: Array,
        var_offset: int,
        sym_idx: NDArray[np.int64],
        row0: int,
        col0: int,
        scale: Array | float = 1.0,
    ) -> None:
        """Add ``scale_k * M_k V N_k`` (V symmetric variable) to block (row0, col0) and its mirror.

        ``m`` is (K, a, n), ``n_`` is (K, n, b); ``scale`` scalar or (K,).
        """
        kk = self.k
        m = np.broadcast_to(m, (kk, *m.shape[-2:]))
        n_ = np.broadcast_to(n_, (kk, *n_.shape[-2:]))
        sc = np.broadcast_to(np.asarray(scale, dtype=float), (kk,))
        coef = np.einsum("k,kac,kdb->kabcd", sc, m, n_)  # d entry(a,b) / d V[c,d]
        k_i, a_i, b_i, c_i, d_i = np.nonzero(coef)
        vals = coef[k_i, a_i, b_i, c_i, d_i]
        var = var_offset + sym_idx[c_i, d_i]
        r, c = row0 + a_i, col0 + b_i
        self._put(k_i, r, c, var, vals)
        # a diagonal block is given symmetrically by the caller (P A and A' P); others mirror
        if row0 != col0:
            self._put(k_i, c, r, var, vals)

    def add_const(self, value: Array, row0: int, col0: int) -> None:
        """Add a constant block (K, a, b) at (row0, col0) and its transpose at the mirror."""
        v = np.broadcast_to(value, (self.k, *value.shape[-2:]))
        a, b = v.shape[1:]
        self.const[:, row0 : row0 + a, col0 : col0 + b] += v
        if row0 != col0:
            self.const[:, col0 : col0 + b, row0 : row0 + a] += np.swapaxes(v, 1, 2)

    def add_var_diag(self, var: int, row0: int, size: int, scale: float) -> None:
        """Add ``scale * x[var] * I`` on the diagonal block at row0 of the given size."""
        k_i = np.repeat(np.arange(self.k), size)
        r = np.tile(np.arange(size), self.k) + row0
        self._put(k_i, r, r, np.full(k_i.shape, var), np.full(k_i.shape, scale, dtype=float))

    def _put(self, k_i, r, c, var, vals) -> None:
        self.rows.append((k_i * self.size + r) * self.size + c)
        self.cols.append(np.asarray(var, dtype=np.int64))
        self.vals.append(np.asarray(vals, dtype=float))

    def matrix(self) -> sp.csr_matrix:
        rows = np.concatenate(self.rows) if self.rows else np.zeros(0, dtype=np.int64)
        cols = np.concatenate(self.cols) if self.cols else np.zeros(0, dtype=np.int64)
        vals = np.concatenate(self.vals) if self.vals else np.zeros(0)
        shape = (self.k * self.size * self.size, self.nvar)
        return sp.csr_matrix((vals, (rows, cols)), shape=shape)


def _balance(a: Array, ad: Array, time_scale_s: float) -> Array:
    """Diagonal state scaling (powers of two) balancing ``|ts A| + |ts Ad|``."""
    mag = time_scale_s * (np.abs(a) + np.abs(ad)) + 1e-12 * np.eye(a.shape[0])
    _, (scale, _perm) = scipy.linalg.matrix_balance(mag, permute=False, separate=True)
    return np.asarray(scale, dtype=float)


def analyse(
    systems: Sequence[DelaySystem],
    rho_hat: Array,
    rate_hat_per_s: Array,
    dtau_drho_hat_s: Array,
    tau_max_s: float,
    p_dependence: str = "affine",
    time_scale_s: float | None = None,
    epsilon: float = 1e-6,
    backoff: float = 0.05,
    solver_options: dict[str, Any] | None = None,
    progress: Callable[[str], None] | None = None,
    state_transform: Array | None = None,
    gamma_cap: float | None = None,
) -> AnalysisResult:
    """Solve the Theorem-1 analysis LMI over a set of frozen closed loops.

    Parameters
    ----------
    systems
        One closed loop per grid point (same state, input and output sizes), physical units.
    rho_hat
        (m, s) normalised parameters of the points, each in [-1, 1].
    rate_hat_per_s
        (s,) bounds on |d rho_hat_i / dt| in 1/s (physical rate bound / half-width of the box).
    dtau_drho_hat_s
        (s,) d tau / d rho_hat_i in s (e.g. [0, 0, half-width of the delay range]).
    tau_max_s
        taubar, the largest delay (s); every ``systems[k].tau`` must be <= it.
    p_dependence
        "constant" or "affine" (in rho_hat).
    time_scale_s
        Time unit of the scaled problem (s); default taubar (or 1 s if taubar is 0).
    epsilon
        Strictness margin of every inequality (scaled units).
    solver_options
        Extra keyword arguments for Clarabel through cvxpy (e.g. ``direct_solve_method``).
    backoff
        If > 0, a second solve fixes gamma at (1 + backoff) times the optimum and maximises the
        strictness margin of every LMI (a better-centred certificate); 0 skips it.
    progress
        Called with a short message before assembly and before each solve.
    state_transform
        Constant invertible T (n x n) with x = T x_new applied to every system before the solve
        (a congruence: feasibility and gamma are unchanged, conditioning is not). Default: a
        diagonal power-of-two balancing of the centre system.
    gamma_cap
        If given, solve the feasibility form instead: gamma <= gamma_cap, maximise a common
        strictness margin (no back-off); the reported gamma is the solution's own bound.

    Returns
    -------
    AnalysisResult
    """
    import cvxpy as cp

    t_start = time.perf_counter()
    if p_dependence not in P_DEPENDENCES:
        raise ValueError(f"p_dependence={p_dependence!r} must be one of {P_DEPENDENCES}")
    m = len(systems)
    rho_hat = np.atleast_2d(np.asarray(rho_hat, dtype=float))
    if m == 0 or rho_hat.shape[0] != m:
        raise ValueError(f"need one rho_hat row per system, got {rho_hat.shape} for {m} systems")
    s = rho_hat.shape[1]
    rate = np.asarray(rate_hat_per_s, dtype=float).reshape(s)
    dtau = np.asarray(dtau_drho_hat_s, dtype=float).reshape(s)
    if np.any(rate < 0) or not np.all(np.isfinite(rate)):
        raise ValueError(f"rate_hat_per_s={rate.tolist()} must be finite and >= 0")
    tau_max = float(tau_max_s)
    taus = np.array([sys_.tau for sys_ in systems])
    if np.any(taus > tau_max * (1 + 1e-12)) or np.any(taus < 0):
        raise ValueError(f"every delay must lie in [0, tau_max_s={tau_max}] s")
    if float(np.sum(rate * np.abs(dtau))) >= 1.0:
        raise ValueError("the delay may change at >= 1 s/s: the functional needs |dtau/dt| < 1")
    ts = float(time_scale_s) if time_scale_s is not None else (tau_max if tau_max > 0 else 1.0)
    n, nw = systems[0].n, systems[0].B.shape[1]

    if state_transform is None:
        mid = systems[m // 2]  # the centre system
        tx = np.diag(_balance(mid.A, mid.Ad, ts))
    else:
        tx = np.asarray(state_transform, dtype=float)
        if tx.shape != (n, n) or not np.all(np.isfinite(tx)) or np.linalg.cond(tx) > 1e12:
            raise ValueError(f"state_transform must be a finite, invertible {n}x{n} matrix")
    txi = np.linalg.inv(tx)
    a = np.stack([ts * txi @ q.A @ tx for q in systems])
    ad = np.stack([ts * txi @ q.Ad @ tx for q in systems])
    b = np.stack([ts * txi @ q.B for q in systems])
    c = np.stack([q.C @ tx for q in systems])
    cd = np.stack([q.Cd @ tx for q in systems])
    d = np.stack([q.D for q in systems])
    tbar = tau_max / ts
    rate_s = rate * ts  # |d rho_hat / d t_hat|

    # rate vertices: only parameters that move and matter (P affine, or the delay depends on them)
    moving = [i for i in range(s) if rate[i] > 0 and (p_dependence != "constant" or dtau[i] != 0.0)]
    vertices = [
        np.array([dict(zip(moving, sig, strict=True)).get(i, 0.0) for i in range(s)])
        for sig in itertools.product((-1.0, 1.0), repeat=len(moving))
    ]
    nv = len(vertices)
    kk = m * nv
    pt = np.repeat(np.arange(m), nv)  # LMI k -> point
    vt = np.tile(np.arange(nv), m)  # LMI k -> vertex
    sig = np.array(vertices)[vt]  # (K, s)

    sym, ns = _sym_index(n)
    # P(rho) = P0 + sum_i rho_i P_i1 (+ 1/2 sum_i rho_i^2 P_i2): value and d/drho_i weights
    p_terms = [(lambda r: np.ones(r.shape[0]), None)]
    if p_dependence != "constant":
        p_terms += [(lambda r, i=i: r[:, i], (i, lambda r: np.ones(r.shape[0]))) for i in range(s)]
    if p_dependence == "quadratic":
        p_terms += [
            (lambda r, i=i: 0.5 * r[:, i] ** 2, (i, lambda r, i=i: r[:, i])) for i in range(s)
        ]
    n_p = len(p_terms)
    off_p = [j * ns for j in range(n_p)]
    off_q, off_r = n_p * ns, (n_p + 1) * ns
    var_g = (n_p + 2) * ns
    nvar = var_g + 1
    size = 2 * n + nw
    r1, r2, r3 = 0, n, 2 * n

    if progress:
        progress(f"analysis LMI: assembling {kk} LMIs of size {size} ({m} points x {nv} vertices)")
    asm = _Assembler(kk, size, nvar)
    eye = np.broadcast_to(np.eye(n), (kk, n, n))
    ak, adk, bk, ck, cdk, dk = a[pt], ad[pt], b[pt], c[pt], cd[pt], d[pt]
    # P(rho) terms: weight 1 for P0, rho_hat_i for P_i
    rho_k = rho_hat[pt]
    for j, (wfun, dfun) in enumerate(p_terms):
        w = wfun(rho_k)
        asm.add_mvn(eye, ak, off_p[j], sym, r1, r1, w)  # P A
        asm.add_mvn(np.swapaxes(ak, 1, 2), eye, off_p[j], sym, r1, r1, w)  # A' P
        asm.add_mvn(eye, adk, off_p[j], sym, r1, r2, w)  # P Ad
        asm.add_mvn(eye, bk, off_p[j], sym, r1, r3, w)  # P B
        if dfun is not None:  # dP/dt = sum_i (d P / d rho_i) * rho_i-dot at this rate vertex
            i, dw = dfun
            asm.add_mvn(eye, eye, off_p[j], sym, r1, r1, dw(rho_k) * sig[:, i] * rate_s[i])
    # Q, R terms
    dtau_k = sig @ (rate * dtau)  # d tau / dt at each vertex (s/s, scale-free)
    asm.add_mvn(eye, eye, off_q, sym, r1, r1, 1.0)
    asm.add_mvn(eye, eye, off_q, sym, r2, r2, -(1.0 - dtau_k))
    asm.add_mvn(eye, eye, off_r, sym, r1, r1, -1.0)
    asm.add_mvn(eye, eye, off_r, sym, r1, r2, 1.0)
    asm.add_mvn(eye, eye, off_r, sym, r2, r2, -1.0)
    # taubar^2 Psi' R Psi and Gamma' Gamma with Psi = [A Ad B], Gamma = [C Cd D] (Schur
    # complements of the printed -R and -gamma I blocks, exact because A.. are data here)
    psi = (ak, adk, bk)
    gam = (ck, cdk, dk)
    rows = (r1, r2, r3)
    for i in range(3):
        for j in range(i, 3):
            asm.add_mvn(np.swapaxes(psi[i], 1, 2), psi[j], off_r, sym, rows[i], rows[j], tbar**2)
            asm.add_const(np.swapaxes(gam[i], 1, 2) @ gam[j], rows[i], rows[j])
    asm.add_var_diag(var_g, r3, nw, -1.0)  # -gamma^2 I
    fmat = asm.matrix()
    const = asm.const + epsilon * np.eye(size)[None]

    x = cp.Variable(nvar)
    lmi = cp.reshape(fmat @ x, (kk, size, size), order="C") + const
    cons = [cp.PSD(-lmi)]
    # P(rho_k) >= eps I at every point, Q, R >= eps I
    pasm = _Assembler(m, n, nvar)
    eye_m = np.broadcast_to(np.eye(n), (m, n, n))
    for j, (wfun, _d) in enumerate(p_terms):
        w = wfun(rho_hat)
        pasm.add_mvn(eye_m, eye_m, off_p[j], sym, 0, 0, w)
    cons.append(cp.PSD(cp.reshape(pasm.matrix() @ x, (m, n, n), order="C") - epsilon * eye_m))
    qr = _Assembler(2, n, nvar)
    qr.add_mvn(np.stack([np.eye(n), np.zeros((n, n))]), np.stack([np.eye(n)] * 2), off_q, sym, 0, 0)
    qr.add_mvn(np.stack([np.zeros((n, n)), np.eye(n)]), np.stack([np.eye(n)] * 2), off_r, sym, 0, 0)
    cons.append(cp.PSD(cp.reshape(qr.matrix() @ x, (2, n, n), order="C") - epsilon * np.eye(n)))
    notes: list[str] = []
    opts = {"chordal_decomposition_enable": False, **(solver_options or {})}
    pmat = pasm.matrix()

    def _gam(mu: float) -> float:
        return float(np.sqrt(max(mu, 0.0)))

    def _recheck(xv: Array) -> tuple[bool, Array, Array]:
        # the certificate is the floating-point re-check, not the solver's word:
        # "optimal_inaccurate" with every LMI negative definite and every P positive certifies
        lmi_val = (fmat @ xv).reshape(kk, size, size) + asm.const
        lmi_val = 0.5 * (lmi_val + np.swapaxes(lmi_val, 1, 2))
        margins = -np.linalg.eigvalsh(lmi_val)[:, -1].reshape(m, nv).max(axis=1)
        p_val = (pmat @ xv).reshape(m, n, n)
        p_min = np.linalg.eigvalsh(0.5 * (p_val + np.swapaxes(p_val, 1, 2)))[:, 0]
        tol = 1e-10 * max(1.0, float(np.max(np.abs(lmi_val))))
        return bool(np.all(margins > tol) and np.all(p_min > 0)), margins, p_min

    def _solve(problem: cp.Problem) -> str:
        try:
            with warnings.catch_warnings():
                # cvxpy's "no CPP backend" / "may be inaccurate" notes: the status and the
                # floating-point re-check below say what matters
                warnings.simplefilter("ignore", UserWarning)
                problem.solve(solver=cp.CLARABEL, **opts)
            return str(problem.status)
        except cp.error.SolverError as exc:  # numerical breakdown: not certified, say why
            notes.append(str(exc).splitlines()[0])
            return "solver_error"

    if progress:
        progress(f"analysis LMI: solving ({nvar} variables, {fmat.nnz} nonzeros) with Clarabel")
    if gamma_cap is not None:
        # feasibility form: gamma bounded, maximise a common strictness margin t (<= 1); measured
        # more robust than minimising gamma when the points differ widely in scale
        t_f = cp.Variable()
        cons_f = [cp.PSD(-lmi - t_f * np.eye(size)[None]), cons[1], cons[2]]
        cons_f += [x[var_g] <= float(gamma_cap) ** 2, t_f <= 1.0]
        status = _solve(cp.Problem(cp.Maximize(t_f), cons_f))
        if t_f.value is not None:
            notes.append(
                f"feasibility form: gamma <= {float(gamma_cap):.4g}, margin t = {float(t_f.value):.3g}"
            )
    else:
        status = _solve(cp.Problem(cp.Minimize(x[var_g]), cons))
    mu_opt = float(x.value[var_g]) if x.value is not None else None
    if (
        gamma_cap is None
        and backoff > 0.0
        and mu_opt is not None
        and status in ("optimal", "optimal_inaccurate")
        and not _recheck(np.asarray(x.value))[0]
    ):
        # second solve: gamma fixed a little above the optimum, maximise the strictness margin;
        # this moves the certificate off the boundary where the solver's tolerances live
        if progress:
            progress(f"analysis LMI: back-off solve at gamma = {_gam((1 + backoff) * mu_opt):.4g}")
        t = cp.Variable()
        shift = t * np.eye(size)[None]
        cons2 = [cp.PSD(-lmi - shift), cons[1], cons[2], x[var_g] == (1 + backoff) * mu_opt]
        cons2 += [t <= 1.0]
        x_first = np.array(x.value)
        status2 = _solve(cp.Problem(cp.Maximize(t), cons2))
        if x.value is None or status2 not in ("optimal", "optimal_inaccurate"):
            notes.append(f"back-off solve ended {status2}; kept the first solution")
            x.value = x_first
        else:
            status = status2
            notes.append(
                f"back-off: gamma {_gam(mu_opt):.6g} -> {_gam((1 + backoff) * mu_opt):.6g}, "
                f"common margin t = {float(t.value):.3g}"
            )
    elapsed = time.perf_counter() - t_start
    if x.value is None or status not in ("optimal", "optimal_inaccurate"):
        return AnalysisResult(
            False,
            status,
            None,
            np.full(m, np.nan),
            np.full(m, np.nan),
            kk,
            elapsed,
            p_dependence,
            notes,
        )
    xv = np.asarray(x.value)
    certified, margins, p_min = _recheck(xv)
    p0m = xv[off_p[0] + sym]  # sym maps both (c, d) and (d, c) to the variable entry
    g = max(_gam(float(xv[var_g])), 1e-300)
    cert = {
        "P": np.stack([xv[o + sym] for o in off_p]) / g,
        "Q": xv[off_q + sym] / g,
        "R": xv[off_r + sym] / g,
        "transform": tx,
        "time_scale_s": ts,
    }
    return AnalysisResult(
        certified,
        status,
        _gam(float(xv[var_g])),
        margins,
        p_min,
        kk,
        elapsed,
        p_dependence,
        notes,
        txi.T @ p0m @ txi,
        cert,
    )


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
    |ts T0^-1 Ad T0|`` (T0 = P^(-1/2)). Measured on the shipped design (27 corner/centre points, P
    quadratic): the default diagonal balancing gave a bogus "optimal" (re-check margin -64),
    whitening alone a Clarabel NumericalError, whitening + balancing a certificate.

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
