"""Research entry: the formulations the shipped design and verification are compared with.

Nothing in ``pressor`` calls this module; ``benchmarks/`` and the tests of those formulations do.
The shipped functions (:func:`pressor.synthesis.families.smith.design.certify_smith`,
:func:`pressor.synthesis.families.smith.design.design_smith`,
:func:`pressor.synthesis.verification.verify.verify_artifact`, the family objects of
:mod:`pressor.synthesis.families.registry`) take only what the shipped path uses; the options here reach the
same analyses through their builders:

* :func:`certify_smith_form` — the shipped family's Wirtinger analysis with any
  :class:`~pressor.synthesis.families.smith.design.WirtingerForm` (vertex form, working set, per-point
  coupling, parameters of P, plain coordinates);
* :func:`design_smith_form` — its design stage in another rate form;
* :func:`verify_all_points_at_once` — ``pressor verify`` with check (a) imposed at every dense point
  and rate vertex in one solve (the straightforward formulation), for either family;
* :func:`synth_case` — one synthesis case of ``benchmarks/synthesis_speed.py``: what ``pressor
  synth`` solves, or the straightforward formulation of the same design.

It lives in the package (not in ``benchmarks/``) because it calls the families' internal builders
and the tests of those formulations import it; ``benchmarks/`` is not a package, and its
``synthesis.py`` would shadow this one.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from pressor.synthesis.artifact import ControllerArtifact
from pressor.synthesis.certificates.interface import AnalysisResult
from pressor.synthesis.families.smith.design import (
    P_DEPENDENCE,
    WirtingerForm,
    certify_in_form,
    design_in_form,
)
from pressor.synthesis.families.smith.family import SmithFamily, capped_analysis
from pressor.synthesis.families.smith.pe_family import SmithPEFamily
from pressor.synthesis.families.theorem3.family import Theorem3Family, jensen_analysis
from pressor.synthesis.problem.closed_loop import DelaySystem
from pressor.synthesis.problem.config import DesignConfig, ModelConfig
from pressor.synthesis.problem.scaling import Scaling
from pressor.synthesis.verification.analysis import Analysis
from pressor.synthesis.verification.verify import VerificationReport, verify_with

__all__ = [
    "certify_smith_form",
    "design_smith_form",
    "synth_case",
    "verify_all_points_at_once",
]

Progress = Callable[[str], None]


def certify_smith_form(
    systems: list[DelaySystem],
    points: np.ndarray,
    centre: tuple[DelaySystem, np.ndarray],
    model: ModelConfig,
    scaling: Scaling,
    gamma_cap: float | None = None,
    progress: Progress | None = None,
    p_dependence: str = P_DEPENDENCE,
    epsilon: float = 1e-6,
    *,
    rate_form: str = "bound",
    working_set: int | None = None,
    coupling: str = "dense",
    p_params: Sequence[int] | None = None,
    coordinates: str = "k_scaled",
) -> AnalysisResult:
    """:func:`pressor.synthesis.families.smith.design.certify_smith` with the formulation options.

    The positional parameters are :func:`~pressor.synthesis.families.smith.design.certify_smith`'s; the
    keyword ones are the fields of :class:`~pressor.synthesis.families.smith.design.WirtingerForm`
    (defaults: the shipped formulation).

    Raises
    ------
    ValueError
        ``coordinates``, ``coupling`` or ``rate_form`` outside its allowed set (before any solve);
        ``working_set`` below 1 or ``p_params`` not distinct indices in 0..2.
    """
    form = WirtingerForm(rate_form, working_set, coupling, p_params, coordinates)
    return certify_in_form(
        form, systems, points, centre, model, scaling, gamma_cap, progress, p_dependence, epsilon
    )


def design_smith_form(
    cfg: DesignConfig, rate_form: str = "bound", progress: Progress | None = None
) -> ControllerArtifact:
    """:func:`pressor.synthesis.families.smith.design.design_smith` with the analysis in ``rate_form``.

    Raises
    ------
    pressor.synthesis.families.smith.design.SmithDesignError
        If the analysis does not certify the law on the grid.
    """
    return design_in_form(cfg, WirtingerForm(rate_form=rate_form), progress)


def _smith_all_vertices(
    artifact: ControllerArtifact,
    systems: list[DelaySystem],
    mesh: np.ndarray,
    centre: tuple[DelaySystem, np.ndarray],
    p_dependence: str,
    progress: Progress,
) -> AnalysisResult:
    """The shipped family's check (a) with every rate vertex as its own LMI."""
    form = WirtingerForm(rate_form="vertex")
    return capped_analysis(
        form, "all vertices", artifact, systems, mesh, centre, p_dependence, progress
    )


