"""Package a certified Smith design as an artifact, whichever analysis certified it.

Both Smith families (:mod:`pressor.synthesis.families.smith.design`,
:mod:`pressor.synthesis.families.smith.pe_family`) store the same law at the design grid's nodes and differ
only in the certificate and in how the metadata names it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pressor.synthesis.artifact import FORMAT_VERSION, ControllerArtifact, make_artifact
from pressor.synthesis.certificates.interface import AnalysisResult
from pressor.synthesis.families.smith.law import SmithLPV
from pressor.synthesis.problem.config import DesignConfig
from pressor.synthesis.problem.model import dims
from pressor.synthesis.problem.scaling import Scaling

__all__ = ["package_artifact"]


def package_artifact(
    cfg: DesignConfig, res: AnalysisResult, analysis: str, basis: str
) -> ControllerArtifact:
    """The artifact of a certified Smith design: the law at the grid nodes, the certificate ``res``
    (``P``, ``S``, ``R``, ``transform``) and the metadata naming ``analysis`` and the P ``basis``.

    Raises
    ------
    ValueError
        If ``res`` holds no certificate or the design has no loop gain.
    """
    model, family = cfg.model, cfg.controller
    if res.gamma is None or res.certificate is None or family.loop_gain is None:
        raise ValueError("package_artifact needs a certified result and a loop gain")
    law = SmithLPV(family.loop_gain, model.omega, model.lambda_)
    scaling = Scaling.for_box(model.box, cfg.solver.time_scale_s, dims(model).n)
    grid = cfg.grid()
    flat = np.stack(np.meshgrid(*grid, indexing="ij"), axis=-1).reshape(-1, 3)
    gshape = tuple(g.size for g in grid)
    laws = [law.at(p) for p in flat]
    nodes = {
        name: np.stack([getattr(k, name) for k in laws]).reshape(
            *gshape, *getattr(laws[0], name).shape
        )
        for name in ("Ak", "Adk", "Bk", "Ck", "Cdk", "Dk")
    }
    cert = res.certificate
    coefs = {name: np.asarray(cert[name], dtype=float) for name in ("P", "S", "R", "transform")}
    meta: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "box": model.box.tolist(),
        "rate_bounds": model.rate_bounds.tolist(),
        "grid": [g.tolist() for g in grid],
        "basis": basis,
        "model": model.to_dict(),
        "design": cfg.to_dict(),
        "reference": cfg.reference.to_dict(),
        "controller": family.to_dict(),
        "scaling": {
            "time_s": scaling.time_s,
            "sx": scaling.sx.tolist(),
            "sy": scaling.sy.tolist(),
            "rho_center": scaling.rho_center.tolist(),
            "rho_half": scaling.rho_half.tolist(),
        },
        "lambda2": None,
        "lambda3": None,
        "gamma": float(res.gamma),
        "solver": {
            "name": "CLARABEL",
            "status": res.status,
            "analysis": analysis,
            "p_dependence": res.p_dependence,
            "n_lmi": res.n_lmis,
            "notes": list(res.notes),
        },
        "verification": None,
        "created_by": "pressor synth",
    }
    return make_artifact(meta, coefs, nodes)
