"""The straightforward per-point cvxpy formulation of the same SDP (benchmark baseline only).

One ``cp.bmat`` LMI per grid node (and per rate vertex in "vertices" mode) built from matrix
variables and numeric plant matrices, exactly as one would write it by hand from the paper. It
describes the same problem as :mod:`pressor.synthesis.families.theorem3.lmi` (a test checks the matrices
agree entry by entry at random decision values); it is only slow to compile. Not used by ``pressor
synth``.
"""

from __future__ import annotations

import time

import cvxpy as cp
import numpy as np

from pressor.synthesis.families.theorem3.lmi import N2, Problem
from pressor.synthesis.families.theorem3.lmi_layout import Layout
from pressor.synthesis.families.theorem3.lmi_solve import DEFAULT_SOLVER_OPTS, SolveResult
from pressor.synthesis.problem.model import N_STATE


class NaiveVariables:
    """cvxpy matrix variables mirroring a :class:`~pressor.synthesis.families.theorem3.lmi_layout.Layout`.

    One per basis term.
    """

    def __init__(self, layout: Layout) -> None:
        self.layout = layout
        self.vars: dict[str, list[cp.Variable]] = {}
        for b in layout.blocks:
            self.vars[b.name] = [
                cp.Variable((b.rows, b.cols), symmetric=b.sym, name=f"{b.name}{k}")
                for k in range(b.nb)
            ]

    def set_from(self, x: np.ndarray) -> None:
        """Assign values from a flat decision vector (for cross-checking)."""
        vals = self.layout.unpack(x[None, :])
        for name, vs in self.vars.items():
            for k, v in enumerate(vs):
                v.value = vals[name][0, k]

    def at(self, name: str, w: np.ndarray):
        """The matrix function at basis weights ``w`` (7,) (constant blocks ignore w)."""
        vs = self.vars[name]
        if len(vs) == 1:
            return vs[0]
        return sum(float(w[k]) * vs[k] for k in range(len(vs)) if w[k] != 0.0)


