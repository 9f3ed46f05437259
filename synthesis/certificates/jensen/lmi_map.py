"""The affine maps of the Theorem-1 analysis LMIs, in Clarabel's PSD-triangle order.

The LMI of :mod:`pressor.synthesis.certificates.jensen.analysis` (solved form, rescaled by gamma) is affine
in the decision vector ``x = [P terms, Q, R, mu]``. Each LMI's exact map ``svec(LMI) = F x + f0`` is
assembled densely a few points at a time (structural zeros stay exact) straight into the order
Clarabel's PSD cones use (:func:`pressor.synthesis.solver.conic.svec_rows`): :func:`lmi_map` for every rate
vertex (or the rate-bound form), :func:`bound_parts` for the rate-bound slacks, :func:`p_map` for
P(rho_k), Q, R.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from pressor.synthesis.solver.conic import svec_rows

__all__ = ["AnalysisProblem", "bound_parts", "lmi_map", "p_map", "sym_index"]

Array = NDArray[np.float64]


def sym_index(n: int) -> tuple[NDArray[np.int64], int]:
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


@dataclass(frozen=True)
class AnalysisProblem:
    """The scaled data of one analysis problem (every point, every rate vertex)."""

    a: Array  # (m, n, n) scaled, transformed closed loops
    ad: Array
    b: Array
    c: Array
    cd: Array
    d: Array
    w_p: Array  # (m, n_p) P basis weights at every point (pressor.synthesis.problem.basis)
    dw_p: Array  # (m, n_p, s) their derivatives in rho_hat
    p_params: tuple[int | None, ...]  # the parameter each P basis term depends on
    vertices: Array  # (nv, s) rate signs
    rate_s: Array  # (s,) |d rho_hat / d t_hat|
    dtau_rate: Array  # (s,) rate * d tau / d rho_hat (s/s)
    tbar: float
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
        return self.w_p.shape[1] * self.ns

    @property
    def var_g(self) -> int:
        return self.off_q + 2 * self.ns

    @property
    def nvar(self) -> int:
        return self.var_g + 1


def lmi_map(
    pr: AnalysisProblem, points: NDArray[np.int64], bound: bool = False
) -> tuple[sp.csr_matrix, Array]:
    """Affine map of the LMIs at ``points`` (all rate vertices of each, point-major order):
    ``svec(LMI) = F x + f0`` in Clarabel's PSD-triangle order (see
    :func:`pressor.synthesis.solver.conic.svec_rows`).

    ``bound``: one matrix per point, without dP/dt and with ``-(1 - dtau_max) Q`` (the rate-bound
    form adds the slack Z terms, :func:`bound_parts`).
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
    for j in range(pr.w_p.shape[1]):
        w = pr.w_p[points, j]
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
    eye = np.broadcast_to(np.eye(n), (npt * nv, n, n))
    for j, i in enumerate(pr.p_params):
        if i is not None:  # dP/dt = sum_i (d P / d rho_i) * rho_i-dot at this rate vertex
            dw = np.repeat(pr.dw_p[points, j, i], nv)
            asm.add_mvn(eye, eye, j * ns, sym, r1, r1, dw * sig[:, i] * pr.rate_s[i])
    asm.add_mvn(eye, eye, off_q, sym, r2, r2, sig @ pr.dtau_rate)  # dtau/dt (s/s, scale-free)
    return asm.svec()


def bound_parts(
    pr: AnalysisProblem, points: NDArray[np.int64]
) -> tuple[sp.csr_matrix, Array, sp.csr_matrix, int]:
    """Rate-bound form at ``points`` (the synthesis' "bound" treatment of the rate vertices).

    Per point p and moving parameter i a symmetric slack Z_{p,i} >= +/- nu_i dP/drho_i(rho_p), and
    one LMI per point with dP/dt replaced by sum_i Z_{p,i} and -(1 - dtau_max) Q: it bounds every
    vertex LMI of the point from above, so it implies them (sufficient, can be more conservative).

    Returns ``(F, f0, G, nz)`` over the variables ``[x, Z]`` (Z after the nvar entries of x, nz of
    them): ``svec(LMI_p) = F [x; Z] + f0`` and ``svec(Z_{p,i} -/+ nu_i dP_i) = G [x; Z]`` (>= 0).
    """
    n, ns, nvar, npt = pr.n, pr.ns, pr.nvar, len(points)
    terms = [(j, i) for j, i in enumerate(pr.p_params) if i is not None]
    moving = sorted({i for _j, i in terms if pr.rate_s[i] > 0})
    nmov = len(moving)
    nz = npt * nmov * ns
    size, nsv, nsn = pr.size, pr.size * (pr.size + 1) // 2, n * (n + 1) // 2
    f_x, f0 = lmi_map(pr, points, bound=True)
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
    par = np.tile(np.repeat(np.array(moving), 2), npt)
    sign = np.tile([1.0, -1.0], npt * nmov)
    for j, i in terms:
        dw = np.repeat(pr.dw_p[points, j, i], nmov * 2)
        scale = np.where(par == i, -sign * pr.rate_s[i] * dw, 0.0)
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


def p_map(pr: AnalysisProblem) -> sp.csr_matrix:
    """svec of P(rho_k) at every point (P(rho) = sum_j w_j(rho) P_j), then Q, R: ``F x``."""
    m, n = pr.w_p.shape[0], pr.n
    pasm = _Assembler(m + 2, n, pr.nvar)
    eye = np.broadcast_to(np.eye(n), (m + 2, n, n))
    for j in range(pr.w_p.shape[1]):
        pasm.add_mvn(eye, eye, j * pr.ns, pr.sym, 0, 0, np.r_[pr.w_p[:, j], 0.0, 0.0])
    pasm.add_mvn(eye, eye, pr.off_q, pr.sym, 0, 0, np.r_[np.zeros(m), 1.0, 0.0])
    pasm.add_mvn(eye, eye, pr.off_q + pr.ns, pr.sym, 0, 0, np.r_[np.zeros(m), 0.0, 1.0])
    return pasm.svec()[0]