def _jensen_all_points(
    artifact: ControllerArtifact,
    systems: list[DelaySystem],
    mesh: np.ndarray,
    centre: tuple[DelaySystem, np.ndarray],
    p_dependence: str,
    progress: Progress,
) -> AnalysisResult:
    """The Theorem-3 family's check (a) at every dense point and rate vertex in one solve."""
    return jensen_analysis(artifact, systems, mesh, p_dependence, progress, all_points_at_once=True)


#: family object type -> its straightforward check (a)
_ALL_POINTS: dict[type, Analysis] = {
    SmithFamily: _smith_all_vertices,
    # its check (a) is already every point and rate vertex in one solve
    SmithPEFamily: SmithPEFamily().analysis,
    Theorem3Family: _jensen_all_points,
}


def verify_all_points_at_once(
    artifact: ControllerArtifact,
    density: int = 2,
    progress: Progress | None = None,
    p_dependence: str = "quadratic",
) -> VerificationReport:
    """``verify_artifact`` with check (a) in the straightforward form.

    Every dense point and rate vertex is imposed in one solve: for the shipped family every rate
    vertex as its own LMI instead of the rate-bound form, for the Theorem-3 family instead of the
    working set. The certificate is the same re-check either way.
    """
    analysis = _ALL_POINTS[type(artifact.family.impl)]
    return verify_with(artifact, analysis, density, progress, p_dependence)


def _smith_synth(cfg: DesignConfig, straightforward: bool) -> dict[str, str]:
    art = design_smith_form(cfg, "vertex" if straightforward else "bound")
    sol = art.metadata["solver"]
    return {
        "outcome": f"gamma={art.gamma:.4f} {sol['status']}",
        "detail": f"{cfg.controller.structure}, {sol['n_lmi']} vertex LMIs re-checked, "
        f"{sol['analysis']}",
    }


def _theorem3_synth(cfg: DesignConfig, straightforward: bool) -> dict[str, str]:
    from pressor.synthesis.families.theorem3 import lmi, lmi_solve

    prob = lmi.make_problem(cfg)
    if straightforward:
        from research.synthesis_forms.naive_lmi import solve_naive

        res = solve_naive(prob)
    else:
        res = lmi_solve.solve(prob)
    return {
        "outcome": f"gamma={res.gamma:.4f} {res.status}",
        "detail": f"{res.n_lmi} LMIs of {res.lmi_size}, build {res.build_time_s:.2f} s, "
        f"{res.iterations} iterations",
    }


def _smith_pe_synth(cfg: DesignConfig, straightforward: bool) -> dict[str, str]:
    """The "smith-pe" design: its analysis has one form (every vertex), so both cases are it."""
    art = SmithPEFamily().certified_artifact(cfg)
    sol = art.metadata["solver"]
    return {
        "outcome": f"gamma={art.gamma:.4f} {sol['status']}",
        "detail": f"{cfg.controller.structure}, {sol['n_lmi']} vertex LMIs re-checked, "
        f"{sol['analysis']}",
    }


#: family object type -> its synthesis benchmark case
_SYNTH_CASES: dict[type, Callable[[DesignConfig, bool], dict[str, str]]] = {
    SmithFamily: _smith_synth,
    SmithPEFamily: _smith_pe_synth,
    Theorem3Family: _theorem3_synth,
}


def synth_case(cfg: DesignConfig, straightforward: bool) -> dict[str, Any]:
    """One synthesis case of the config's family: ``outcome`` and ``detail`` lines.

    ``straightforward`` False: what ``pressor synth`` solves (the shipped family: the design's
    rate-bound analysis; the Theorem-3 family: the batched sparse SDP of
    :func:`pressor.synthesis.families.theorem3.lmi_solve.solve`); True: the straightforward formulation of
    the same design (every rate vertex as its own LMI; the naive per-point cvxpy SDP of
    :mod:`research.synthesis_forms.naive_lmi`).
    """
    return _SYNTH_CASES[type(cfg.controller.impl)](cfg, straightforward)
