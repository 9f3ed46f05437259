"""The "smith" controller family (the shipped one), as registered in ``families/registry.py``.

The law is the scheduled Smith predictor + PI of :class:`pressor.synthesis.families.smith.law.SmithLPV` with
one parameter, ``loop_gain`` = K·Kc = T/λ (dimensionless, in (0, 10]), fixed in closed form: there
is no synthesis LMI. The design stage (:func:`pressor.synthesis.families.smith.design.design_smith`) is the
Wirtinger-based analysis LMI in K-scaled coordinates
(:mod:`pressor.synthesis.certificates.wirtinger.k_scaling`) on the design grid, and the artifact stores its
certificate (``P``, ``S``, ``R`` and the state ``transform`` it lives in, all in those coordinates,
:func:`smith_coef_shapes`); its nodes are the law at the grid nodes. Check (a) of ``pressor verify``
is the same analysis over every dense point in one feasibility solve with the L2 gain capped at
:data:`SMITH_GAMMA_CAP_FACTOR` x the artifact's γ (the design grid's minimum). The cap is loose on
purpose: the dense grid adds points between the design nodes, whose γ is larger, and a cap too tight
would turn a stable, certified loop into a failed solve.

The heavy modules (cvxpy, the analysis) are imported inside the methods, so the artifact loader can
ask this family for its shapes cheaply.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pressor.synthesis.families.registry import Designed, Progress, SynthRequest

if TYPE_CHECKING:
    from pressor.synthesis.artifact import ControllerArtifact
    from pressor.synthesis.certificates.interface import AnalysisResult
    from pressor.synthesis.families.smith.design import WirtingerForm
    from pressor.synthesis.problem.closed_loop import DelaySystem
    from pressor.synthesis.problem.config import DesignConfig
    from pressor.synthesis.problem.reconstruct import DelayedController

__all__ = [
    "FAMILY",
    "NAME",
    "SMITH_GAMMA_CAP_FACTOR",
    "SMITH_ORDER",
    "SmithFamily",
    "capped_analysis",
    "smith_coef_shapes",
]

NAME = "smith"
#: controller states: û (ml/h, the model's filter state) and ŷ (mmHg)
SMITH_ORDER = 2
#: basis terms of the certificate's P(ρ) (quadratic in ρ̂: 1, ρ̂_i, ρ̂_i²/2)
SMITH_P_TERMS = 7
#: check (a) of ``pressor verify``: L2 gain <= this factor x the artifact's gamma
SMITH_GAMMA_CAP_FACTOR = 2.0


def smith_coef_shapes(n_plant: int) -> dict[str, tuple[int, ...]]:
    """The artifact's coefficients: the Wirtinger certificate, name -> shape.

    The closed loop has ``n = n_plant + SMITH_ORDER`` states; ``P`` (7, 2n, 2n) are the basis terms
    of P(ρ) on ξ = [x; ∫x], ``S``, ``R`` (n, n) the integral terms, all divided by γ, and
    ``transform`` (n, n) the state coordinates they live in (scaled time, see
    :func:`pressor.synthesis.certificates.wirtinger.analysis.analyse_wirtinger`).
    """
    n = n_plant + SMITH_ORDER
    return {"P": (SMITH_P_TERMS, 2 * n, 2 * n), "S": (n, n), "R": (n, n), "transform": (n, n)}


class SmithFamily:
    """The "smith" family's :class:`pressor.synthesis.families.registry.Family` object."""

    name = NAME
    takes_loop_gain = True
    synth_options: frozenset[str] = frozenset()
    bumpless_log_k = True  # synthesis.families.smith.design.bumpless_rows

    def controller_order(self, n_plant: int) -> int:
        """Always :data:`SMITH_ORDER`, whatever the plant."""
        return SMITH_ORDER

    def coefficient_shapes(self, n_plant: int, ny: int) -> dict[str, tuple[tuple[int, ...], ...]]:
        """One allowed shape per coefficient (:func:`smith_coef_shapes`)."""
        return {name: (shape,) for name, shape in smith_coef_shapes(n_plant).items()}

    #: how the design summary names the certifying analysis
    analysis_name = "Wirtinger analysis"

    def certified_artifact(
        self, cfg: DesignConfig, progress: Progress | None = None
    ) -> ControllerArtifact:
        """The certified artifact (``design.design_smith``); raises ``SmithDesignError``."""
        from pressor.synthesis.families.smith.design import design_smith

        return design_smith(cfg, progress=progress)

    def design(self, cfg: DesignConfig, request: SynthRequest, progress: Progress) -> Designed:
        """Certify the law on the design grid (:meth:`certified_artifact`)."""
        from pressor.synthesis.families.smith.design import SmithDesignError

        try:
            art = self.certified_artifact(cfg, progress)
        except SmithDesignError as exc:
            return Designed(None, failure=f"not certified: {exc}")
        notes = [n for n in art.metadata["solver"]["notes"] if n.startswith("KKT fallback")]
        summary = [
            f"controller       {self.name}, loop gain {cfg.controller.loop_gain:g}",
            f"gamma            {art.gamma:.6g} ({self.analysis_name}, design grid)",
            f"solver status    {art.metadata['solver']['status']}",
        ]
        return Designed(art, summary, notes)

    def controller_at(self, artifact: ControllerArtifact, rho: np.ndarray) -> DelayedController:
        """The closed-form law ``SmithLPV(loop_gain, Ω, Λ).at(ρ)``."""
        from pressor.synthesis.families.smith.law import SmithLPV
        from pressor.synthesis.problem.reconstruct import DelayedController

        loop_gain = artifact.family.loop_gain
        assert loop_gain is not None
        r = np.asarray(rho, dtype=float)
        s = SmithLPV(loop_gain, artifact.omega, artifact.lambda_).at(r)
        return DelayedController(
            Ak=s.Ak, Adk=s.Adk, Bk=s.Bk, Ck=s.Ck, Cdk=s.Cdk, Dk=s.Dk, rho=r, tau_s=float(r[2])
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
        """The design's Wirtinger analysis over every dense point, γ capped (module doc)."""
        from pressor.synthesis.families.smith.design import SHIPPED_FORM

        return capped_analysis(
            SHIPPED_FORM, "smith family", artifact, systems, mesh, centre, p_dependence, progress
        )


def capped_analysis(
    form: WirtingerForm,
    label: str,
    artifact: ControllerArtifact,
    systems: list[DelaySystem],
    mesh: np.ndarray,
    centre: tuple[DelaySystem, np.ndarray],
    p_dependence: str,
    progress: Progress,
) -> AnalysisResult:
    """Check (a) in ``form``: one feasibility solve over ``mesh``, γ capped at
    :data:`SMITH_GAMMA_CAP_FACTOR` × the artifact's (the family's analysis with the shipped form;
    :mod:`research.synthesis_forms` with its ablations). ``label`` names it in the progress line."""
    from pressor.synthesis.families.smith.design import certify_in_form
    from pressor.synthesis.families.smith.law import SmithLPV
    from pressor.synthesis.problem.reconstruct import scaling_of

    cap = SMITH_GAMMA_CAP_FACTOR * float(artifact.gamma)
    progress(f"analysis LMI (Wirtinger, {label}): gamma <= {cap:.4g}, {len(mesh)} points")
    return certify_in_form(
        form,
        systems,
        mesh,
        centre,
        artifact.model_config,
        scaling_of(artifact),
        cap,
        progress,
        p_dependence,
        law=SmithLPV(artifact.family.loop_gain, artifact.omega, artifact.lambda_),
    )


FAMILY = SmithFamily()
