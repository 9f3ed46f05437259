"""The synthesis pipeline: config → scaled problem → SDP solve → reconstruction → artifact.

Named stages (CVXPYgen style): :func:`build`, :func:`solve_design`, :func:`to_artifact`;
:func:`synthesize` runs them, with the optional (λ2, λ3) line search of
:mod:`pressor.synthesis.families.theorem3.line_search` in front.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from pressor.synthesis.artifact import FORMAT_VERSION, ControllerArtifact, make_artifact
from pressor.synthesis.families.theorem3 import lmi, lmi_solve
from pressor.synthesis.families.theorem3.family import COEF_NAMES
from pressor.synthesis.problem import basis
from pressor.synthesis.problem.config import DesignConfig
from pressor.synthesis.problem.reconstruct import controllers_at

Progress = Callable[[str], None]


class SynthesisError(RuntimeError):
    """The SDP could not be solved to a usable solution (infeasible or numerical failure)."""


@dataclass
class DesignResult:
    """A solved design: the problem, the solve outcome and the artifact (None if it failed)."""

    cfg: DesignConfig
    result: lmi_solve.SolveResult
    artifact: ControllerArtifact | None
    wall_s: float


def build(cfg: DesignConfig) -> lmi.Problem:
    """Stage 1: the scaled problem on the design grid."""
    return lmi.make_problem(cfg)


def solve_design(
    prob: lmi.Problem, solver_opts: dict | None = None, progress: Progress | None = None
) -> lmi_solve.SolveResult:
    """Stage 2: the SDP (minimise γ, optional back-off); ``progress`` gets one line per iteration."""
    return lmi_solve.solve(prob, solver_opts, progress=progress)


def to_artifact(
    prob: lmi.Problem, res: lmi_solve.SolveResult, extra: dict | None = None
) -> ControllerArtifact:
    """Stage 3: coefficients + controller at the grid nodes + metadata -> artifact.

    Wall-clock figures are deliberately not stored, so the same command reproduces the same bytes.
    """
    if res.x is None:
        raise SynthesisError(f"no solution to package (status {res.status})")
    cfg = prob.cfg
    vals = prob.layout.unpack(res.x[None, :])
    coefs = {k: vals[k][0] for k in COEF_NAMES}
    grid = cfg.grid()
    mesh = np.stack(np.meshgrid(*grid, indexing="ij"), axis=-1)  # (nK, nT, ntau, 3)
    k = controllers_at(coefs, mesh.reshape(-1, 3), prob.scaling, cfg.model)
    gshape = tuple(g.size for g in grid)
    nodes = {name: v.reshape(*gshape, *v.shape[1:]) for name, v in k.items()}
    sc = prob.scaling
    meta: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "box": cfg.model.box.tolist(),
        "rate_bounds": cfg.model.rate_bounds.tolist(),
        "grid": [g.tolist() for g in grid],
        "basis": basis.BASIS_NAME,
        "model": cfg.model.to_dict(),
        "design": cfg.to_dict(),
        "reference": cfg.reference.to_dict(),
        "scaling": {
            "time_s": sc.time_s,
            "sx": sc.sx.tolist(),
            "sy": sc.sy.tolist(),
            "rho_center": sc.rho_center.tolist(),
            "rho_half": sc.rho_half.tolist(),
        },
        "lambda2": cfg.solver.lambda2,
        "lambda3": cfg.solver.lambda3,
        "gamma": float(res.gamma),
        "solver": {
            "name": "CLARABEL",
            "status": res.status,
            "iterations": res.iterations,
            "n_lmi": res.n_lmi,
            "lmi_size": res.lmi_size,
        },
        "factorisation": "M = I, N = I - X(rho) Y",
        "verification": None,
        "created_by": "pressor synth",
    }
    if extra:
        meta.update(extra)
    return make_artifact(meta, coefs, nodes)


def synthesize(
    cfg: DesignConfig,
    progress: Progress | None = None,
    solver_opts: dict | None = None,
    extra_meta: dict | None = None,
) -> DesignResult:
    """Run the pipeline at the config's fixed (λ2, λ3).

    Raises
    ------
    SynthesisError
        If the solver returns no solution or the solution is not (nearly) optimal.
    """
    say = progress or (lambda _msg: None)
    t0 = time.perf_counter()
    prob = build(cfg)
    say(
        f"solve: grid {cfg.grid_points}, lambda2={cfg.solver.lambda2:g}, "
        f"lambda3={cfg.solver.lambda3:g} ({prob.rho.shape[0]} nodes) ..."
    )
    res = solve_design(prob, solver_opts, progress)
    say(
        f"solve: status {res.status}, gamma {res.gamma:.4g}, build {res.build_time_s:.2f} s, "
        f"solve {res.solve_time_s:.1f} s, {res.iterations} iterations"
    )
    if res.x is None or not res.status.startswith("optimal"):
        raise SynthesisError(f"solver status {res.status!r} (gamma {res.gamma})")
    art = to_artifact(prob, res, extra_meta)
    return DesignResult(cfg, res, art, time.perf_counter() - t0)
