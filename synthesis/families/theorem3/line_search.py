"""Line search over the fixed slack multipliers (λ2, λ3) of Theorem 3.

With λ2, λ3 fixed the synthesis condition is an LMI; γ*(λ2, λ3) is not convex in them, so the
search is a plain grid over the candidate lists of the design config (``[line_search]``), one SDP
per point, keeping the smallest γ among solves that reached "optimal". The points are independent:
they run in this process, in local worker processes (``jobs``) or on a Dask cluster
(``scheduler``, :mod:`pressor.plumbing.parallel`), with the same result.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from pressor.plumbing.parallel import run_ordered
from pressor.synthesis.families.theorem3 import lmi, lmi_solve
from pressor.synthesis.problem.config import DesignConfig


@dataclass(frozen=True)
class LinePoint:
    """One (λ2, λ3) point of the search."""

    lambda2: float
    lambda3: float
    status: str
    gamma: float
    solve_time_s: float


def _solve_point(task: tuple[DesignConfig, float, float, dict | None]) -> LinePoint:
    cfg, l2, l3, solver_opts = task
    res = lmi_solve.solve(lmi.make_problem(cfg.with_lambdas(l2, l3)), solver_opts)
    return LinePoint(l2, l3, res.status, res.gamma, res.solve_time_s)


def search(
    cfg: DesignConfig,
    progress: Callable[[str], None] | None = None,
    solver_opts: dict | None = None,
    jobs: int = 1,
    scheduler: str | None = None,
) -> tuple[tuple[float, float] | None, list[LinePoint]]:
    """Solve at every (λ2, λ3) candidate pair.

    Parameters
    ----------
    cfg
        The design; its ``lambda2_candidates`` × ``lambda3_candidates`` are searched.
    progress
        Called with one line per finished point.
    solver_opts
        Clarabel options (default: the synthesis defaults).
    jobs, scheduler
        Local worker processes (≥ 1), or the address of a Dask scheduler; neither changes the result.

    Returns
    -------
    tuple
        ``(best (λ2, λ3) or None if no point was optimal, all points in search order)``.
    """
    say = progress or (lambda _m: None)
    tasks = [
        (cfg, l2, l3, solver_opts) for l2 in cfg.lambda2_candidates for l3 in cfg.lambda3_candidates
    ]
    say(f"lambda search: {len(tasks)} points")
    pts = run_ordered(
        _solve_point,
        tasks,
        jobs=jobs,
        scheduler=scheduler,
        progress=lambda done, total: say(f"lambda search: {done}/{total} points solved"),
    )
    best: tuple[float, float] | None = None
    best_gamma = float("inf")
    for p in pts:
        say(
            f"lambda2={p.lambda2:g}, lambda3={p.lambda3:g}: status {p.status}, "
            f"gamma {p.gamma:.4g}, {p.solve_time_s:.1f} s"
        )
        if p.status == "optimal" and p.gamma < best_gamma:
            best_gamma = p.gamma
            best = (p.lambda2, p.lambda3)
    return best, pts
