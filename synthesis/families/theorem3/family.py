"""The "theorem3" controller family (the alternative), as registered in ``families/registry.py``.

The full-order controller of the paper's Theorem 3, synthesised by the LMIs of
:mod:`pressor.synthesis.families.theorem3.lmi` (Jensen functional;
:func:`pressor.synthesis.families.theorem3.synthesize.synthesize`, optionally after the (λ2, λ3) line search
of :mod:`pressor.synthesis.families.theorem3.line_search`). The artifact's coefficients are the decision
variables (:func:`coef_shapes`) and the controller is reconstructed from them
(:mod:`pressor.synthesis.problem.reconstruct`). A design file or an artifact without a ``controller`` entry
is this family.

Check (a) of ``pressor verify`` is the delay-dependent analysis LMI of
:mod:`pressor.synthesis.certificates.jensen.analysis` (Theorem 1, Jensen functional), in state coordinates
whitened by the centre point's own Lyapunov matrix and balanced, in feasibility form with the L2
gain capped at :data:`JENSEN_GAMMA_CAP_FACTOR` x the synthesis γ, in the rate-bound form on a
working set (as many points as the synthesis grid has nodes, grown by the failing ones), the
all-vertex form as fallback (:func:`jensen_analysis`).

The heavy modules (cvxpy, the LMIs) are imported inside the functions, so the artifact loader can
ask this family for its shapes cheaply.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from pressor.synthesis.families.registry import Designed, Progress, SynthRequest

if TYPE_CHECKING:
    from pressor.synthesis.artifact import ControllerArtifact
    from pressor.synthesis.certificates.interface import AnalysisResult
    from pressor.synthesis.problem.closed_loop import DelaySystem
    from pressor.synthesis.problem.config import DesignConfig
    from pressor.synthesis.problem.reconstruct import DelayedController

__all__ = [
    "COEF_NAMES",
    "FAMILY",
    "JENSEN_GAMMA_CAP_FACTOR",
    "NAME",
    "Theorem3Family",
    "coef_shapes",
    "jensen_analysis",
]

NAME = "theorem3"
#: decision coefficients (leading axis = number of basis terms, 1 or 7); shapes: :func:`coef_shapes`
COEF_NAMES = ("P", "Q", "R", "X", "Y", "Ah", "Adh", "Bh", "Ch", "Cdh", "Dk")
#: basis terms a decision coefficient may have (constant, or quadratic in ρ̂)
BASIS_TERMS = (1, 7)
# The Jensen analysis is solved in feasibility form: L2 gain <= this factor x the synthesis gamma,
# maximise a common strictness margin (minimising gamma on the dense grid ended in Clarabel
# NumericalError or a bogus "optimal" whose re-check failed). The certificate is the rate-bounded
# stability and the reported (not tightened) gain bound.
JENSEN_GAMMA_CAP_FACTOR = 20.0


def coef_shapes(n: int, ny: int = 2) -> dict[str, tuple[int, int]]:
    """Decision coefficients: name -> (rows, cols) for a generalised plant of order ``n``.

    n = 3 for the default model; frequency weights add states
    (:func:`pressor.synthesis.problem.model.dims`).
    """
    n2 = 2 * n
    return {
        "P": (n2, n2),
        "Q": (n2, n2),
        "R": (n2, n2),
        "X": (n, n),
        "Y": (n, n),
        "Ah": (n, n),
        "Adh": (n, n),
        "Bh": (n, ny),
        "Ch": (1, n),
        "Cdh": (1, n),
        "Dk": (1, ny),
    }


class Theorem3Family:
    """The "theorem3" family's :class:`pressor.synthesis.families.registry.Family` object."""

    name = NAME
    takes_loop_gain = False
    synth_options = frozenset({"--lambda-search", "--lambda2", "--lambda3", "--backoff"})
    bumpless_log_k = False

    def controller_order(self, n_plant: int) -> int:
        """Full order: the generalised plant's."""
        return n_plant

    def coefficient_shapes(self, n_plant: int, ny: int) -> dict[str, tuple[tuple[int, ...], ...]]:
        """Every decision coefficient with 1 or 7 basis terms (:func:`coef_shapes`)."""
        return {
            name: tuple((nb, r, c) for nb in BASIS_TERMS)
            for name, (r, c) in coef_shapes(n_plant, ny).items()
        }

    def design(self, cfg: DesignConfig, request: SynthRequest, progress: Progress) -> Designed:
        """The Theorem-3 synthesis, after the (λ2, λ3) line search if asked for.

        Raises
        ------
        pressor.plumbing.usage.UsageError
            If the line search's Dask scheduler cannot be used.
        """
        from pressor.synthesis.families.theorem3.synthesize import SynthesisError, synthesize

        extra: dict[str, Any] = {}
        if request.lambda_search:
            from pressor.plumbing.parallel import BackendError
            from pressor.plumbing.usage import UsageError
            from pressor.synthesis.families.theorem3.line_search import search

            try:
                best, pts = search(
                    cfg, progress=progress, jobs=request.jobs, scheduler=request.scheduler
                )
            except BackendError as exc:
                raise UsageError(str(exc)) from None
            extra["line_search"] = [
                {"lambda2": p.lambda2, "lambda3": p.lambda3, "status": p.status, "gamma": p.gamma}
                for p in pts
            ]
            if best is None:
                return Designed(None, failure="no (lambda2, lambda3) candidate reached 'optimal'")
            progress(f"lambda search: best lambda2={best[0]:g}, lambda3={best[1]:g}")
            cfg = cfg.with_lambdas(*best)
        try:
            res = synthesize(cfg, progress=progress, extra_meta=extra or None)
        except SynthesisError as exc:
            return Designed(None, failure=f"synthesis failed: {exc}")
        r = res.result
        summary = [
            f"gamma            {r.gamma:.6g}",
            f"solver status    {r.status} ({r.iterations} iterations)",
            f"build / solve    {r.build_time_s:.2f} s / {r.solve_time_s:.1f} s",
        ]
        return Designed(res.artifact, summary)

    def controller_at(self, artifact: ControllerArtifact, rho: np.ndarray) -> DelayedController:
        """Reconstructed from the decision variables.

        (:func:`pressor.synthesis.problem.reconstruct.controllers_at`)
        """
        from pressor.synthesis.problem.reconstruct import (
            DelayedController,
            controllers_at,
            scaling_of,
        )

        r = np.asarray(rho, dtype=float)
        k = controllers_at(
            artifact.coefficients, r[None, :], scaling_of(artifact), artifact.model_config
        )
        return DelayedController(
            Ak=k["Ak"][0],
            Adk=k["Adk"][0],
            Bk=k["Bk"][0],
            Ck=k["Ck"][0],
            Cdk=k["Cdk"][0],
            Dk=k["Dk"][0],
            rho=r,
            tau_s=float(r[2]),
        )

    def analysis(
        self,
        artifact: ControllerArtifact,
        systems: list[DelaySystem],
        mesh: np.ndarray,
        centre: tuple[DelaySystem, np.ndarray],
        p_dependence: str,
        progress: Progress,
    ) -> AnalysisResult:
        """The Jensen analysis on a working set (module doc); ``centre`` is unused."""
        return jensen_analysis(artifact, systems, mesh, p_dependence, progress)


