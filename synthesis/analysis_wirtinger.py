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

Build: the LMI is affine in the decision vector; its exact sparse map at the imposed points is
obtained by evaluating the vectorised numeric LMI at unit vectors in chunks (as
:mod:`synthesis.lmi`), in Clarabel's PSD-triangle order, and Clarabel is called on that conic data
directly (:mod:`synthesis.conic`, one progress line per iteration). The re-check evaluates the
same vectorised LMI at the solution for every point and rate vertex, so it never needs the map of
the points left out. Scaling, state transform, strictness margins, the feasibility form
(``gamma_cap``), the working set (``working_set``) and the floating-point re-check are those of
:func:`synthesis.analysis_lmi.analyse`; the result type is the same.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from synthesis.analysis_interface import AnalysisResult, checked_inputs
from synthesis.closed_loop import DelaySystem
from synthesis.conic import solve_conic, svec_eye, svec_rows, unsvec
from synthesis.state_transform import transform_of
from synthesis.working_set import first_points, grow_working_set

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


def _svec_of_triu(n: int) -> sp.csr_matrix:
    """Map from the upper-triangle entries of a symmetric n x n matrix (``np.triu_indices``
    order, as :func:`_sym` reads them) to its Clarabel PSD triangle (:func:`svec_rows`)."""
    tri = np.zeros((n, n), dtype=np.int64)
    tri[np.triu_indices(n)] = np.arange(n * (n + 1) // 2)
    idx, w = svec_rows(n)
    rr, cc = idx // n, idx % n
    return sp.csr_matrix((w, (np.arange(len(idx)), tri[np.minimum(rr, cc), np.maximum(rr, cc)])))


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
    working_set: int | None = None,
    progress: Callable[[str], None] | None = None,
) -> AnalysisResult:
    """Solve the Wirtinger-based analysis LMI over a set of frozen closed loops.

    Parameters are those of :func:`synthesis.analysis_lmi.analyse` (no back-off solve: use
    ``gamma_cap`` for a centred certificate; no rate-bound form). Every delay must be > 0 (the
    functional divides by tau) and <= ``tau_max_s``. ``working_set=k`` imposes the LMI (all rate
    vertices) at k spread points, re-checks every point and vertex in floating point and adds up
    to k failing points per round (with ``gamma_cap`` it stops as soon as an imposed point fails:
    that cap is then infeasible for the whole grid too); ``certified`` is that re-check either way.

    Returns
    -------
    AnalysisResult
        ``certificate`` holds ``P`` (n_p, 2n, 2n) on ``xi = [x; int x]``, ``S``, ``R`` (divided by
        gamma), ``transform`` and ``time_scale_s``.
    """
    import clarabel

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
    points = first_points(rho_hat, working_set)
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
    const = np.einsum("mra,mrb->mab", gz, gz)  # (m, big, big), the same at every vertex

    def linear(x: Array, pts: NDArray[np.int64]) -> Array:
        """The LMI stack's linear part at ``pts`` for decision vectors x (J, nvar):
        (J, len(pts), nv, big, big)."""
        j = x.shape[0]
        g1p, g0p, gap, hp = g1[pts], g0[pts], ga[pts], h[pts]
        pc = _sym(x[:, :off_s].reshape(j, n_p, ns2), n2)
        sm, rm, mu = _sym(x[:, off_s:off_r], n), _sym(x[:, off_r:var_mu], n), x[:, var_mu]
        p = np.einsum("mk,Jkab->Jmab", w_p[pts], pc, optimize=True)
        pdot = np.einsum("mvk,Jkab->Jmvab", dw_v[pts], pc, optimize=True)
        he = np.einsum("mra,Jmrs,mvsb->Jmvab", g1p, p, g0p, optimize=True)
        out = (
            he
            + np.swapaxes(he, -1, -2)
            + np.einsum("mra,Jmvrs,msb->Jmvab", g1p, pdot, g1p, optimize=True)
        )
        out += np.einsum("ra,Jrs,sb->Jab", ex, sm, ex, optimize=True)[:, None, None]
        out -= (1.0 - dtau_dt)[None, None, :, None, None] * np.einsum(
            "ra,Jrs,sb->Jab", eh, sm, eh, optimize=True
        )[:, None, None]
        out += hbar**2 * np.einsum("mra,Jrs,msb->Jmab", gap, rm, gap, optimize=True)[:, :, None]
        wirt = np.einsum("ra,Jrs,sb->Jab", e1, rm, e1, optimize=True) + 3.0 * np.einsum(
            "ra,Jrs,sb->Jab", e2, rm, e2
        )
        out -= (hbar / hp)[None, :, None, None, None] * wirt[:, None, None]
        out -= mu[:, None, None, None, None] * (ew.T @ ew)
        return out

    idx, wsv = svec_rows(big)
    nsv = len(idx)

    def lmi_map(pts: NDArray[np.int64]) -> tuple[sp.csr_matrix, Array]:
        """``svec(LMI) = F x + f0`` at ``pts`` (point-major, then rate vertex), by unit probes."""
        kp = len(pts) * nv
        rows, cols, vals = [], [], []
        for j0 in range(0, nvar, _PROBE_CHUNK):
            js = np.arange(j0, min(nvar, j0 + _PROBE_CHUNK))
            unit = np.zeros((len(js), nvar))
            unit[np.arange(len(js)), js] = 1.0
            full = linear(unit, pts).reshape(len(js), kp, big * big)
            block = (full[:, :, idx] * wsv).reshape(len(js), -1)
            jj, rr = np.nonzero(block)
            rows.append(rr)
            cols.append(js[jj])
            vals.append(block[jj, rr])
        fmat = sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(kp * nsv, nvar),
        )
        f0 = np.repeat(const[pts].reshape(len(pts), big * big)[:, idx] * wsv, nv, axis=0)
        return fmat, f0.reshape(-1)

    # P(rho_k) on xi at every point, then S and R, as svec maps of x (imposed in every round)
    tri2, tri1 = _svec_of_triu(n2), _svec_of_triu(n)
    pmat = sp.block_diag(
        [sp.kron(sp.csr_matrix(w_p), tri2), tri1, tri1, sp.csr_matrix((0, 1))], format="csr"
    )
    eye_lmi, eye2 = svec_eye(big), svec_eye(n2)
    eye_pos = np.concatenate([np.tile(eye2, m), svec_eye(n), svec_eye(n)])
    pos_cones = [clarabel.PSDTriangleConeT(n2)] * m + [clarabel.PSDTriangleConeT(n)] * 2
    notes: list[str] = []
    opts = {"chordal_decomposition_enable": False, **(solver_options or {})}

    def solve(pts: NDArray[np.int64]) -> tuple[str, Array | None]:
        # z = [x, t]: -LMI - eps I >= 0 (min mu), or -LMI - t I >= 0, t <= 1, mu <= cap^2
        # (max t); P(rho_k), S, R >= eps I at every point
        if progress:
            progress(f"Wirtinger LMI: assembling {len(pts) * nv} LMIs of size {big}")
        fmat, f0 = lmi_map(pts)
        n_lmi = len(pts) * nv
        eyes = np.tile(eye_lmi, n_lmi)
        with_t = gamma_cap is not None
        ncol = nvar + int(with_t)
        q = np.zeros(ncol)
        if with_t:
            a_lmi = sp.hstack([fmat, sp.csr_matrix(eyes[:, None])])
            b_lmi = -f0
            rows = sp.csr_matrix(([1.0, 1.0], ([0, 1], [var_mu, nvar])), shape=(2, ncol))
            extra = [(rows, np.array([float(gamma_cap) ** 2, 1.0]), [clarabel.NonnegativeConeT(2)])]
            q[nvar] = -1.0
        else:
            a_lmi, b_lmi, extra = fmat, -(f0 + epsilon * eyes), []
            q[var_mu] = 1.0
        blocks = extra + [
            (-pmat, -epsilon * eye_pos, pos_cones),
            (a_lmi, b_lmi, [clarabel.PSDTriangleConeT(big)] * n_lmi),
        ]

        def pad(mat: sp.spmatrix) -> sp.csr_matrix:
            return sp.hstack([mat, sp.csr_matrix((mat.shape[0], ncol - mat.shape[1]))], "csr")

        label = f"Wirtinger LMI ({len(pts)}/{m} points)"
        if progress:
            progress(f"{label}: solving {n_lmi} LMIs, {ncol} variables with Clarabel")
        sol = solve_conic(
            q,
            sp.vstack([pad(blk[0]) for blk in blocks], format="csc"),
            np.concatenate([blk[1] for blk in blocks]),
            [cone for blk in blocks for cone in blk[2]],
            opts,
            progress,
            label,
        )
        if sol.status == "solver_error":
            notes.append(f"Clarabel ended {sol.clarabel_status}")
        if sol.x is not None and with_t:
            notes.append(
                f"feasibility form: gamma <= {float(gamma_cap):.4g}, margin t = {sol.x[nvar]:.3g}"
            )
        return sol.status, None if sol.x is None else sol.x[:nvar]

    everywhere = np.arange(m)

    def recheck(xv: Array) -> tuple[bool, Array, Array]:
        # the certificate: the LMI evaluated at the solution at EVERY point and rate vertex
        lmi_val = linear(xv[None], everywhere)[0] + const[:, None]
        lmi_val = 0.5 * (lmi_val + np.swapaxes(lmi_val, -1, -2)).reshape(kk, big, big)
        margins = -np.linalg.eigvalsh(lmi_val)[:, -1].reshape(m, nv).max(axis=1)
        pos = unsvec((pmat @ xv)[: m * len(eye2)].reshape(m, -1), n2)
        p_min = np.linalg.eigvalsh(pos)[:, 0]
        sr_min = min(
            np.linalg.eigvalsh(_sym(xv[off_s:off_r], n))[0],
            np.linalg.eigvalsh(_sym(xv[off_r:var_mu], n))[0],
        )
        tol = 1e-10 * max(1.0, float(np.max(np.abs(lmi_val))))
        certified = bool(np.all(margins > tol) and np.all(p_min > 0) and sr_min > 0)
        return certified, margins, p_min

    status, xv, points, (certified, margins, p_min) = grow_working_set(
        points,
        working_set,
        solve,
        recheck,
        notes,
        progress,
        nv,
        stop_if_imposed_fails=gamma_cap is not None,
    )
    elapsed = time.perf_counter() - t_start
    if xv is None:
        nan = np.full(m, np.nan)
        return AnalysisResult(False, status, None, nan, nan, kk, elapsed, p_dependence, notes)
    if working_set is not None:
        notes.append(f"working set: LMI imposed at {len(points)} of {m} points")
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
