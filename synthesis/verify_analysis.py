"""Check (a) of ``pressor verify``: the analysis LMI over the dense grid, by controller family.

* "theorem3" (:mod:`synthesis.family`): the delay-dependent analysis LMI of
  :mod:`synthesis.analysis_lmi` (Theorem 1, Jensen functional), in state coordinates whitened by
  the centre point's own Lyapunov matrix and balanced, in feasibility form with the L2 gain capped
  at ``JENSEN_GAMMA_CAP_FACTOR`` x the synthesis γ; fast path: the rate-bound form on a working set
  (as many points as the synthesis grid has nodes, grown by the failing ones), the all-vertex form
  as fallback; ``all_points_at_once`` imposes every point and vertex in one solve.
* "smith": the Wirtinger-based analysis of :func:`synthesis.smith_design.certify_smith` (the one
  the design stage ran, rate-bound form, one LMI per point) over every dense point in ONE
  feasibility solve with the L2 gain capped at ``SMITH_GAMMA_CAP_FACTOR`` x the artifact's γ (the
  design grid's minimum); ``all_points_at_once`` imposes every rate vertex as its own LMI instead
  (the straightforward form, for ``benchmarks/synthesis_speed.py``). The cap is loose on purpose: the dense grid adds points between the
  design nodes, whose γ is larger (measured, loop gain 2: 2x2x2 11.65, 3x3x3 13.86, 5x5x5 14.5),
  and a cap too tight would turn a stable, certified loop into a failed solve.

Either way the verdict is the floating-point re-check of every vertex LMI at every dense point.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from synthesis.analysis_lmi import analyse
from synthesis.closed_loop import DelaySystem
from synthesis.reconstruct import scaling_of
from synthesis.smith_design import certify_smith
from synthesis.state_transform import conditioning_transform

__all__ = ["JENSEN_GAMMA_CAP_FACTOR", "SMITH_GAMMA_CAP_FACTOR", "analysis_check"]

# The Jensen analysis is solved in feasibility form: L2 gain <= this factor x the synthesis gamma,
# maximise a common strictness margin (minimising gamma on the dense grid ended in Clarabel
# NumericalError or a bogus "optimal" whose re-check failed). The certificate is the rate-bounded
# stability and the reported (not tightened) gain bound.
JENSEN_GAMMA_CAP_FACTOR = 20.0
#: the Wirtinger analysis of a "smith" artifact: L2 gain <= this factor x the artifact's gamma
SMITH_GAMMA_CAP_FACTOR = 2.0

Progress = Callable[[str], None]


def analysis_check(
    artifact: Any,
    systems: list[DelaySystem],
    mesh: np.ndarray,
    centre: tuple[DelaySystem, np.ndarray],
    p_dependence: str,
    all_points_at_once: bool,
    say: Progress,
) -> dict[str, Any]:
    """Run check (a) on the frozen loops ``systems`` at the dense points ``mesh`` (G, 3).

    ``centre`` is the loop at the nominal ρ (clipped to the box) and that ρ, used by the "smith"
    family to condition the state. Returns the ``analysis_lmi`` entry of the report.
    """
    if artifact.family.is_smith:
        cap = SMITH_GAMMA_CAP_FACTOR * float(artifact.gamma)
        say(f"analysis LMI (Wirtinger, smith family): gamma <= {cap:.4g}, {len(mesh)} points")
        res = certify_smith(
            systems,
            mesh,
            centre,
            artifact.model_config,
            scaling_of(artifact),
            cap,
            say,
            p_dependence=p_dependence,
            rate_form="vertex" if all_points_at_once else "bound",
        )
    else:
        res = _jensen(artifact, systems, mesh, p_dependence, all_points_at_once, say)
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


def _jensen(
    artifact: Any,
    systems: list[DelaySystem],
    mesh: np.ndarray,
    p_dependence: str,
    all_points_at_once: bool,
    say: Progress,
) -> Any:
    box = np.asarray(artifact.box, dtype=float)
    rates = np.asarray(artifact.rate_bounds, dtype=float)
    # the synthesis' own scaling (numerics only: feasibility and gamma are unaffected)
    sc = scaling_of(artifact)
    rho_hat, half, ts = sc.to_hat(mesh), sc.rho_half, sc.time_s
    # conditioning: whiten the state by the centre point's own Lyapunov matrix (a constant
    # congruence, so feasibility and gamma are unchanged), then balance; see analysis_lmi
    ic = int(np.argmin(np.sum(rho_hat**2, axis=1)))
    centre = analyse(
        [systems[ic]],
        rho_hat[ic : ic + 1],
        rates / half,
        np.array([0.0, 0.0, half[2]]),
        float(box[2, 1]),
        p_dependence="constant",
        time_scale_s=ts,
        backoff=0.0,
    )
    transform = None
    if centre.p0_phys is not None and centre.status in ("optimal", "optimal_inaccurate"):
        try:
            transform = conditioning_transform(centre.p0_phys, systems[ic], ts)
        except ValueError:
            transform = None
    say(f"analysis LMI: conditioning transform from the centre point ({transform is not None})")
    return analyse(
        systems,
        rho_hat,
        rates / half,
        np.array([0.0, 0.0, half[2]]),
        float(box[2, 1]),
        p_dependence=p_dependence,
        time_scale_s=ts,
        progress=say,
        state_transform=transform,
        gamma_cap=JENSEN_GAMMA_CAP_FACTOR * float(artifact.gamma),
        working_set=None if all_points_at_once else int(np.prod([len(a) for a in artifact.grid])),
        rate_bound=not all_points_at_once,
    )
