"""Run Clarabel on conic data and report its progress while it iterates.

One job: call ``clarabel.DefaultSolver`` on ``min q'x s.t. A x + s = b, s in K`` (data built by
the caller, or compiled by cvxpy), stream one progress line per interior-point iteration through a
callback (Clarabel's termination callback, which sees the iteration, the costs, the relative gap
and the primal/dual residuals), and name the outcome with cvxpy's status strings so that callers
that switched from ``problem.solve`` keep their status logic.

No single KKT solver decides. Clarabel factorises its KKT system with a backend chosen by
``direct_solve_method``; the default (faer, supernodal and multithreaded) dispatches to SIMD
kernels by CPU feature, so the same data can meet different rounding on different CPUs. A solve
that ends in a numerical failure (``NumericalError``, ``InsufficientProgress``) is repeated with
the next backend of the chain (:data:`pressor.synthesis.solver.kkt.DEFAULT_KKT_CHAIN`: faer, then qdldl, a
simplicial LDL' with its own ordering and no SIMD dispatch), and each retry is reported through
``progress`` and recorded in :attr:`ConicSolution.fallbacks`. :func:`pressor.synthesis.solver.kkt.kkt_chain`
sets the chain for a block of code (the ``--kkt`` option of ``pressor synth`` and ``pressor
verify``, the tests that force one backend). An infeasible, unbounded or iteration-limited end is
an answer, not a numerical failure: it is not retried. Whatever backend solved, the callers'
floating-point re-check is the verdict.

PSD blocks use Clarabel's ``PSDTriangleConeT`` convention: the upper triangle by columns (for a
symmetric matrix the same entries as the lower triangle by rows) with the off-diagonal entries
scaled by sqrt(2); :func:`svec_rows` gives those positions and weights.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from pressor.synthesis.solver.kkt import DEFAULT_KKT_CHAIN, KktAttempt, current_kkt_chain

__all__ = ["ConicSolution", "solve_conic", "solve_cvxpy", "svec_eye", "svec_rows", "unsvec"]

Progress = Callable[[str], None]

#: Clarabel statuses that are numerical failures of a backend (retried on the next one)
_NUMERICAL = frozenset({"NumericalError", "InsufficientProgress"})
#: Clarabel status -> cvxpy status string (the strings the callers already test for)
_STATUS = {
    "Solved": "optimal",
    "AlmostSolved": "optimal_inaccurate",
    "PrimalInfeasible": "infeasible",
    "AlmostPrimalInfeasible": "infeasible_inaccurate",
    "DualInfeasible": "unbounded",
    "AlmostDualInfeasible": "unbounded_inaccurate",
    "MaxIterations": "user_limit",
    "MaxTime": "user_limit",
    "CallbackTerminated": "user_limit",
}


@dataclass(frozen=True)
class ConicSolution:
    """Outcome of :func:`solve_conic`.

    Attributes
    ----------
    status
        cvxpy-style status ("optimal", "optimal_inaccurate", "infeasible", ..., "solver_error").
    clarabel_status
        Clarabel's own status name (e.g. "NumericalError").
    x
        Primal solution (None unless a solution is present).
    iterations
        Interior-point iterations.
    solve_time_s
        Wall time of setup + solve (s).
    raw
        Clarabel's solution object (for cvxpy's ``unpack_results``).
    kkt_method
        The final attempt's KKT backend (``direct_solve_method``, with its own settings if any).
    fallbacks
        The attempts that ended in a numerical failure before it, as "method: status".
    """

    status: str
    clarabel_status: str
    x: NDArray[np.float64] | None
    iterations: int
    solve_time_s: float
    raw: Any = None
    kkt_method: str = str(DEFAULT_KKT_CHAIN[0])
    fallbacks: tuple[str, ...] = ()

    @property
    def notes(self) -> list[str]:
        """What a report records about this solve: each KKT fallback, then Clarabel's own status
        when the solve ended in a solver error."""
        out = [f"KKT fallback: {f}, then {self.kkt_method}" for f in self.fallbacks]
        if self.status == "solver_error":
            out.append(f"Clarabel ended {self.clarabel_status}")
        return out


def svec_rows(size: int) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Row-major indices (r * size + c, r >= c) of a ``size x size`` matrix in Clarabel's PSD
    triangle order, and the weights (1 on the diagonal, sqrt(2) off it)."""
    # Clarabel: the upper triangle column by column, i.e. (0,0), (0,1), (1,1), (0,2), ...
    pairs = [(r, c) for c in range(size) for r in range(c + 1)]
    rr = np.array([r for r, _ in pairs], dtype=np.int64)
    cc = np.array([c for _, c in pairs], dtype=np.int64)
    idx = rr * size + cc
    w = np.where(rr == cc, 1.0, np.sqrt(2.0))
    return idx.astype(np.int64), w


def unsvec(v: NDArray[np.float64], size: int) -> NDArray[np.float64]:
    """(..., size(size+1)/2) Clarabel triangles -> (..., size, size) symmetric matrices."""
    idx, w = svec_rows(size)
    out = np.zeros((*v.shape[:-1], size * size))
    out[..., idx] = v / w
    out = out.reshape(*v.shape[:-1], size, size)
    return out + np.swapaxes(np.triu(out, 1), -1, -2)


