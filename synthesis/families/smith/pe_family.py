"""The "smith-pe" family: the shipped Smith law, certified in prediction-error coordinates.

Same law, nodes and generated module as the "smith" family
(:class:`pressor.synthesis.families.smith.law.SmithLPV`); only the certificate differs. Its design stage
and check (a) of ``pressor verify`` are the Wirtinger analysis of the loop written in the
coordinates of the Smith cancellation (:mod:`pressor.synthesis.certificates.wirtinger.prediction_error`,
law "trapezoid"), which reaches delay boxes the plant-coordinate analysis cannot
(docs/notes/certificate-structure.md, §5: 200 s at rates 5e-5 / 0.01 / 0.01). The design grid's T and τ
point counts are the analysis grid (K drops out in K-scaled coordinates); check (a) re-solves on
the verification mesh's T and τ counts with γ capped at :data:`SMITH_GAMMA_CAP_FACTOR` × the
artifact's. The artifact stores the certificate (``P`` affine in (T, τ): 3 terms on ξ = [x; ∫x],
``S``, ``R``, ``transform`` on the 4 states [K u, ŷ, x_e/T_ref, e]).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pressor.synthesis.families.registry import Progress
from pressor.synthesis.families.smith.family import SMITH_GAMMA_CAP_FACTOR, SmithFamily

if TYPE_CHECKING:
    from pressor.synthesis.artifact import ControllerArtifact
    from pressor.synthesis.certificates.interface import AnalysisResult
    from pressor.synthesis.problem.closed_loop import DelaySystem
    from pressor.synthesis.problem.config import DesignConfig

__all__ = ["FAMILY", "NAME", "SmithPEFamily", "design_smith_pe"]

NAME = "smith-pe"
#: basis terms of P: affine in (T, τ)
PE_P_TERMS = 3


class SmithPEFamily(SmithFamily):
    """The "smith-pe" family's :class:`pressor.synthesis.families.registry.Family` object."""

    name = NAME
    analysis_name = "prediction-error analysis"
    bumpless_log_k = False  # its certificate carries no bumpless rows

    def coefficient_shapes(self, n_plant: int, ny: int) -> dict[str, tuple[tuple[int, ...], ...]]:
        """The prediction-error certificate: P (3, 8, 8), S, R and transform (4, 4)."""
        from pressor.synthesis.certificates.wirtinger.prediction_error import N_STATES as n

        return {
            "P": ((PE_P_TERMS, 2 * n, 2 * n),),
            "S": ((n, n),),
            "R": ((n, n),),
            "transform": ((n, n),),
        }

    def certified_artifact(
        self, cfg: DesignConfig, progress: Progress | None = None
    ) -> ControllerArtifact:
        """The certified artifact (:func:`design_smith_pe`); raises ``SmithDesignError``."""
        return design_smith_pe(cfg, progress)

    def analysis(
        self,
        artifact: ControllerArtifact,
        systems: list[DelaySystem],
        mesh: np.ndarray,
        centre: tuple[DelaySystem, np.ndarray],
        p_dependence: str,
        progress: Progress,
    ) -> AnalysisResult:
        """Check (a): the same analysis on the mesh's T × τ counts, γ capped (module doc)."""
        from pressor.synthesis.certificates.wirtinger.prediction_error import (
            PredictionErrorBox,
            certify,
        )

        loop_gain = artifact.family.loop_gain
        assert loop_gain is not None
        box = PredictionErrorBox.from_model(artifact.model_config, loop_gain, "trapezoid")
        time_s = float(artifact.metadata["scaling"]["time_s"])
        pts = np.asarray(mesh, dtype=float).reshape(-1, 3)
        n_t = max(len(np.unique(pts[:, 1])), 2)
        n_tau = max(len(np.unique(pts[:, 2])), 2)
        cap = SMITH_GAMMA_CAP_FACTOR * float(artifact.gamma)
        progress(f"analysis LMI ({NAME}): gamma <= {cap:.4g}, {n_t} x {n_tau} (T, tau)")
        return certify(box, n_t, n_tau, time_scale_s=time_s, gamma_cap=cap)


def design_smith_pe(cfg: DesignConfig, progress: Progress | None = None) -> ControllerArtifact:
    """Certify the config's Smith law in prediction-error coordinates; package the artifact.

    Raises
    ------
    SmithDesignError
        If the analysis does not certify the law on the design grid's T × τ.
    """
    from pressor.synthesis.certificates.wirtinger.prediction_error import (
        PredictionErrorBox,
        certify,
    )
    from pressor.synthesis.families.smith.design import SmithDesignError
    from pressor.synthesis.families.smith.packaging import package_artifact

    say = progress or (lambda _msg: None)
    box = PredictionErrorBox.from_config(cfg, law="trapezoid")
    _, n_t, n_tau = cfg.grid_points
    n_t, n_tau = max(n_t, 2), max(n_tau, 2)
    say(f"{NAME}: Wirtinger analysis in prediction-error coordinates, T x tau {n_t} x {n_tau}")
    res = certify(box, n_t, n_tau, time_scale_s=cfg.solver.time_scale_s)
    if not res.certified or res.gamma is None or res.certificate is None:
        raise SmithDesignError(
            f"loop gain {cfg.controller.loop_gain:g} not certified on T x tau {n_t} x {n_tau} "
            f"(status {res.status})"
        )
    return package_artifact(
        cfg,
        res,
        "wirtinger, prediction-error coordinates (trapezoid law)",
        "certificate P affine in (T, tau) normalised (1, T_hat, tau_hat)",
    )


FAMILY = SmithPEFamily()
