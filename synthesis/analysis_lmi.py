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
* Build and solve (measured on the shipped design, 125 points x 8 rate vertices = 1000 LMIs of
  size 15, 190 variables): each LMI's exact affine map is assembled densely a few points at a time
  (structural zeros stay exact) straight into Clarabel's PSD-triangle order, and Clarabel is
  called on that conic data directly (:mod:`synthesis.conic`, which also reports every
  iteration). Going through cvxpy instead (one batched PSD constraint over a 10.7 M-nonzero
  full-matrix map, all 1000 LMIs) took 53 s of ``pressor synth``'s verification and most of its
  2.5 GB peak memory.
* ``working_set=k``: the LMI (all rate vertices) is imposed only at k points spread over the grid
  (farthest-point order from the centre); every point and vertex is then re-checked and up to k
  failing points are added, until the re-check passes or every point is imposed. Clarabel's cost
  grows with the number of PSD blocks, and on the shipped design the synthesis-node count (27)
  of spread points already certifies all 125; the certificate is the same re-check either way.
  ``working_set=None`` imposes every point in one solve.
* ``rate_bound=True``: the working-set solves use the rate-bound form (one LMI per point, slacks
  Z_i >= +/- nu_i dP/drho_i and the largest dtau/dt, as the synthesis' "bound" rate terms), which
  implies every vertex LMI; the vertex form is solved if it does not pass the re-check. Shipped
  design: 27 blocks instead of 216, the analysis 6.5 s instead of ~20 s on a loaded machine.
* Strictness: every LMI <= -epsilon I and P(rho_k) >= epsilon I, Q, R >= epsilon I. Minimise mu;
  only if the re-check below fails, a back-off solve fixes mu a few percent above the optimum and
  maximises a common margin t (LMI <= -t I, t <= 1). Clarabel's chordal decomposition is off (it
  split the cones into many more variables and was slower and less robust here). The solution
  is re-evaluated in floating point at every point and rate vertex; ``margins`` are the smallest
  ``-lambda_max`` per point over the rate vertices (scaled units).
  ``certified`` means every re-evaluated LMI is negative definite and every P(rho_k) positive
  definite (the solver's own status is reported, but the re-check is the certificate).
* ``gamma`` reported is the value the certificate holds for (the backed-off one).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from numpy.typing import NDArray

from synthesis.closed_loop import DelaySystem
from synthesis.conic import solve_conic, svec_eye, svec_rows, unsvec

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
        Clarabel's outcome as a cvxpy status string ("optimal", "optimal_inaccurate", ...).
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
        The Lyapunov-Krasovskii matrices divided by gamma, with the state transform and time
        scale they live in, for analyses that return them (:mod:`synthesis.analysis_wirtinger`);
        None here.
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
    """Coefficients of ``K`` symmetric N x N matrices affine in one vector x (a few at a time).

    Dense per call (K x N x N x nvar, so callers keep K small) and exact: every coefficient is a
    sum of products of the data, structural zeros stay exact zeros. :meth:`svec` returns the map
    in Clarabel's PSD-triangle order as a sparse matrix.
    """

    def __init__(self, k: int, size: int, nvar: int) -> None:
        self.k, self.size, self.nvar = k, size, nvar
        self.coef = np.zeros((k, size, size, nvar))
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
        n = sym_idx.shape[0]
        a, b = m.shape[1], n_.shape[2]
        ns = int(sym_idx.max()) + 1
        # d entry(a, b) / d V[c, d] = scale m[a, c] n[d, b]
        nt = np.swapaxes(n_, 1, 2)  # [k, b, d]
        coef = (sc[:, None, None] * m)[:, :, None, :, None] * nt[:, None, :, None, :]
        # V[c, d] and V[d, c] are the same variable: sum their coefficients
        fold = np.zeros((n * n, ns))
        fold[np.arange(n * n), sym_idx.reshape(-1)] = 1.0
        block = coef.reshape(kk, a, b, n * n) @ fold
        self.coef[:, row0 : row0 + a, col0 : col0 + b, var_offset : var_offset + ns] += block
        # a diagonal block is given symmetrically by the caller (P A and A' P); others mirror
        if row0 != col0:
            self.coef[:, col0 : col0 + b, row0 : row0 + a, var_offset : var_offset + ns] += (
                np.swapaxes(block, 1, 2)
            )

    def add_const(self, value: Array, row0: int, col0: int) -> None:
        """Add a constant block (K, a, b) at (row0, col0) and its transpose at the mirror."""
        v = np.broadcast_to(value, (self.k, *value.shape[-2:]))
        a, b = v.shape[1:]
        self.const[:, row0 : row0 + a, col0 : col0 + b] += v
        if row0 != col0:
            self.const[:, col0 : col0 + b, row0 : row0 + a] += np.swapaxes(v, 1, 2)

    def add_var_diag(self, var: int, row0: int, size: int, scale: float) -> None:
        """Add ``scale * x[var] * I`` on the diagonal block at row0 of the given size."""
        r = np.arange(row0, row0 + size)
        self.coef[:, r, r, var] += scale

    def repeated(self, times: int) -> _Assembler:
        """A new assembler holding each of these matrices ``times`` times in a row."""
        out = _Assembler(self.k * times, self.size, self.nvar)
        out.coef = np.repeat(self.coef, times, axis=0)
        out.const = np.repeat(self.const, times, axis=0)
        return out

    def svec(self) -> tuple[sp.csr_matrix, Array]:
        """``(F, f0)`` with ``svec(M_k(x))`` stacked over k equal to ``F x + f0``."""
        idx, w = svec_rows(self.size)
        nn = self.size * self.size
        f = self.coef.reshape(self.k, nn, self.nvar)[:, idx, :] * w[None, :, None]
        f0 = self.const.reshape(self.k, nn)[:, idx] * w[None, :]
        return sp.csr_matrix(f.reshape(-1, self.nvar)), f0.reshape(-1)


def _balance(a: Array, ad: Array, time_scale_s: float) -> Array:
    """Diagonal state scaling (powers of two) balancing ``|ts A| + |ts Ad|``."""
    mag = time_scale_s * (np.abs(a) + np.abs(ad)) + 1e-12 * np.eye(a.shape[0])
    _, (scale, _perm) = scipy.linalg.matrix_balance(mag, permute=False, separate=True)
    return np.asarray(scale, dtype=float)


@dataclass(frozen=True)
class _Problem:
    """The scaled data of one analysis problem (every point, every rate vertex)."""

    a: Array  # (m, n, n) scaled, transformed closed loops
    ad: Array
    b: Array
    c: Array
    cd: Array
    d: Array
    rho_hat: Array  # (m, s)
    vertices: Array  # (nv, s) rate signs
    rate_s: Array  # (s,) |d rho_hat / d t_hat|
    dtau_rate: Array  # (s,) rate * d tau / d rho_hat (s/s)
    tbar: float
    p_terms: list  # [(weight(rho), (i, d weight / d rho_i) or None)]
    sym: NDArray[np.int64]
    ns: int

    @property
    def n(self) -> int:
        return self.a.shape[1]

    @property
    def size(self) -> int:
        return 2 * self.n + self.b.shape[2]

    @property
    def off_q(self) -> int:
        return len(self.p_terms) * self.ns

    @property
    def var_g(self) -> int:
        return self.off_q + 2 * self.ns

    @property
    def nvar(self) -> int:
        return self.var_g + 1


def checked_inputs(
    systems: Sequence[DelaySystem],
    rho_hat: Array,
    rate_hat_per_s: Array,
    dtau_drho_hat_s: Array,
    tau_max_s: float,
    p_dependence: str,
    zero_delay_ok: bool = True,
) -> tuple[Array, Array, Array, float, Array]:
    """Validate the arguments every analysis LMI shares; return rho_hat, rates, dtau, tau_max, taus.

    Raises
    ------
    ValueError
        An unknown ``p_dependence``, a rho_hat row count that differs from the systems, a negative
        or non-finite rate, a delay outside [0, tau_max] ((0, tau_max] without ``zero_delay_ok``)
        or a delay that may change at 1 s/s or faster.
    """
    if p_dependence not in P_DEPENDENCES:
        raise ValueError(f"p_dependence={p_dependence!r} must be one of {P_DEPENDENCES}")
    m = len(systems)
    rho = np.atleast_2d(np.asarray(rho_hat, dtype=float))
    if m == 0 or rho.shape[0] != m:
        raise ValueError(f"need one rho_hat row per system, got {rho.shape} for {m} systems")
    s = rho.shape[1]
    rate = np.asarray(rate_hat_per_s, dtype=float).reshape(s)
    dtau = np.asarray(dtau_drho_hat_s, dtype=float).reshape(s)
    if np.any(rate < 0) or not np.all(np.isfinite(rate)):
        raise ValueError(f"rate_hat_per_s={rate.tolist()} must be finite and >= 0")
    tau_max = float(tau_max_s)
    taus = np.array([sys_.tau for sys_ in systems])
    low_bad = taus < 0 if zero_delay_ok else taus <= 0
    if np.any(taus > tau_max * (1 + 1e-12)) or np.any(low_bad):
        lo = "[0" if zero_delay_ok else "(0"
        raise ValueError(f"every delay must lie in {lo}, tau_max_s={tau_max}] s")
    if float(np.sum(rate * np.abs(dtau))) >= 1.0:
        raise ValueError("the delay may change at >= 1 s/s: the functional needs |dtau/dt| < 1")
    return rho, rate, dtau, tau_max, taus


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


def _lmi_map(
    pr: _Problem, points: NDArray[np.int64], bound: bool = False
) -> tuple[sp.csr_matrix, Array]:
    """Affine map of the LMIs at ``points`` (all rate vertices of each, point-major order):
    ``svec(LMI) = F x + f0`` in Clarabel's PSD-triangle order (see :func:`synthesis.conic.svec_rows`).

    ``bound``: one matrix per point, without dP/dt and with ``-(1 - dtau_max) Q`` (the rate-bound
    form adds the slack Z terms, :func:`_bound_parts`).
    """
    nv, npt = pr.vertices.shape[0], len(points)
    n, size, ns = pr.n, pr.size, pr.ns
    sym = pr.sym
    r1, r2, r3 = 0, n, 2 * n
    off_q, off_r = pr.off_q, pr.off_q + ns
    # the terms that do not depend on the rate vertex, once per point
    base = _Assembler(npt, size, pr.nvar)
    eye = np.broadcast_to(np.eye(n), (npt, n, n))
    ak, adk, bk, ck, cdk, dk = (v[points] for v in (pr.a, pr.ad, pr.b, pr.c, pr.cd, pr.d))
    rho_p = pr.rho_hat[points]
    for j, (wfun, _dfun) in enumerate(pr.p_terms):
        w = wfun(rho_p)
        base.add_mvn(eye, ak, j * ns, sym, r1, r1, w)  # P A
        base.add_mvn(np.swapaxes(ak, 1, 2), eye, j * ns, sym, r1, r1, w)  # A' P
        base.add_mvn(eye, adk, j * ns, sym, r1, r2, w)  # P Ad
        base.add_mvn(eye, bk, j * ns, sym, r1, r3, w)  # P B
    base.add_mvn(eye, eye, off_q, sym, r1, r1, 1.0)
    base.add_mvn(eye, eye, off_q, sym, r2, r2, -1.0)
    base.add_mvn(eye, eye, off_r, sym, r1, r1, -1.0)
    base.add_mvn(eye, eye, off_r, sym, r1, r2, 1.0)
    base.add_mvn(eye, eye, off_r, sym, r2, r2, -1.0)
    # taubar^2 Psi' R Psi and Gamma' Gamma with Psi = [A Ad B], Gamma = [C Cd D] (Schur
    # complements of the printed -R and -gamma I blocks, exact because A.. are data here)
    psi, gam, rows = (ak, adk, bk), (ck, cdk, dk), (r1, r2, r3)
    for i in range(3):
        for j in range(i, 3):
            base.add_mvn(
                np.swapaxes(psi[i], 1, 2), psi[j], off_r, sym, rows[i], rows[j], pr.tbar**2
            )
            base.add_const(np.swapaxes(gam[i], 1, 2) @ gam[j], rows[i], rows[j])
    base.add_var_diag(pr.var_g, r3, pr.b.shape[2], -1.0)  # -gamma^2 I
    if bound:  # -(1 - dtau) Q is largest at the largest dtau/dt because Q >= 0
        base.add_mvn(eye, eye, off_q, sym, r2, r2, float(np.max(pr.vertices @ pr.dtau_rate)))
        return base.svec()
    # then each point's copy per rate vertex gets dP/dt and the dtau/dt part of -(1 - dtau) Q
    asm = base.repeated(nv)
    sig = np.tile(pr.vertices, (npt, 1))  # (K, s), point-major
    rho_k = np.repeat(rho_p, nv, axis=0)
    eye = np.broadcast_to(np.eye(n), (npt * nv, n, n))
    for j, (_wfun, dfun) in enumerate(pr.p_terms):
        if dfun is not None:  # dP/dt = sum_i (d P / d rho_i) * rho_i-dot at this rate vertex
            i, dw = dfun
            asm.add_mvn(eye, eye, j * ns, sym, r1, r1, dw(rho_k) * sig[:, i] * pr.rate_s[i])
    asm.add_mvn(eye, eye, off_q, sym, r2, r2, sig @ pr.dtau_rate)  # dtau/dt (s/s, scale-free)
    return asm.svec()


def _bound_parts(
    pr: _Problem, points: NDArray[np.int64]
) -> tuple[sp.csr_matrix, Array, sp.csr_matrix, int]:
    """Rate-bound form at ``points`` (the synthesis' "bound" treatment of the rate vertices).

    Per point p and moving parameter i a symmetric slack Z_{p,i} >= +/- nu_i dP/drho_i(rho_p), and
    one LMI per point with dP/dt replaced by sum_i Z_{p,i} and -(1 - dtau_max) Q: it bounds every
    vertex LMI of the point from above, so it implies them (sufficient, can be more conservative).

    Returns ``(F, f0, G, nz)`` over the variables ``[x, Z]`` (Z after the nvar entries of x, nz of
    them): ``svec(LMI_p) = F [x; Z] + f0`` and ``svec(Z_{p,i} -/+ nu_i dP_i) = G [x; Z]`` (>= 0).
    """
    n, ns, nvar, npt = pr.n, pr.ns, pr.nvar, len(points)
    terms = [(j, d) for j, (_w, d) in enumerate(pr.p_terms) if d is not None]
    moving = sorted({i for _j, (i, _dw) in terms if pr.rate_s[i] > 0})
    nmov = len(moving)
    nz = npt * nmov * ns
    size, nsv, nsn = pr.size, pr.size * (pr.size + 1) // 2, n * (n + 1) // 2
    f_x, f0 = _lmi_map(pr, points, bound=True)
    # Z entries in the (1, 1) block of each point's LMI (svec rows with both indices < n)
    idx, w = svec_rows(size)
    rr, cc = idx // size, idx % size
    pos = np.flatnonzero((rr < n) & (cc < n))
    zsym = pr.sym[rr[pos], cc[pos]]
    q, il, k = np.meshgrid(np.arange(npt), np.arange(nmov), np.arange(len(pos)), indexing="ij")
    f_z = sp.csr_matrix(
        (w[pos][k].ravel(), ((q * nsv + pos[k]).ravel(), ((q * nmov + il) * ns + zsym[k]).ravel())),
        shape=(npt * nsv, nz),
    )
    # Z_{p,i} - s nu_i dP/drho_i(rho_p) for s = +1, -1: matrices ordered (point, parameter, sign)
    nmat = npt * nmov * 2
    asm = _Assembler(nmat, n, nvar)
    eye = np.broadcast_to(np.eye(n), (nmat, n, n))
    rho_m = np.repeat(pr.rho_hat[points], nmov * 2, axis=0)
    par = np.tile(np.repeat(np.array(moving), 2), npt)
    sign = np.tile([1.0, -1.0], npt * nmov)
    for j, (i, dw) in terms:
        scale = np.where(par == i, -sign * pr.rate_s[i] * dw(rho_m), 0.0)
        asm.add_mvn(eye, eye, j * ns, pr.sym, 0, 0, scale)
    g_x, _ = asm.svec()
    idn, wn = svec_rows(n)
    zs = pr.sym[idn // n, idn % n]
    mat, e = np.meshgrid(np.arange(nmat), np.arange(nsn), indexing="ij")
    g_z = sp.csr_matrix(
        (wn[e].ravel(), ((mat * nsn + e).ravel(), ((mat // 2) * ns + zs[e]).ravel())),
        shape=(nmat * nsn, nz),
    )
    return sp.hstack([f_x, f_z], format="csr"), f0, sp.hstack([g_x, g_z], format="csr"), nz


def _p_map(pr: _Problem) -> sp.csr_matrix:
    """svec of P(rho_k) at every point (P(rho) = sum_j w_j(rho) P_j), then Q, R: ``F x``."""
    m, n = pr.rho_hat.shape[0], pr.n
    pasm = _Assembler(m + 2, n, pr.nvar)
    eye = np.broadcast_to(np.eye(n), (m + 2, n, n))
    for j, (wfun, _d) in enumerate(pr.p_terms):
        pasm.add_mvn(eye, eye, j * pr.ns, pr.sym, 0, 0, np.r_[wfun(pr.rho_hat), 0.0, 0.0])
    pasm.add_mvn(eye, eye, pr.off_q, pr.sym, 0, 0, np.r_[np.zeros(m), 1.0, 0.0])
    pasm.add_mvn(eye, eye, pr.off_q + pr.ns, pr.sym, 0, 0, np.r_[np.zeros(m), 0.0, 1.0])
    return pasm.svec()[0]


def first_points(rho_hat: Array, working_set: int | None) -> NDArray[np.int64]:
    """The points of the first solve: every point (``working_set=None``) or the first k of
    :func:`_spread_order`, sorted.

    Raises
    ------
    ValueError
        ``working_set`` not None and below 1.
    """
    if working_set is not None and int(working_set) < 1:
        raise ValueError(f"working_set={working_set!r} must be None or an integer >= 1")
    m = rho_hat.shape[0]
    return (
        np.arange(m) if working_set is None else np.sort(_spread_order(rho_hat)[: int(working_set)])
    )


Recheck = tuple[bool, Array, Array]


def grow_working_set(
    points: NDArray[np.int64],
    working_set: int | None,
    solve: Callable[[NDArray[np.int64]], tuple[str, Array | None]],
    recheck: Callable[[Array], Recheck],
    notes: list[str],
    progress: Callable[[str], None] | None,
    n_vertices: int,
    stop_if_imposed_fails: bool = False,
) -> tuple[str, Array | None, NDArray[np.int64], Recheck]:
    """Solve with the LMI imposed at ``points``, re-check every point, add failing ones, repeat.

    ``solve(points)`` returns (status, decision vector or None); ``recheck(x)`` returns
    (certified, margins (m,), P eigenvalue minima) at EVERY point and rate vertex. Up to
    ``working_set`` failing points (the worst first; all of them when None) are added per round,
    until the re-check passes, every point is imposed, or no failing point is left to add.
    ``stop_if_imposed_fails``: also stop when an imposed point fails (sound for a feasibility
    form with a fixed gamma cap: a larger set of points cannot be feasible when a subset is not).

    Returns
    -------
    tuple
        (status, x or None, the points imposed last, the last re-check (False, nan, nan if none)).
    """
    checked: Recheck = (False, np.array([np.nan]), np.array([np.nan]))
    while True:
        status, xv = solve(points)
        if xv is None:
            return status, xv, points, checked
        checked = recheck(xv)
        certified, margins, _ = checked
        m = len(margins)
        failing = np.flatnonzero(~(margins > 0))
        new = np.setdiff1d(failing[np.argsort(margins[failing], kind="stable")], points)
        imposed_fail = np.intersect1d(failing, points)
        if certified or len(points) == m or len(new) == 0:
            return status, xv, points, checked
        if stop_if_imposed_fails and len(imposed_fail):
            notes.append(
                f"{len(imposed_fail)} of the {len(points)} imposed points failed the re-check: "
                "not certifiable at this gamma cap, no points added"
            )
            return status, xv, points, checked
        add = new if working_set is None else new[: int(working_set)]
        if progress:
            progress(
                f"analysis LMI: re-check of all {m} points x {n_vertices} vertices: "
                f"{len(failing)} fail; adding {len(add)} points"
            )
        notes.append(f"working set {len(points)} points: {len(failing)} failed the re-check")
        points = np.union1d(points, add)


def _spread_order(rho_hat: Array) -> NDArray[np.int64]:
    """Points in farthest-point order, starting from the one nearest the centre (deterministic):
    any prefix is spread evenly over the grid."""
    m = rho_hat.shape[0]
    first = int(np.argmin(np.sum(rho_hat**2, axis=1)))
    order = [first]
    dist = np.sum((rho_hat - rho_hat[first]) ** 2, axis=1)
    for _ in range(m - 1):
        nxt = int(np.argmax(dist))  # ties: lowest index
        order.append(nxt)
        dist = np.minimum(dist, np.sum((rho_hat - rho_hat[nxt]) ** 2, axis=1))
    return np.array(order, dtype=np.int64)


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
    working_set: int | None = None,
    rate_bound: bool = False,
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
        "constant", "affine" or "quadratic" (in rho_hat).
    time_scale_s
        Time unit of the scaled problem (s); default taubar (or 1 s if taubar is 0).
    epsilon
        Strictness margin of every inequality (scaled units).
    backoff
        If > 0, a second solve fixes gamma at (1 + backoff) times the optimum and maximises the
        strictness margin of every LMI (a better-centred certificate); 0 skips it.
    solver_options
        Extra Clarabel settings by name (e.g. ``{"direct_solve_method": "qdldl"}``).
    progress
        Called with a short message before assembly, before each solve and per solver iteration.
    state_transform
        Constant invertible T (n x n) with x = T x_new applied to every system before the solve
        (a congruence: feasibility and gamma are unchanged, conditioning is not). Default: a
        diagonal power-of-two balancing of the centre system.
    gamma_cap
        If given, solve the feasibility form instead: gamma <= gamma_cap, maximise a common
        strictness margin (no back-off); the reported gamma is the solution's own bound.
    working_set
        None: impose the LMI at every point in one solve (the straightforward formulation). An
        integer k: impose it (all rate vertices) at k points spread over the grid, re-check every
        point and vertex, add up to k of the points that fail, solve again, until the re-check
        passes or every point is imposed. P(rho_k) > 0 is imposed at every point in every round.
        Either way ``certified`` is the floating-point re-check at every point and vertex.
    rate_bound
        Solve the rate-bound form first (one LMI per point with slacks Z_i >= +/- nu_i dP/drho_i
        in place of the rate vertices, see :func:`_bound_parts`): sufficient for the vertex LMIs,
        eight times fewer PSD blocks for three moving parameters. If its solution does not pass
        the re-check of every vertex, the vertex form is solved as without this option.

    Returns
    -------
    AnalysisResult
    """
    import clarabel

    t_start = time.perf_counter()
    rho_hat, rate, dtau, tau_max, taus = checked_inputs(
        systems, rho_hat, rate_hat_per_s, dtau_drho_hat_s, tau_max_s, p_dependence
    )
    m, s = rho_hat.shape
    points = first_points(rho_hat, working_set)
    ts = float(time_scale_s) if time_scale_s is not None else (tau_max if tau_max > 0 else 1.0)
    n = systems[0].n

    tx, txi = transform_of(systems, ts, state_transform)

    # rate vertices: only parameters that move and matter (P affine, or the delay depends on them)
    moving = [i for i in range(s) if rate[i] > 0 and (p_dependence != "constant" or dtau[i] != 0.0)]
    vertices = np.array(
        [
            [dict(zip(moving, sig, strict=True)).get(i, 0.0) for i in range(s)]
            for sig in itertools.product((-1.0, 1.0), repeat=len(moving))
        ]
    ).reshape(-1, s)
    # P(rho) = P0 + sum_i rho_i P_i1 (+ 1/2 sum_i rho_i^2 P_i2): value and d/drho_i weights
    p_terms: list = [(lambda r: np.ones(r.shape[0]), None)]
    if p_dependence != "constant":
        p_terms += [(lambda r, i=i: r[:, i], (i, lambda r: np.ones(r.shape[0]))) for i in range(s)]
    if p_dependence == "quadratic":
        p_terms += [
            (lambda r, i=i: 0.5 * r[:, i] ** 2, (i, lambda r, i=i: r[:, i])) for i in range(s)
        ]
    sym, ns = _sym_index(n)
    pr = _Problem(
        a=np.stack([ts * txi @ q.A @ tx for q in systems]),
        ad=np.stack([ts * txi @ q.Ad @ tx for q in systems]),
        b=np.stack([ts * txi @ q.B for q in systems]),
        c=np.stack([q.C @ tx for q in systems]),
        cd=np.stack([q.Cd @ tx for q in systems]),
        d=np.stack([q.D for q in systems]),
        rho_hat=rho_hat,
        vertices=vertices,
        rate_s=rate * ts,
        dtau_rate=rate * dtau,
        tbar=tau_max / ts,
        p_terms=p_terms,
        sym=sym,
        ns=ns,
    )
    nv, size, nvar, var_g = len(vertices), pr.size, pr.nvar, pr.var_g
    kk = m * nv
    nsv = size * (size + 1) // 2
    if progress:
        progress(f"analysis LMI: assembling {kk} LMIs of size {size} ({m} points x {nv} vertices)")
    # the map of every LMI, assembled a few points at a time (bounded intermediate arrays)
    chunk = max(1, 64 // nv)
    parts = [_lmi_map(pr, np.arange(i, min(m, i + chunk))) for i in range(0, m, chunk)]
    fmat = sp.vstack([f for f, _ in parts], format="csr")
    f0 = np.concatenate([c0 for _, c0 in parts])
    del parts
    pmat = _p_map(pr)
    eye_lmi, eye_p = svec_eye(size), svec_eye(n)
    notes: list[str] = []
    opts = {"chordal_decomposition_enable": False, **(solver_options or {})}

    def _gam(mu: float) -> float:
        return float(np.sqrt(max(mu, 0.0)))

    def _recheck(xv: Array) -> tuple[bool, Array, Array]:
        # the certificate is the floating-point re-check of every point and vertex, not the
        # solver's word: "optimal_inaccurate" with every LMI negative definite certifies
        lmi_val = unsvec((fmat @ xv + f0).reshape(kk, nsv), size)
        margins = -np.linalg.eigvalsh(lmi_val)[:, -1].reshape(m, nv).max(axis=1)
        p_val = unsvec((pmat @ xv).reshape(m + 2, -1)[:m], n)
        p_min = np.linalg.eigvalsh(p_val)[:, 0]
        tol = 1e-10 * max(1.0, float(np.max(np.abs(lmi_val))))
        return bool(np.all(margins > tol) and np.all(p_min > 0)), margins, p_min

    def _solve(
        points: NDArray[np.int64], form: str, bound: bool, mu_fix: float = 0.0
    ) -> tuple[str, Array | None, float]:
        # z = [x, Z, t]; LMI + eps I + t I <= 0 (t absent in the "min" form; Z only in the
        # rate-bound form); P(rho_k), Q, R >= eps I at every point
        if bound:
            lmi_map, lmi_f0, z_map, nzz = _bound_parts(pr, points)
            n_lmi = len(points)
        else:
            rows = (points[:, None] * (nv * nsv) + np.arange(nv * nsv)[None, :]).reshape(-1)
            lmi_map, lmi_f0, z_map, nzz = fmat[rows], f0[rows], None, 0
            n_lmi = len(points) * nv
        with_t = form != "min"
        it = nvar + nzz  # index of t
        ncol = it + int(with_t)

        def pad(mat: sp.spmatrix) -> sp.csr_matrix:
            return sp.hstack([mat, sp.csr_matrix((mat.shape[0], ncol - mat.shape[1]))], "csr")

        eyes = np.tile(eye_lmi, n_lmi)
        a_blocks = [pad(sp.hstack([lmi_map, sp.csr_matrix(eyes[:, None])]) if with_t else lmi_map)]
        b_blocks = [-(lmi_f0 + epsilon * eyes)]
        cones = [clarabel.PSDTriangleConeT(size)] * n_lmi
        a_blocks.append(pad(-pmat))
        b_blocks.append(-epsilon * np.tile(eye_p, m + 2))
        cones += [clarabel.PSDTriangleConeT(n)] * (m + 2)
        if z_map is not None:  # Z_{p,i} -/+ nu_i dP/drho_i >= 0
            a_blocks.append(pad(-z_map))
            b_blocks.append(np.zeros(z_map.shape[0]))
            cones += [clarabel.PSDTriangleConeT(n)] * (z_map.shape[0] // len(eye_p))
        q = np.zeros(ncol)
        unit = sp.csr_matrix(([1.0], ([0], [var_g])), shape=(1, ncol))
        if form == "min":
            q[var_g] = 1.0
        else:
            q[it] = -1.0
            t_row = sp.csr_matrix(([1.0], ([0], [it])), shape=(1, ncol))
            if form == "cap":  # mu <= cap^2, t <= 1
                a_blocks += [sp.vstack([unit, t_row])]
                b_blocks += [np.array([float(gamma_cap) ** 2, 1.0])]
                cones += [clarabel.NonnegativeConeT(2)]
            else:  # back-off: mu fixed, t <= 1
                a_blocks += [unit, t_row]
                b_blocks += [np.array([mu_fix]), np.array([1.0])]
                cones += [clarabel.ZeroConeT(1), clarabel.NonnegativeConeT(1)]
        label = f"analysis LMI ({len(points)}/{m} points{', rate bound' if bound else ''})"
        if progress:
            progress(f"{label}: solving {n_lmi} LMIs, {ncol} variables with Clarabel")
        sol = solve_conic(
            q,
            sp.vstack(a_blocks, format="csc"),
            np.concatenate(b_blocks),
            cones,
            opts,
            progress,
            label,
        )
        if sol.status == "solver_error":
            notes.append(f"Clarabel ended {sol.clarabel_status}")
        t_val = float(sol.x[it]) if sol.x is not None and with_t else 0.0
        return sol.status, None if sol.x is None else sol.x[:nvar], t_val

    def _round(points: NDArray[np.int64], bound: bool) -> tuple[str, Array | None]:
        if gamma_cap is not None:
            # feasibility form: gamma bounded, maximise a common strictness margin t (<= 1);
            # measured more robust than minimising gamma when the points differ widely in scale
            status, xv, t_val = _solve(points, "cap", bound)
            if xv is not None:
                notes.append(
                    f"feasibility form: gamma <= {float(gamma_cap):.4g}, margin t = {t_val:.3g}"
                )
            return status, xv
        status, xv, _ = _solve(points, "min", bound)
        if backoff > 0.0 and xv is not None and not _recheck(xv)[0]:
            # second solve: gamma fixed a little above the optimum, maximise the strictness
            # margin; this moves the certificate off the boundary where the tolerances live
            mu_b = (1 + backoff) * float(xv[var_g])
            if progress:
                progress(f"analysis LMI: back-off solve at gamma = {_gam(mu_b):.4g}")
            status2, xb, t_val = _solve(points, "backoff", bound, mu_b)
            if xb is None:
                notes.append(f"back-off solve ended {status2}; kept the first solution")
            else:
                status, xv = status2, xb
                notes.append(
                    f"back-off: gamma {_gam(mu_b / (1 + backoff)):.6g} -> "
                    f"{_gam(mu_b):.6g}, common margin t = {t_val:.3g}"
                )
        return status, xv

    certified = False
    for bound in (True, False) if rate_bound else (False,):
        status, xv, points, (certified, margins, p_min) = grow_working_set(
            points,
            working_set,
            lambda pts, bound=bound: _round(pts, bound),
            _recheck,
            notes,
            progress,
            nv,
        )
        if certified:
            break
        if bound:  # the sufficient rate-bound form did not certify: the vertex form decides
            notes.append(f"rate-bound form not certified ({status}); solved the vertex form")
            if progress:
                progress("analysis LMI: rate-bound form not certified; solving every rate vertex")
    if rate_bound and certified and bound:
        notes.append("solved in the rate-bound form, re-checked at every rate vertex")
    elapsed = time.perf_counter() - t_start
    if xv is None:
        nan = np.full(m, np.nan)
        return AnalysisResult(False, status, None, nan, nan, kk, elapsed, p_dependence, notes)
    if working_set is not None:
        notes.append(f"working set: LMI imposed at {len(points)} of {m} points")
    p0m = xv[sym]  # P0 (the first basis term); sym maps (c, d) and (d, c) to the entry
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
