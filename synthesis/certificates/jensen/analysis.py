"""Delay-dependent analysis LMI for a gridded closed-loop LPV delay system (verification side).

Condition: Theorem 1 of the paper (Zope et al. 2012; Jensen-type Lyapunov-Krasovskii functional
``V = x'P(rho)x + int_{t-tau}^t x'Qx + taubar int_{-taubar}^0 int_{t+theta}^t xdot'R xdot``). For
the closed loop ``dx/dt = A x + Ad x(t - tau(rho)) + B w``, ``z = C x + Cd x(t - tau) + D w`` with 0
<= tau <= taubar it requires, at every grid point and every rate vertex sigma in {-1, +1}^s::

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
gives the equivalent, smaller (2n + n_w instead of 3n + n_w + n_z) LMI linear in (P, Q, R, mu =
g^2)::

    [ He(P A) + dP + Q - R   P Ad + R            P B   ]
    [ *                      -(1 - dtau) Q - R   0     ] + taubar^2 Psi' R Psi + Gamma' Gamma < 0
    [ *                      *                   -mu I ]

with Psi = [A Ad B], Gamma = [C Cd D]; the reported gamma is sqrt(mu).

Choices (this module is independent of the synthesis LMI in :mod:`pressor.synthesis.families.theorem3.lmi`):

* ``P(rho)`` constant, affine, or quadratic in the normalised parameters rho_hat in [-1, 1]^s
  (quadratic = the synthesis basis ``P0 + sum rho_i P_i1 + 1/2 sum rho_i^2 P_i2``, so
  ``dP/dt = sum (P_i1 + rho_i P_i2) rho_i-dot``); Q, R constant. ``verify`` uses quadratic.
* A constant state transform ``state_transform`` (a congruence: feasibility and gamma unchanged)
  may replace the default diagonal balancing; ``verify`` whitens then balances
  (:func:`pressor.synthesis.certificates.state_transform.conditioning_transform`, which records the
  measurements).
* ``gamma_cap``: feasibility form (gamma <= cap, maximise a common strictness margin t <= 1),
  more robust on the dense grid than minimising gamma; ``verify`` uses it.
* ``taubar`` is the largest delay of the box (``tau_max_s``) at every point, as in the paper.
* Numerics: time is scaled by ``time_scale_s`` and the states by a constant diagonal
  balancing of the centre system (powers of two); both leave the L2 gain unchanged.
* Build and solve: each LMI's exact affine map is assembled densely a few points at a time
  (structural zeros stay exact) straight into Clarabel's PSD-triangle order, and Clarabel is
  called on that conic data directly (:mod:`pressor.synthesis.solver.conic`, which also reports every
  iteration); going through cvxpy instead (one batched PSD constraint over a full-matrix map) costs
  far more time and memory (docs/notes/benchmarks.md, "Design measurements").
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
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from pressor.synthesis.certificates.interface import AnalysisResult, checked_inputs
from pressor.synthesis.certificates.jensen.lmi_map import (
    AnalysisProblem,
    bound_parts,
    lmi_map,
    p_map,
    sym_index,
)
from pressor.synthesis.certificates.state_transform import transform_of
from pressor.synthesis.certificates.working_set import (
    BackOff,
    Formulation,
    Solution,
    Steps,
    first_points,
    solve_and_recheck,
)
from pressor.synthesis.problem.basis import basis_terms, term_parameters
from pressor.synthesis.problem.closed_loop import DelaySystem
from pressor.synthesis.solver.conic import solve_conic, svec_eye, unsvec

__all__ = ["analyse"]

Array = NDArray[np.float64]


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
        in place of the rate vertices, see :func:`bound_parts`): sufficient for the vertex LMIs,
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
    w_p, dw_p = basis_terms(rho_hat, p_dependence)
    sym, ns = sym_index(n)
    pr = AnalysisProblem(
        a=np.stack([ts * txi @ q.A @ tx for q in systems]),
        ad=np.stack([ts * txi @ q.Ad @ tx for q in systems]),
        b=np.stack([ts * txi @ q.B for q in systems]),
        c=np.stack([q.C @ tx for q in systems]),
        cd=np.stack([q.Cd @ tx for q in systems]),
        d=np.stack([q.D for q in systems]),
        w_p=w_p,
        dw_p=dw_p,
        p_params=term_parameters(p_dependence, range(s)),
        vertices=vertices,
        rate_s=rate * ts,
        dtau_rate=rate * dtau,
        tbar=tau_max / ts,
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
    parts = [lmi_map(pr, np.arange(i, min(m, i + chunk))) for i in range(0, m, chunk)]
    fmat = sp.vstack([f for f, _ in parts], format="csr")
    f0 = np.concatenate([c0 for _, c0 in parts])
    del parts
    pmat = p_map(pr)
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
            lmi_f, lmi_f0, z_map, nzz = bound_parts(pr, points)
            n_lmi = len(points)
        else:
            rows = (points[:, None] * (nv * nsv) + np.arange(nv * nsv)[None, :]).reshape(-1)
            lmi_f, lmi_f0, z_map, nzz = fmat[rows], f0[rows], None, 0
            n_lmi = len(points) * nv
        with_t = form != "min"
        it = nvar + nzz  # index of t
        ncol = it + int(with_t)

        def pad(mat: sp.spmatrix) -> sp.csr_matrix:
            return sp.hstack([mat, sp.csr_matrix((mat.shape[0], ncol - mat.shape[1]))], "csr")

        eyes = np.tile(eye_lmi, n_lmi)
        a_blocks = [pad(sp.hstack([lmi_f, sp.csr_matrix(eyes[:, None])]) if with_t else lmi_f)]
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
        notes.extend(sol.notes)
        t_val = float(sol.x[it]) if sol.x is not None and with_t else 0.0
        return sol.status, None if sol.x is None else sol.x[:nvar], t_val

    def _formulation(bound: bool) -> Formulation:
        def cap_solve(pts: NDArray[np.int64]) -> tuple[str, Array | None]:
            # feasibility form: gamma bounded, maximise a common strictness margin t (<= 1);
            # measured more robust than minimising gamma when the points differ widely in scale
            status, xv, t_val = _solve(pts, "cap", bound)
            if xv is not None:
                notes.append(
                    f"feasibility form: gamma <= {float(gamma_cap):.4g}, margin t = {t_val:.3g}"
                )
            return status, xv

        def back_off(pts: NDArray[np.int64], xv: Array) -> tuple[str, Array | None, str]:
            # gamma fixed a little above the optimum, maximise the strictness margin; this moves
            # the certificate off the boundary where the tolerances live
            mu_b = (1 + backoff) * float(xv[var_g])
            if progress:
                progress(f"analysis LMI: back-off solve at gamma = {_gam(mu_b):.4g}")
            status, xb, t_val = _solve(pts, "backoff", bound, mu_b)
            return (
                status,
                xb,
                f"back-off: gamma {_gam(mu_b / (1 + backoff)):.6g} -> "
                f"{_gam(mu_b):.6g}, common margin t = {t_val:.3g}",
            )

        backs_off = gamma_cap is None and backoff > 0.0
        return Formulation(
            cap_solve if gamma_cap is not None else lambda pts: _solve(pts, "min", bound)[:2],
            back_off=BackOff(lambda _pts, xv: not _recheck(xv)[0], back_off) if backs_off else None,
            if_not_certified=_vertex_form_next if bound else None,
            note_if_certified=(
                "solved in the rate-bound form, re-checked at every rate vertex" if bound else None
            ),
        )

    def _vertex_form_next(status: str) -> None:
        # the sufficient rate-bound form did not certify: the vertex form decides
        notes.append(f"rate-bound form not certified ({status}); solved the vertex form")
        if progress:
            progress("analysis LMI: rate-bound form not certified; solving every rate vertex")

    def _solution(xv: Array) -> Solution:
        p0m = xv[sym]  # P0 (the first basis term); sym maps (c, d) and (d, c) to the entry
        return _gam(float(xv[var_g])), txi.T @ p0m @ txi, None

    steps = Steps(
        [_formulation(bound) for bound in ((True, False) if rate_bound else (False,))],
        _recheck,
        _solution,
        nv,
    )
    return solve_and_recheck(steps, points, working_set, m, p_dependence, t_start, notes, progress)