def naive_lmis(prob: Problem, nv: NaiveVariables) -> tuple[list, list]:
    """Per-point expressions: (synthesis LMI matrices F ≺ 0, positivity matrices ≻ 0)."""
    cfg = prob.cfg
    l2, l3 = cfg.solver.lambda2, cfg.solver.lambda3
    tb = prob.tau_bar_hat
    bound = cfg.solver.rate_terms == "bound"
    n = N_STATE
    eye = np.eye(n)
    Fs, Ps = [], []
    Q, R = nv.vars["Q"][0], nv.vars["R"][0]
    for g in range(prob.rho.shape[0]):
        gam = nv.vars["gnode"][g]
        w = prob.weights[g]
        p = {k: v[g] for k, v in prob.plant.items()}
        X, Y = nv.at("X", w), nv.at("Y", w)
        Ah, Adh, Bh = nv.at("Ah", w), nv.at("Adh", w), nv.at("Bh", w)
        Ch, Cdh, Dk = nv.at("Ch", w), nv.at("Cdh", w), nv.at("Dk", w)
        P = nv.at("P", w)
        dP = [
            sum(
                float(prob.dweights[g, i, k]) * nv.vars["P"][k]
                for k in range(7)
                if prob.dweights[g, i, k] != 0.0
            )
            for i in range(3)
        ]
        A, Ad, B1, B2 = p["A"], p["Ad"], p["B1"], p["B2"]
        C1, C1d, C2, C2d = p["C1"], p["C1d"], p["C2"], p["C2d"]
        D11, D12, D21 = p["D11"], p["D12"], p["D21"]
        V = cp.bmat([[Y, eye], [eye, X]])
        cA = cp.bmat([[A @ Y + B2 @ Ch, A + B2 @ Dk @ C2], [Ah, X @ A + Bh @ C2]])
        cAd = cp.bmat([[Ad @ Y + B2 @ Cdh, Ad + B2 @ Dk @ C2d], [Adh, X @ Ad + Bh @ C2d]])
        cB = cp.vstack([B1 + B2 @ Dk @ D21, X @ B1 + Bh @ D21])
        cC = cp.hstack([C1 @ Y + D12 @ Ch, C1 + D12 @ Dk @ C2])
        cCd = cp.hstack([C1d @ Y + D12 @ Cdh, C1d + D12 @ Dk @ C2d])
        cD = D11 + D12 @ Dk @ D21
        nw, nz = B1.shape[1], C1.shape[0]
        Ps.append(P)
        if bound:
            Z = [nv.vars["Z"][3 * g + i] for i in range(3)]
            for i in range(3):
                Ps += [Z[i] - dP[i], Z[i] + dP[i]]
            cases = [(sum(float(prob.nu_hat[i]) * Z[i] for i in range(3)), prob.nu_tau)]
        else:
            cases = [
                (sum(float(s[i] * prob.nu_hat[i]) * dP[i] for i in range(3)), s[2] * prob.nu_tau)
                for s in prob.vertices
            ]
        for pdot, td in cases:
            F = cp.bmat(
                [
                    [tb**2 * R - 2 * V, P - l2 * V + cA, -l3 * V + cAd, cB, np.zeros((N2, nz))],
                    [
                        (P - l2 * V + cA).T,
                        pdot + Q - R + l2 * (cA + cA.T),
                        R + l3 * cA.T + l2 * cAd,
                        l2 * cB,
                        cC.T,
                    ],
                    [
                        (-l3 * V + cAd).T,
                        (R + l3 * cA.T + l2 * cAd).T,
                        -(1 - td) * Q - R + l3 * (cAd + cAd.T),
                        l3 * cB,
                        cCd.T,
                    ],
                    [cB.T, l2 * cB.T, l3 * cB.T, -gam * np.eye(nw), cD.T],
                    [np.zeros((nz, N2)), cC, cCd, cD, -gam * np.eye(nz)],
                ]
            )
            Fs.append(F)
    Ps += [Q, R]
    return Fs, Ps


def solve_naive(prob: Problem, solver_opts: dict | None = None) -> SolveResult:
    """Build the per-point problem and minimise γ with Clarabel (no back-off)."""
    t0 = time.perf_counter()
    nv = NaiveVariables(prob.layout)
    Fs, Ps = naive_lmis(prob, nv)
    eps = prob.cfg.solver.epsilon
    m = Fs[0].shape[0]
    cons = [-(F + F.T) / 2 - eps * np.eye(m) >> 0 for F in Fs]
    cons += [(Pm + Pm.T) / 2 - eps * np.eye(Pm.shape[0]) >> 0 for Pm in Ps]
    gam = nv.vars["gamma"][0]
    gn = nv.vars["gnode"]
    mu = prob.cfg.solver.mean_gamma_weight
    cons += [v <= gam if mu > 0 else v == gam for v in gn]
    obj = gam[0, 0] + mu * sum(v[0, 0] for v in gn) / len(gn) if mu > 0 else gam[0, 0]
    problem = cp.Problem(cp.Minimize(obj), cons)
    problem.get_problem_data(cp.CLARABEL)  # compile now so build time is measured separately
    build = time.perf_counter() - t0
    t1 = time.perf_counter()
    opts = {**DEFAULT_SOLVER_OPTS, **(solver_opts or {})}
    try:
        problem.solve(solver=cp.CLARABEL, **opts)
        status = str(problem.status)
    except cp.error.SolverError as exc:
        status = f"solver_error: {exc}"
    t_solve = time.perf_counter() - t1
    its = problem.solver_stats.num_iters if problem.solver_stats is not None else None
    val = gam.value
    return SolveResult(
        status=status,
        gamma=float(val[0, 0]) if val is not None else float("nan"),
        x=None,
        solve_time_s=t_solve,
        build_time_s=build,
        iterations=its,
        n_lmi=len(Fs),
        lmi_size=m,
    )