def jensen_analysis(
    artifact: ControllerArtifact,
    systems: list[DelaySystem],
    mesh: np.ndarray,
    p_dependence: str,
    progress: Progress,
    all_points_at_once: bool = False,
) -> AnalysisResult:
    """The Jensen analysis LMI of check (a) over the frozen loops ``systems`` at ``mesh`` (G, 3).

    ``all_points_at_once`` (:mod:`research.synthesis_forms` only) imposes every point and rate vertex in
    one solve instead of the rate-bound form on a working set; the verdict is the same re-check.
    """
    from pressor.synthesis.certificates.jensen.analysis import analyse
    from pressor.synthesis.certificates.state_transform import conditioning_transform
    from pressor.synthesis.problem.reconstruct import scaling_of

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
    progress(
        f"analysis LMI: conditioning transform from the centre point ({transform is not None})"
    )
    return analyse(
        systems,
        rho_hat,
        rates / half,
        np.array([0.0, 0.0, half[2]]),
        float(box[2, 1]),
        p_dependence=p_dependence,
        time_scale_s=ts,
        progress=progress,
        state_transform=transform,
        gamma_cap=JENSEN_GAMMA_CAP_FACTOR * float(artifact.gamma),
        working_set=None if all_points_at_once else int(np.prod([len(a) for a in artifact.grid])),
        rate_bound=not all_points_at_once,
    )


FAMILY = Theorem3Family()
