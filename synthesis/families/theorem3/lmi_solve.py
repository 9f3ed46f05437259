"""Solving the Theorem-3 synthesis LMI: one batched SDP in cvxpy, Clarabel underneath.

:func:`solve` receives the exact sparse affine maps of the LMI and of the positivity set
(:func:`pressor.synthesis.families.theorem3.lmi.affine_map`) as single batched PSD constraints, minimises γ
and optionally backs off to a better-conditioned solution (``solver.backoff``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from pressor.synthesis.families.theorem3.lmi import Problem, affine_map, positivity, synthesis_lmi
from pressor.synthesis.families.theorem3.lmi_layout import Layout

__all__ = ["DEFAULT_SOLVER_OPTS", "SolveResult", "solve"]


@dataclass
class SolveResult:
    """Outcome of one SDP solve."""

    status: str
    gamma: float
    x: np.ndarray | None
    solve_time_s: float
    build_time_s: float
    iterations: int | None
    n_lmi: int
    lmi_size: int


#: Clarabel tolerances: slightly looser than its 1e-8 defaults, which end in "AlmostSolved" here;
#: every LMI keeps the margin ``epsilon`` anyway and verification re-checks independently.
DEFAULT_SOLVER_OPTS: dict = {"tol_gap_abs": 1e-7, "tol_gap_rel": 1e-6, "tol_feas": 1e-7}


def _run(
    problem, solver_opts: dict, progress: Callable[[str], None] | None = None
) -> tuple[str, float, int | None]:
    import warnings

    import cvxpy as cp

    from pressor.synthesis.solver.conic import solve_cvxpy

    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            # batched (3-D) PSD expressions use cvxpy's SCIPY canonicalisation backend: expected
            warnings.filterwarnings("ignore", message=".*dimension greater than 2.*")
            # Clarabel called on cvxpy's own conic data, so each iteration can be reported
            sol = solve_cvxpy(problem, solver_opts, progress, "solve")
    except cp.error.SolverError as exc:  # numerical failure: report, do not crash
        return f"solver_error: {exc}", time.perf_counter() - t0, None
    return str(problem.status), time.perf_counter() - t0, sol.iterations


def solve(
    prob: Problem,
    solver_opts: dict | None = None,
    verbose: bool = False,
    progress: Callable[[str], None] | None = None,
) -> SolveResult:
    """Build the batched SDP and minimise γ (then optionally back off, see ``solver.backoff``).

    ``progress`` is called with one line per solver iteration (iteration, cost, gap, residuals).

    Returns
    -------
    SolveResult
        ``status`` is cvxpy's status string ("optimal", "infeasible", …); ``x`` the decision vector.
    """
    import cvxpy as cp

    opts = {"verbose": verbose, **DEFAULT_SOLVER_OPTS}
    if solver_opts:
        opts.update(solver_opts)
    t0 = time.perf_counter()
    eps = prob.cfg.solver.epsilon
    lay = prob.layout
    A1, b1, shp1 = affine_map(prob, synthesis_lmi)  # F ≺ 0
    A2, b2, shp2 = affine_map(prob, positivity)  # ≻ 0
    m = shp1[-1]
    n1 = int(np.prod(shp1[:-2]))
    n2 = int(np.prod(shp2[:-2]))
    # Quadratic basis terms of an axis with only two nodes equal a constant on the grid (ρ̂² = 1):
    # they are not identifiable and make the optimal face non-unique, so they are fixed to zero.
    free = lay.free_mask(prob.cfg.grid_points)
    E = sp.identity(lay.nvar, format="csr")[:, np.flatnonzero(free)]
    xf = cp.Variable(int(free.sum()))
    x = E @ xf
    eye1 = np.tile(np.eye(m).reshape(-1), n1)
    k2 = shp2[-1]
    eye2 = np.tile(np.eye(k2).reshape(-1), n2)
    S1 = cp.reshape(-(A1 @ x) - b1 - eps * eye1, (n1, m, m), order="C")
    S2 = cp.reshape(A2 @ x + b2 - eps * eye2, (n2, k2, k2), order="C")
    gidx = lay.offsets["gamma"]
    go = lay.offsets["gnode"]
    gn = x[go : go + lay.by_name["gnode"].nb]
    mu = prob.cfg.solver.mean_gamma_weight
    # with μ = 0 the node levels are tied to γ (free γ_g below γ only blur the optimal face)
    cons = [S1 >> 0, S2 >> 0, gn <= x[gidx] if mu > 0 else gn == x[gidx]]
    objective = x[gidx] + mu * cp.sum(gn) / gn.shape[0] if mu > 0 else x[gidx]
    problem = cp.Problem(cp.Minimize(objective), cons)
    build = time.perf_counter() - t0
    status, t_solve, its = _run(problem, opts, progress)
    xval = None if xf.value is None else E @ np.array(xf.value, dtype=float)
    gamma = float(xval[gidx]) if xval is not None else float("nan")
    if xval is not None and status == "optimal" and prob.cfg.solver.backoff > 0.0:
        # Back-off: accept γ ≤ (1+β)γ* and minimise the size of X, Y (better-conditioned
        # N = I − XY and controller matrices).
        t = cp.Variable()
        Xmats = positivity_x(prob, x)
        ycons = _y_matrix(x, lay)
        cons2 = [*cons, x[gidx] <= (1.0 + prob.cfg.solver.backoff) * gamma]
        cons2 += [t * np.eye(lay.n) - Xm >> 0 for Xm in Xmats]
        cons2 += [t * np.eye(lay.n) - ycons >> 0]
        p2 = cp.Problem(cp.Minimize(t), cons2)
        st2, t2, its2 = _run(p2, opts, progress)
        t_solve += t2
        if st2 == "optimal" and xf.value is not None:
            xval = E @ np.array(xf.value, dtype=float)
            gamma = float(xval[gidx])
            its = (its or 0) + (its2 or 0)
        else:
            status = f"{status} (backoff: {st2}, kept optimum)"
    return SolveResult(
        status=status,
        gamma=gamma,
        x=xval,
        solve_time_s=t_solve,
        build_time_s=build,
        iterations=its,
        n_lmi=n1,
        lmi_size=m,
    )


def _sym_expr(x, off: int, n: int):
    import cvxpy as cp

    iu = np.triu_indices(n)
    rows, cols = [], []
    for t, (r, c) in enumerate(zip(iu[0], iu[1], strict=True)):
        rows += [r * n + c]
        cols += [off + t]
        if r != c:
            rows += [c * n + r]
            cols += [off + t]
    S = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n * n, x.shape[0]))
    return cp.reshape(S @ x, (n, n), order="C")


def _y_matrix(x, lay: Layout):
    return _sym_expr(x, lay.offsets["Y"], lay.n)


def positivity_x(prob: Problem, x) -> list:
    """X(ρ) at every node as cvxpy expressions (for the back-off objective)."""
    import cvxpy as cp

    off, blk = prob.layout.offsets["X"], prob.layout.by_name["X"]
    n = prob.layout.n
    per = n * (n + 1) // 2
    mats = [_sym_expr(x, off + b * per, n) for b in range(blk.nb)]
    if blk.nb == 1:
        return mats
    out = []
    for g in range(prob.weights.shape[0]):
        out.append(cp.sum([prob.weights[g, b] * mats[b] for b in range(blk.nb)]))
    return out
