"""Delay-dependent analysis LMI with an augmented (Wirtinger-based) Lyapunov-Krasovskii functional.

Why a second analysis: the Jensen functional of :mod:`pressor.synthesis.certificates.jensen.analysis`
(Theorem 1) is nearly tight for the shipped design but nearly blind to delay compensation: a Smith
predictor in the controller class (:mod:`pressor.synthesis.families.smith.law`, loop gain 1.5) is infeasible
for it at frozen points with tau = 27.5 and 45 s and bounded at twice its exact norm at the nominal
point, while this functional bounds the same loops at their exact frozen H-infinity norm (within
solver accuracy; measured figures in docs/notes/certificate-structure.md). Reference: Seuret & Gouaisbaut,
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
and rate vertex, rescaled by gamma as in the Jensen analysis (mu = gamma^2)::

    He(G1' P G0) + G1' dP G1 + Ex'S Ex - (1 - dtau) Eh'S Eh + taubar^2 Ga'R Ga
      - (taubar/tau)(E1'R E1 + 3 E2'R E2) - mu Ew'Ew + Gz'Gz  <  0,   P(rho) > 0, S > 0, R > 0

with ``G1 zeta = xi``, ``G0 zeta = dxi/dt``, ``Ga = [A Ad 0 B]``, ``Gz = [C Cd 0 D]`` and the
selectors Ex, Eh, E1, E2, Ew of x, x_tau, e1, e2, w. Then the closed loop is asymptotically stable
for every parameter trajectory in the gridded box with the rate bounds (up to gridding) and its
L2 gain w -> z is below gamma. P(rho) is in the basis of the Jensen analysis (constant, affine or
quadratic in rho_hat, optionally in a subset of the parameters); S, R constant.

Rate forms and cost (:mod:`.conic`): the vertex LMI is affine in the rate vertex,
``L0 + sum_i sigma_i M_i`` (:mod:`.lmi`).
``rate_form="vertex"`` imposes all 2^s' vertices (s' moving parameters); ``rate_form="bound"``
imposes ONE LMI per point, ``L0 + sum_i Z_i < 0`` with slacks ``Z_i >= +/- M_i`` on the rows where
M_i lives, which implies every vertex LMI (``sigma_i M_i <= Z_i`` for |sigma_i| <= 1).
``coupling="per_point"`` gives each imposed point its own copy of P(rho_k) and of its rate terms,
tied to the basis by equalities, so the PSD blocks stop coupling all basis terms densely.
``p_params`` lets P depend on a subset of the parameters (fewer variables; a parameter P does not
depend on and the delay does not depend on needs no rate vertex). Whatever the form, the certificate
is the floating-point re-check of EVERY vertex LMI at EVERY grid point, P(rho_k) > 0, S > 0, R > 0.
Clarabel is called on the conic data directly (:mod:`pressor.synthesis.solver.conic`, one progress line per
iteration). Scaling, state transform, strictness margins, the feasibility form (``gamma_cap``) and
the working set (``working_set``) are those of the Jensen analysis; the result type is the same.

K-scaled coordinates (``k_scaling``, :mod:`pressor.synthesis.certificates.wirtinger.k_scaling`): the same
functional written in ``x~ = D(K) x`` (the ml/h states times K), i.e. ``V = xi~' P~(rho) xi~ + int
x~'S~x~ + taubar int int dx~'R~ dx~`` with ``x~(s) = D(K(s)) x(s)`` inside the integrals: S, R
constant in x~ are K(s)-dependent in x. x~ obeys a delay system whose matrices also depend on
``kappa = dK/dt / K`` and ``r = K(t)/K(t - tau)``::

    Ga(sigma) = [A~ + sigma_K kappa_max Pi,  Ad~(r_c) + sigma_r dr Ad~ Pi,  0,  B~] = Ga0 + sum_i sigma_i Delta_i

(``Ad~(r_c)``: Ad at the centre r_c of the point's r interval, half-width dr). Wirtinger's
inequality holds for any absolutely continuous x~, so the derivation above holds verbatim for the
x~ system, and the condition at a point and a rate vertex sigma (now also sigma_r) is the one
above with G0, Ga at sigma. It is affine in sigma except ``taubar^2 Ga' R Ga``, which is
matrix-convex in sigma (R > 0), so the whole LMI is matrix-convex in sigma: negative definite at
every vertex of the sigma box implies negative definite at every sigma inside (every rate, every
r in the interval). The solve uses ``Ga'RGa <= Ga0'RGa0 + He(Ga0'R sum_i sigma_i Delta_i) + q sum_i
Delta_i'R Delta_i`` (Cauchy-Schwarz, q = 2 nonzero directions, |sigma_i| <= 1), affine in sigma;
the vertex form imposes that at every vertex. The bound form keeps the slacks Z_i of the P and
tau rates; the kappa and r terms are ``sigma_j He(W_j Phi_j)`` with ``W_j = (G1' P[:, :n] +
taubar^2 Ga0' R) U_j`` linear in the variables and ``Phi_j`` data of n_s rows (``Delta_j = U_j
Phi_j``, n_s the scaled states), and Young's inequality ``sigma He(W Phi) <= W W'/e + e Phi'Phi``
(|sigma| <= 1, e > 0) with a Schur complement turns them into one block per point::

    [[L0 + sum_i E_i'Z_i E_i + e_1 Phi_1'Phi_1 + e_2 Phi_2'Phi_2,  W_1,      W_2     ],
     [W_1',                                                       -e_1 I,   0       ],
     [W_2',                                                       0,        -e_2 I  ]]  <=  -eps I

(2 n_s more rows instead of two full slacks). The re-check (the verdict) evaluates the exact LMI
at every vertex of every grid point. Then V is a
Lyapunov-Krasovskii functional of the x~ system along every admissible trajectory, with L2 gain
w -> z below gamma; since ``x = D(K)^-1 x~`` with K in [K_min, K_max] > 0, the original closed
loop is asymptotically stable with the same gain bound (z and w are not rescaled).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pressor.synthesis.certificates.interface import AnalysisResult, checked_inputs
from pressor.synthesis.certificates.wirtinger.conic import build_conic, vertices_of
from pressor.synthesis.certificates.wirtinger.k_scaling import KScaling
from pressor.synthesis.certificates.wirtinger.lmi import WirtingerData, prepare, sym, vertex_lmis
from pressor.synthesis.certificates.working_set import (
    BackOff,
    Formulation,
    Solution,
    Steps,
    first_points,
    solve_and_recheck,
)
from pressor.synthesis.problem.closed_loop import DelaySystem
from pressor.synthesis.solver.conic import solve_conic

__all__ = ["analyse_wirtinger", "recheck_certificate"]

Array = NDArray[np.float64]


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
    rate_form: str = "vertex",
    coupling: str = "dense",
    p_params: Sequence[int] | None = None,
    backoff: float = 0.02,
    k_scaling: KScaling | None = None,
) -> AnalysisResult:
    """Solve the Wirtinger-based analysis LMI over a set of frozen closed loops.

    Parameters are those of :func:`pressor.synthesis.certificates.jensen.analysis.analyse`, plus the ones
    below. Every delay must be > 0 (the functional divides by tau) and <= ``tau_max_s``.
    ``working_set=k`` imposes the LMI at k spread points, re-checks every point and vertex in
    floating point and adds up to k failing points per round (with ``gamma_cap`` it stops as soon as
    an imposed point fails: that cap is then infeasible for the whole grid too); ``certified`` is
    that re-check either way.

    Parameters
    ----------
    rate_form
        "vertex" (every rate vertex of every imposed point) or "bound" (one LMI per point with
        rate slacks; sufficient for every vertex), see
        :mod:`pressor.synthesis.certificates.wirtinger.conic`.
    coupling
        "dense" (LMIs written in the P basis terms) or "per_point" (a copy of P(rho_k) and its
        rate terms per imposed point, tied by equalities): the same feasible set, a sparser solve.
    p_params
        Indices of the parameters P depends on (default all); ignored for "constant".
    backoff
        If the minimum-gamma solution fails the re-check at an imposed point (it sits on the
        boundary), solve again with gamma <= (1 + backoff) times that optimum, maximising the
        common margin; 0 skips it. Not used with ``gamma_cap``.
    k_scaling
        None (the functional in the systems' own coordinates) or the K-scaled functional (see
        above): K per point, its rate bound and the ml/h states. ``state_transform``, ``p0_phys``
        and the certificate are then in the K-scaled coordinates x~.

    Returns
    -------
    AnalysisResult
        ``n_lmis`` counts the re-checked vertex LMIs (points x rate vertices of the moving
        parameters). ``certificate`` holds ``P`` (n_p, 2n, 2n) on ``xi = [x; int x]``, ``S``,
        ``R`` (divided by gamma), ``transform`` and ``time_scale_s``.
    """
    t_start = time.perf_counter()
    data, rho_hat = _prepared(
        systems,
        rho_hat,
        rate_hat_per_s,
        dtau_drho_hat_s,
        tau_max_s,
        p_dependence,
        p_params,
        time_scale_s,
        state_transform,
        k_scaling,
    )
    m = rho_hat.shape[0]
    points = first_points(rho_hat, working_set)
    verts = vertices_of(data)
    nv = len(verts)
    n, n2, ns, ns2, nvar = data.n, 2 * data.n, data.ns, data.ns2, data.nvar
    off_s = data.n_p * ns2
    notes: list[str] = []
    opts = {"chordal_decomposition_enable": False, **(solver_options or {})}

    def solve_once(pts: NDArray[np.int64], cap: float | None) -> tuple[str, Array | None]:
        if progress:
            progress(f"Wirtinger LMI: assembling {len(pts)} points ({rate_form}, {coupling})")
        q, a, b, cones, ncol, n_psd = build_conic(data, pts, rate_form, coupling, epsilon, cap)
        label = f"Wirtinger LMI ({len(pts)}/{m} points, {rate_form})"
        if progress:
            progress(f"{label}: solving {n_psd} PSD blocks, {ncol} variables with Clarabel")
        sol = solve_conic(q, a, b, cones, opts, progress, label)
        notes.extend(sol.notes)
        if sol.x is not None and cap is not None:
            notes.append(f"feasibility form: gamma <= {cap:.4g}, margin t = {sol.x[-1]:.3g}")
        return sol.status, None if sol.x is None else sol.x[:nvar]

    recheck_tol = [0.0]  # the last re-check's strictness tolerance (scaled to the LMI's size)

    def recheck(xv: Array) -> tuple[bool, Array, Array]:
        certified, margins, p_min, recheck_tol[0] = _recheck(data, xv)
        return certified, margins, p_min

    def off_boundary(pts: NDArray[np.int64], xv: Array) -> bool:
        _, margins, p_min = recheck(xv)
        return not (
            np.all(margins[pts] > recheck_tol[0]) and np.all(p_min > 0) and _sr_positive(data, xv)
        )

    def back_off(pts: NDArray[np.int64], xv: Array) -> tuple[str, Array | None, str]:
        # the optimum sits on the boundary (in the bound form the slack cones Z_i >= +/- M_i
        # too; S or R may end singular): back off gamma by a few percent and maximise the
        # common margin instead
        cap = float(np.sqrt(max(float(xv[-1]), 0.0))) * (1.0 + backoff)
        if progress:
            progress(f"Wirtinger LMI: back-off solve at gamma = {cap:.4g}")
        status, xb = solve_once(pts, cap)
        return status, xb, f"back-off: gamma {cap / (1.0 + backoff):.6g} -> {cap:.6g}"

    def solution(xv: Array) -> Solution:
        gamma = float(np.sqrt(max(float(xv[-1]), 0.0)))
        g = max(gamma, 1e-300)
        certificate = {
            "P": sym(xv[:off_s].reshape(data.n_p, ns2), n2) / g,
            "S": sym(xv[off_s : off_s + ns], n) / g,
            "R": sym(xv[off_s + ns : off_s + 2 * ns], n) / g,
            "transform": data.tx,
            "time_scale_s": data.time_scale_s,
        }
        if k_scaling is not None:
            certificate["k_scaled_states"] = tuple(k_scaling.states)
        p0 = sym(xv[:ns2], n2)[:n, :n]
        return gamma, data.txi.T @ p0 @ data.txi, certificate

    closing_notes: list[str] = []
    if rate_form == "bound":
        closing_notes.append("rate-bound form (one LMI per point), re-checked at every rate vertex")
    if k_scaling is not None:
        closing_notes.append(f"K-scaled coordinates: states {tuple(k_scaling.states)} times K")
    cap = None if gamma_cap is None else float(gamma_cap)
    formulation = Formulation(
        lambda pts: solve_once(pts, cap),
        back_off=BackOff(off_boundary, back_off) if cap is None and backoff > 0.0 else None,
    )
    steps = Steps(
        [formulation],
        recheck,
        solution,
        nv,
        # with a fixed gamma cap a larger set of points cannot pass when a subset fails
        stop_if_imposed_fails=cap is not None,
        closing_notes=tuple(closing_notes),
    )
    return solve_and_recheck(steps, points, working_set, m, p_dependence, t_start, notes, progress)


def _recheck(data: WirtingerData, xv: Array) -> tuple[bool, Array, Array, float]:
    """The certificate's verdict at the global vector ``xv``: every vertex LMI evaluated in floating
    point at EVERY point of ``data``, P(rho_k) > 0, S > 0, R > 0; (certified, margins (m,),
    smallest eigenvalue of each P(rho_k) (m,), the strictness tolerance used)."""
    verts = vertices_of(data)
    m, nv, n2 = len(data.h), len(verts), 2 * data.n
    lmi_val = vertex_lmis(data, xv, verts)
    lmi_val = 0.5 * (lmi_val + np.swapaxes(lmi_val, -1, -2)).reshape(m * nv, data.big, data.big)
    margins = -np.linalg.eigvalsh(lmi_val)[:, -1].reshape(m, nv).max(axis=1)
    off_s = data.n_p * data.ns2
    pos = np.einsum("mj,jab->mab", data.w_p, sym(xv[:off_s].reshape(data.n_p, data.ns2), n2))
    p_min = np.linalg.eigvalsh(pos)[:, 0]
    tol = 1e-10 * max(1.0, float(np.max(np.abs(lmi_val))))
    certified = bool(np.all(margins > tol) and np.all(p_min > 0) and _sr_positive(data, xv))
    return certified, margins, p_min, tol


def _sr_positive(data: WirtingerData, xv: Array) -> bool:
    off_s, ns, n = data.n_p * data.ns2, data.ns, data.n
    sr_min = min(
        np.linalg.eigvalsh(sym(xv[off_s : off_s + ns], n))[0],
        np.linalg.eigvalsh(sym(xv[off_s + ns : off_s + 2 * ns], n))[0],
    )
    return bool(sr_min > 0)


def recheck_certificate(
    systems: Sequence[DelaySystem],
    rho_hat: Array,
    rate_hat_per_s: Array,
    dtau_drho_hat_s: Array,
    tau_max_s: float,
    certificate: dict[str, Any],
    gamma: float,
    p_dependence: str,
    k_scaling: KScaling | None = None,
) -> tuple[bool, Array]:
    """Re-check a stored certificate (no solve): every vertex LMI at every point, in floating point.

    Parameters
    ----------
    systems, rho_hat, rate_hat_per_s, dtau_drho_hat_s, tau_max_s, p_dependence, k_scaling
        As for :func:`analyse_wirtinger` (P depends on every parameter).
    certificate
        ``P`` (n_p, 2n, 2n), ``S``, ``R`` (n, n), divided by gamma, with the ``transform`` and
        ``time_scale_s`` they live in (what :func:`analyse_wirtinger` returns and an artifact
        stores).
    gamma
        The L2-gain bound the certificate claims (> 0).

    Returns
    -------
    (certified, margins)
        Whether every LMI is negative definite (beyond round-off) and P(rho_k), S, R positive;
        the smallest margin ``-lambda_max`` at each point (scaled units).
    """
    data, _ = _prepared(
        systems,
        rho_hat,
        rate_hat_per_s,
        dtau_drho_hat_s,
        tau_max_s,
        p_dependence,
        None,
        certificate["time_scale_s"],
        np.asarray(certificate["transform"]),
        k_scaling,
    )
    iu = np.triu_indices(data.n)
    iu2 = np.triu_indices(2 * data.n)
    p = np.asarray(certificate["P"], dtype=float)
    if p.shape != (data.n_p, 2 * data.n, 2 * data.n):
        raise ValueError(
            f"certificate P has shape {p.shape}, the analysis needs "
            f"{(data.n_p, 2 * data.n, 2 * data.n)}"
        )
    g = float(gamma)
    xv = np.concatenate(
        [
            (g * p)[:, iu2[0], iu2[1]].ravel(),
            g * np.asarray(certificate["S"], dtype=float)[iu],
            g * np.asarray(certificate["R"], dtype=float)[iu],
            [g * g],
        ]
    )
    certified, margins, _, _ = _recheck(data, xv)
    return certified, margins


def _prepared(
    systems: Sequence[DelaySystem],
    rho_hat: Array,
    rate_hat_per_s: Array,
    dtau_drho_hat_s: Array,
    tau_max_s: float,
    p_dependence: str,
    p_params: Sequence[int] | None,
    time_scale_s: float | None,
    state_transform: Array | None,
    k_scaling: KScaling | None,
) -> tuple[WirtingerData, Array]:
    """The inputs checked (:func:`checked_inputs`, ``p_params``) and the scaled data; and ρ̂."""
    rho_hat, rate, dtau, tau_max, taus = checked_inputs(
        systems,
        rho_hat,
        rate_hat_per_s,
        dtau_drho_hat_s,
        tau_max_s,
        p_dependence,
        zero_delay_ok=False,
    )
    s = rho_hat.shape[1]
    params = tuple(range(s)) if p_params is None else tuple(int(i) for i in p_params)
    if any(not 0 <= i < s for i in params) or len(set(params)) != len(params):
        raise ValueError(f"p_params={p_params!r}: distinct indices in 0..{s - 1} needed")
    ts = float(time_scale_s) if time_scale_s is not None else tau_max
    data = prepare(
        systems,
        rho_hat,
        rate,
        dtau,
        tau_max,
        taus,
        p_dependence,
        params,
        ts,
        state_transform,
        k_scaling,
    )
    return data, rho_hat