def svec_eye(size: int) -> NDArray[np.float64]:
    """The identity in Clarabel's PSD-triangle order."""
    idx, _ = svec_rows(size)
    return (idx // size == idx % size).astype(float)


def _reporter(label: str, progress: Progress | None, every_s: float) -> Callable[[Any], bool]:
    last = [-np.inf]

    def callback(info: Any) -> bool:
        now = time.perf_counter()
        if progress is not None and now - last[0] >= every_s:
            last[0] = now
            progress(
                f"{label}: iter {info.iterations:3d}  cost {info.cost_primal:+.5e}  "
                f"gap {info.gap_rel:.1e}  pres {info.res_primal:.1e}  dres {info.res_dual:.1e}"
            )
        return False  # never stop the solver: the callback only reports

    return callback


def _settings(options: dict[str, Any]) -> Any:
    import clarabel

    settings = clarabel.DefaultSettings()
    settings.verbose = False
    for key, value in options.items():
        if not hasattr(settings, key):
            raise ValueError(f"unknown Clarabel setting {key!r}")
        setattr(settings, key, value)
    return settings


def solve_conic(
    q: NDArray[np.float64],
    a: sp.spmatrix,
    b: NDArray[np.float64],
    cones: list[Any],
    options: dict[str, Any] | None = None,
    progress: Progress | None = None,
    label: str = "Clarabel",
    every_s: float = 0.0,
    p: sp.spmatrix | None = None,
) -> ConicSolution:
    """Solve ``min 1/2 x'Px + q'x  s.t.  a x + s = b, s in cones`` with Clarabel.

    The KKT backends of :func:`pressor.synthesis.solver.kkt.current_kkt_chain` are tried in order while a
    solve ends in a numerical failure (module docstring); each retry is reported through
    ``progress``.

    Parameters
    ----------
    q, a, b, cones
        Conic data in Clarabel's form (``cones`` a list of ``clarabel.*ConeT``).
    options
        Clarabel settings by name (e.g. ``{"max_iter": 50}``); verbose is off. A
        ``direct_solve_method`` here forces that backend alone.
    progress
        Called with one line per iteration (at most one per ``every_s`` seconds) while it runs.
    label
        Prefix of the progress lines.
    every_s
        Minimum spacing of progress lines (s); 0 reports every iteration.
    p
        Quadratic cost (upper triangle used); default none.

    Returns
    -------
    ConicSolution
        The last attempt's outcome, with the failed attempts in ``fallbacks``.
    """
    opts = dict(options or {})
    forced = opts.pop("direct_solve_method", None)
    chain = (KktAttempt(str(forced)),) if forced is not None else current_kkt_chain()
    t0 = time.perf_counter()
    failed: list[str] = []
    for i, attempt in enumerate(chain):
        settings = {**opts, **attempt.settings, "direct_solve_method": attempt.method}
        sol = _solve_once(q, a, b, cones, settings, p, _reporter(label, progress, every_s))
        name = str(sol.status)
        if name not in _NUMERICAL or i + 1 == len(chain):
            break
        failed.append(f"{attempt}: {name}")
        if progress:
            progress(
                f"{label}: Clarabel ended {name} with the {attempt} KKT solver; "
                f"solving again with {chain[i + 1]}"
            )
    status = _STATUS.get(name, "solver_error")
    has_x = status in ("optimal", "optimal_inaccurate") and sol.x is not None
    x = np.asarray(sol.x, dtype=float) if has_x else None
    elapsed = time.perf_counter() - t0
    return ConicSolution(
        status, name, x, int(sol.iterations), elapsed, sol, str(attempt), tuple(failed)
    )


def _solve_once(
    q: NDArray[np.float64],
    a: sp.spmatrix,
    b: NDArray[np.float64],
    cones: list[Any],
    options: dict[str, Any],
    p: sp.spmatrix | None,
    callback: Callable[[Any], bool],
) -> Any:
    import clarabel

    n = int(np.asarray(q).size)
    p_mat = sp.csc_matrix((n, n)) if p is None else sp.triu(p, format="csc")
    solver = clarabel.DefaultSolver(
        p_mat,
        np.asarray(q, dtype=float),
        sp.csc_matrix(a),
        np.asarray(b, dtype=float),
        cones,
        _settings(options),
    )
    solver.set_termination_callback(callback)
    return solver.solve()


def solve_cvxpy(
    problem: Any,
    options: dict[str, Any] | None = None,
    progress: Progress | None = None,
    label: str = "Clarabel",
    every_s: float = 0.0,
) -> ConicSolution:
    """Solve a cvxpy problem with Clarabel through :func:`solve_conic` (so progress is reported)
    and load the result back into the problem's variables, as ``problem.solve`` would.

    ``options`` are Clarabel settings by name (as for ``problem.solve(solver=CLARABEL, ...)``).
    """
    import cvxpy as cp
    import cvxpy.settings as s
    from cvxpy.reductions.solvers.conic_solvers.clarabel_conif import dims_to_solver_cones
    from cvxpy.reductions.solvers.conic_solvers.conic_solver import ConicSolver

    data, chain, inverse = problem.get_problem_data(cp.CLARABEL, solver_opts=dict(options or {}))
    sol = solve_conic(
        data[s.C],
        data[s.A],
        data[s.B],
        dims_to_solver_cones(data[ConicSolver.DIMS]),
        options,
        progress,
        label,
        every_s,
        data.get(s.P),
    )
    problem.unpack_results(sol.raw, chain, inverse)
    return sol
