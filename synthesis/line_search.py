"""Line search over the fixed slack multipliers (λ2, λ3) of Theorem 3.

With λ2, λ3 fixed the synthesis condition is an LMI; γ*(λ2, λ3) is not convex in them, so the
search is a plain grid over the candidate lists of the design config (``[line_search]``), one SDP
per point, keeping the smallest γ among solves that reached "optimal".
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from synthesis import lmi, lmi_solve
from synthesis.config import DesignConfig


@dataclass(frozen=True)
class LinePoint:
    """One (λ2, λ3) point of the search."""

    lambda2: float
    lambda3: float
    status: str
    gamma: float
    solve_time_s: float


def search(
    cfg: DesignConfig,
    progress: Callable[[str], None] | None = None,
    solver_opts: dict | None = None,
) -> tuple[tuple[float, float] | None, list[LinePoint]]:
    """Solve at every (λ2, λ3) candidate pair.

    Returns
    -------
    tuple
        ``(best (λ2, λ3) or None if no point was optimal, all points in search order)``.
    """
    say = progress or (lambda _m: None)
    pts: list[LinePoint] = []
    best: tuple[float, float] | None = None
    best_gamma = float("inf")
    total = len(cfg.lambda2_candidates) * len(cfg.lambda3_candidates)
    k = 0
    for l2 in cfg.lambda2_candidates:
        for l3 in cfg.lambda3_candidates:
            k += 1
            c = cfg.with_lambdas(l2, l3)
            say(f"lambda search {k}/{total}: lambda2={l2:g}, lambda3={l3:g} ...")
            res = lmi_solve.solve(lmi.make_problem(c), solver_opts)
            pts.append(LinePoint(l2, l3, res.status, res.gamma, res.solve_time_s))
            ok = res.status == "optimal"
            say(
                f"lambda search {k}/{total}: status {res.status}, gamma {res.gamma:.4g}, "
                f"{res.solve_time_s:.1f} s"
                + ("  <- best so far" if ok and res.gamma < best_gamma else "")
            )
            if ok and res.gamma < best_gamma:
                best_gamma = res.gamma
                best = (l2, l3)
    return best, pts
