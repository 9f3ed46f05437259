"""Check (a) of ``pressor verify``: the controller family's analysis LMI over the dense grid.

The analysis itself is the family's (:meth:`pressor.synthesis.families.registry.Family.analysis`: the
Wirtinger analysis the design ran for the shipped family, the Jensen analysis of Theorem 1 for the
alternative); this module runs it and turns its
:class:`~pressor.synthesis.certificates.interface.AnalysisResult` into the report's ``analysis_lmi`` entry.
Either way the verdict is the floating-point re-check of every vertex LMI at every dense point.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from pressor.synthesis.certificates.interface import AnalysisResult
from pressor.synthesis.problem.closed_loop import DelaySystem

__all__ = ["Analysis", "analysis_check"]

Progress = Callable[[str], None]
#: (artifact, systems, mesh, centre, p_dependence, progress) -> result: a family's check (a)
Analysis = Callable[
    [Any, list[DelaySystem], np.ndarray, tuple[DelaySystem, np.ndarray], str, Progress],
    AnalysisResult,
]


def analysis_check(
    artifact: Any,
    analysis: Analysis,
    systems: list[DelaySystem],
    mesh: np.ndarray,
    centre: tuple[DelaySystem, np.ndarray],
    p_dependence: str,
    say: Progress,
) -> dict[str, Any]:
    """Run ``analysis`` on the frozen loops ``systems`` at the dense points ``mesh`` (G, 3).

    ``centre`` is the loop at the nominal ρ (clipped to the box) and that ρ. Returns the
    ``analysis_lmi`` entry of the report.
    """
    res = analysis(artifact, systems, mesh, centre, p_dependence, say)
    finite = np.isfinite(res.margins)
    worst_lmi = int(np.nanargmin(res.margins)) if finite.any() else None
    say(
        f"analysis LMI: certified={res.certified} status={res.status} gamma={res.gamma} "
        f"({res.solve_time_s:.1f} s)"
    )
    return {
        "certified": res.certified,
        "status": res.status,
        "gamma": res.gamma,
        "synthesis_gamma": float(artifact.gamma),
        "min_margin": float(np.min(res.margins)) if finite.all() else None,
        "n_failed_points": int(np.sum(~(res.margins > 0))),
        "worst_rho": mesh[worst_lmi].tolist() if worst_lmi is not None else None,
        "n_lmis": res.n_lmis,
        "p_dependence": res.p_dependence,
        "solve_time_s": res.solve_time_s,
        "notes": res.notes,
    }
