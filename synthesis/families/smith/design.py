"""The shipped family's design stage: certify the closed-form Smith law, package the artifact.

There is no synthesis LMI for this family (:mod:`pressor.synthesis.families.smith.family`): the law is
``SmithLPV(loop_gain, Ω, Λ).at(ρ)`` (:mod:`pressor.synthesis.families.smith.law`) and the design stage is
the Wirtinger-based analysis LMI
(:func:`pressor.synthesis.certificates.wirtinger.analysis.analyse_wirtinger`, one LMI per point with rate
slacks, P(ρ) quadratic in ρ̂, S and R constant) written in K-scaled coordinates
(:mod:`pressor.synthesis.certificates.wirtinger.k_scaling`: the ml/h states u and û times K, so S and R are
K(t)-dependent in the original state; docs/notes/certificate-structure.md, section 2c) over the closed
loops at the grid nodes. The law's gains scale like 1/K, which is why the functional is written in
K-scaled coordinates. :func:`certify_smith` is that analysis on any set of points; the design
(:func:`design_smith`, the design grid, minimum γ at the strictness :data:`DESIGN_EPSILON`, one
solve; a back-off solve only if that optimum fails the re-check) and the verification (``pressor
verify``, a denser grid, γ capped, one solve) both call it.

Conditioning: the K-scaled state is whitened by the nominal point's own frozen certificate and
balanced (a constant congruence: feasibility and γ unchanged); time is scaled by the design's
``solver.time_scale_s`` (the only [solver] key this family uses).

Other formulations of the same analysis (:class:`WirtingerForm`: vertex form, working set,
coupling, parameters of P, plain coordinates) are reached through :func:`certify_in_form` and
:func:`design_in_form`, the builders :mod:`research.synthesis_forms` calls; the shipped functions take
none of those options.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pressor.synthesis.artifact import ControllerArtifact
from pressor.synthesis.certificates.interface import AnalysisResult
from pressor.synthesis.certificates.state_transform import conditioning_transform
from pressor.synthesis.certificates.wirtinger.analysis import analyse_wirtinger, recheck_certificate
from pressor.synthesis.certificates.wirtinger.conic import COUPLINGS, RATE_FORMS
from pressor.synthesis.certificates.wirtinger.k_scaling import KScaling, k_scaled_system
from pressor.synthesis.families.smith.family import NAME
from pressor.synthesis.families.smith.law import SmithLPV
from pressor.synthesis.families.smith.packaging import package_artifact
from pressor.synthesis.problem.closed_loop import DelaySystem, close_loop
from pressor.synthesis.problem.config import NOMINAL_RHO, DesignConfig, ModelConfig
from pressor.synthesis.problem.model import I_U, I_XE, dims, plant_at
from pressor.synthesis.problem.reconstruct import scaling_of
from pressor.synthesis.problem.scaling import Scaling

__all__ = [
    "COORDINATES",
    "SHIPPED_FORM",
    "SmithDesignError",
    "WirtingerForm",
    "certify_in_form",
    "certify_smith",
    "design_in_form",
    "design_smith",
    "nominal_centre",
    "recheck_smith_artifact",
    "smith_loops",
]

Progress = Callable[[str], None]
#: Lyapunov matrix P(ρ) of the certificate (the artifact stores its 7 basis terms)
P_DEPENDENCE = "quadratic"
#: strictness of the design's minimum-γ solve (every LMI <= -ε I, P, S, R >= ε I, scaled units):
#: large enough that the optimum passes the floating-point re-check at once, so the back-off solve
#: (the fallback) is not needed (docs/notes/benchmarks.md, "Design measurements")
DESIGN_EPSILON = 1e-3
#: Clarabel settings of the capped (feasibility) solve: maximising the common margin t to 1e-8
#: only sharpens t and iterative refinement of each KKT solve only sharpens the iterate; the
#: verdict is the re-check, so both are relaxed (docs/notes/benchmarks.md, "Design measurements")
FEASIBILITY_SOLVER_OPTIONS: dict[str, Any] = {
    "tol_gap_abs": 1e-4,
    "tol_gap_rel": 1e-4,
    "iterative_refinement_enable": False,
}


#: coordinates of the functional: "k_scaled" (u and û times K, shipped) or "plain" (own states)
COORDINATES = ("k_scaled", "plain")


class SmithDesignError(RuntimeError):
    """The Wirtinger analysis did not certify the Smith law on the design grid."""


def smith_loops(law: SmithLPV, model: ModelConfig, points: np.ndarray) -> list[DelaySystem]:
    """The frozen closed loops plant + Smith law at each ρ (rows of ``points``, physical units)."""
    return [close_loop(plant_at(p, model), law.at(p), float(p[2])) for p in points]


def nominal_centre(law: SmithLPV, model: ModelConfig) -> tuple[DelaySystem, np.ndarray]:
    """The ``centre`` of :func:`certify_smith`: the loop at the nominal ρ (clipped to the box), ρ."""
    nominal = np.clip(np.asarray(NOMINAL_RHO, dtype=float), model.box[:, 0], model.box[:, 1])
    return smith_loops(law, model, nominal[None, :])[0], nominal


@dataclass(frozen=True)
class WirtingerForm:
    """How the analysis LMI is written; the defaults (:data:`SHIPPED_FORM`) are what ships.

    Attributes
    ----------
    rate_form
        "bound" (one LMI per point with rate slacks) or "vertex" (every rate vertex as its own
        LMI: the straightforward form).
    working_set
        None (the LMI imposed at every point) or k >= 1: imposed at k spread points, every point
        and rate vertex re-checked (the verdict covers all the points either way).
    coupling
        "dense" (the LMIs written in the P basis terms) or "per_point" (a copy of P(ρ_k) per
        imposed point, tied by equalities: the same feasible set, a sparser solve).
    p_params
        Indices into (K, T, τ) of the parameters P depends on (None: all three).
    coordinates
        "k_scaled" (the ml/h states u and û times K,
        :mod:`pressor.synthesis.certificates.wirtinger.k_scaling`) or "plain" (the functional in the loops'
        own states).

    Raises
    ------
    ValueError
        ``coordinates``, ``coupling`` or ``rate_form`` outside its allowed set.
    """

    rate_form: str = "bound"
    working_set: int | None = None
    coupling: str = "dense"
    p_params: Sequence[int] | None = None
    coordinates: str = "k_scaled"

    def __post_init__(self) -> None:
        for name, value, allowed in (
            ("coordinates", self.coordinates, COORDINATES),
            ("coupling", self.coupling, COUPLINGS),
            ("rate_form", self.rate_form, RATE_FORMS),
        ):
            if value not in allowed:
                raise ValueError(f"WirtingerForm: {name}={value!r} must be one of {allowed}")


#: the formulation the design and ``pressor verify`` run
SHIPPED_FORM = WirtingerForm()


def certify_smith(
    systems: list[DelaySystem],
    points: np.ndarray,
    centre: tuple[DelaySystem, np.ndarray],
    model: ModelConfig,
    scaling: Scaling,
    gamma_cap: float | None = None,
    progress: Progress | None = None,
    p_dependence: str = P_DEPENDENCE,
    epsilon: float = 1e-6,
    law: SmithLPV | None = None,
) -> AnalysisResult:
    """The Wirtinger analysis (rate-bound form) of the frozen Smith loops ``systems`` at ``points``.

    Parameters
    ----------
    systems
        The closed loops plant + Smith law, one per row of ``points``.
    points
        (G, 3) physical (K [mmHg/(ml/h)], T [s], τ [s]); every τ > 0.
    centre
        A closed loop and its ρ whose frozen certificate conditions the state (the nominal plant).
    model
        Plant model, box and rate bounds (the certificate covers |ρ̇| within ``model.rate_bounds``).
    scaling
        ρ normalisation and the time unit of the scaled problem.
    gamma_cap
        None: minimise γ (back-off solve if the optimum fails the re-check); a number: one
        feasibility solve with γ ≤ gamma_cap (what a verifier uses).
    progress
        One line per stage and per solver iteration.
    p_dependence
        P(ρ) basis: "quadratic" (default, 7 terms), "affine" or "constant".
    epsilon
        Strictness of the solve (scaled units; :data:`DESIGN_EPSILON` for the design).
    law
        The law of ``systems``; needed (and only used) with a relative K rate, whose certificate
        covers the law's bumpless integral (:func:`bumpless_rows`).
    """
    return certify_in_form(
        SHIPPED_FORM,
        systems,
        points,
        centre,
        model,
        scaling,
        gamma_cap,
        progress,
        p_dependence,
        epsilon,
        law,
    )


def certify_in_form(
    form: WirtingerForm,
    systems: list[DelaySystem],
    points: np.ndarray,
    centre: tuple[DelaySystem, np.ndarray],
    model: ModelConfig,
    scaling: Scaling,
    gamma_cap: float | None = None,
    progress: Progress | None = None,
    p_dependence: str = P_DEPENDENCE,
    epsilon: float = 1e-6,
    law: SmithLPV | None = None,
) -> AnalysisResult:
    """:func:`certify_smith` written in ``form`` (the builder :mod:`research.synthesis_forms` calls).

    Raises
    ------
    ValueError
        ``form.working_set`` below 1 or ``form.p_params`` not distinct indices in 0..2.
    """
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    c_sys, c_rho = centre
    k_scaling = None
    if form.coordinates == "k_scaled":
        k_scaling = _k_scaling(pts, model, law)
        c_sys = k_scaled_system(c_sys, float(c_rho[0]), k_scaling.states)

    zero = np.zeros(3)
    c0 = analyse_wirtinger(
        [c_sys], scaling.to_hat(c_rho)[None], zero, zero, float(c_rho[2]), "constant"
    )
    tx = None
    if c0.p0_phys is not None:
        try:
            tx = conditioning_transform(c0.p0_phys, c_sys, scaling.time_s)
        except ValueError:
            tx = None
    if progress:
        progress(
            f"Wirtinger analysis: conditioning transform from rho {c_rho.tolist()} ({tx is not None})"
        )
    rate_form = form.rate_form
    if model.k_rate_relative:
        # the bumpless integral's kappa term is far from the Young bound's reach: exact vertices
        rate_form = "vertex"
    return analyse_wirtinger(
        systems,
        *_analysis_inputs(pts, model, scaling),
        p_dependence=p_dependence,
        time_scale_s=scaling.time_s,
        state_transform=tx,
        epsilon=epsilon,
        gamma_cap=gamma_cap,
        solver_options=None if gamma_cap is None else FEASIBILITY_SOLVER_OPTIONS,
        working_set=form.working_set,
        progress=progress,
        rate_form=rate_form,
        coupling=form.coupling,
        p_params=form.p_params,
        k_scaling=k_scaling,
    )


def _k_scaling(points: np.ndarray, model: ModelConfig, law: SmithLPV | None = None) -> KScaling:
    """The K-scaling of the Smith loops at ``points``: the ml/h states (the plant's infusion u and
    the controller's model input û, its first state) times K, K's rate bound from the model.

    With a relative K rate (``model.k_rate_relative``) the bound is on d(ln K)/dt and the law is
    the one that absorbs a change of K in its integral (:func:`bumpless_rows`, needs ``law``)."""
    scaled = (I_U, plant_at(points[0], model).A.shape[0])
    if not model.k_rate_relative:
        return KScaling(points[:, 0], float(model.rate_bounds[0]), scaled)
    if law is None:
        raise ValueError("a relative K rate needs the law (its bumpless integral's kappa rows)")
    rows = np.stack([bumpless_rows(law, model, p, scaled) for p in points])
    up = model.k_rate_up_per_s
    return KScaling(points[:, 0], float(model.rate_bounds[0]), scaled, 0, True, rows, up)


def bumpless_rows(
    law: SmithLPV, model: ModelConfig, rho: np.ndarray, scaled: tuple[int, ...]
) -> np.ndarray:
    """The kappa rows of the bumpless Smith law at ``rho``, in K-scaled coordinates.

    The law keeps its command's rate u_a continuous when K changes: the integral x_e absorbs it,
    ``x_e <- (K'/K) x_e + (1 - K'/K)(τ(ŷ + ŷ(t - τ))/2 - T e_p)`` (the generated module does this
    at every tick its K moves; :mod:`pressor.synthesis.families.smith.law`). With κ = d(ln K)/dt that is
    ``dx_e/dt += κ (T e_p + x_e - τ(ŷ + ŷ(t - τ))/2) = κ (K T / g) u_a``, u_a the law's output.
    Returns the (n, 2n + nw) rows ``[E, E_d, E_w]`` of that term over the closed loop's
    ``[x, x(t - τ), w]`` (only the x_e row is non-zero), with the scaled states divided by K.
    """
    pm, ctrl = plant_at(rho, model), law.at(rho)
    k, t_s = float(rho[0]), float(rho[1])
    row_x = np.concatenate([ctrl.Dk @ pm.C2, ctrl.Ck], axis=1)
    row_d = np.concatenate([ctrl.Dk @ pm.C2d, ctrl.Cdk], axis=1)
    row_w = ctrl.Dk @ pm.D21
    n = row_x.shape[1]
    d_inv = np.ones(n)
    d_inv[list(scaled)] = 1.0 / k
    factor = k * t_s / law.loop_gain
    rows = np.zeros((n, 2 * n + row_w.shape[1]))
    rows[I_XE, :n] = factor * row_x[0] * d_inv
    rows[I_XE, n : 2 * n] = factor * row_d[0] * d_inv
    rows[I_XE, 2 * n :] = factor * row_w[0]
    return rows


def _analysis_inputs(
    points: np.ndarray, model: ModelConfig, scaling: Scaling
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(ρ̂, rate bounds of ρ̂ per s, dτ/dρ̂ in s, τ_max in s) of the analysis at ``points``.

    With a relative K rate ν the K coordinate of ρ̂ moves at most ν·K_max (the box's top) per s."""
    rates = np.asarray(model.rate_bounds, dtype=float).copy()
    if model.k_rate_relative:
        up = rates[0] if model.k_rate_up_per_s is None else model.k_rate_up_per_s
        rates[0] = max(rates[0], up) * float(np.asarray(model.box, dtype=float)[0, 1])
    return (
        scaling.to_hat(points),
        rates / scaling.rho_half,
        np.array([0.0, 0.0, scaling.rho_half[2]]),
        float(np.asarray(model.box, dtype=float)[2, 1]),
    )


def recheck_smith_artifact(artifact: ControllerArtifact) -> tuple[bool, np.ndarray]:
    """Re-check a "smith" artifact's stored certificate on its design grid, without a solve.

    The law is rebuilt from the artifact's family and model (closed form), the stored P, S, R,
    transform and γ are put back into every vertex LMI of every grid point (K-scaled, rate-bound
    analysis), and each is evaluated in floating point: the verdict does not depend on the solver,
    its backend or the CPU that found the certificate.

    Returns
    -------
    (certified, margins)
        As :func:`pressor.synthesis.certificates.wirtinger.analysis.recheck_certificate`: margins per grid
        point.

    Raises
    ------
    ValueError
        If the artifact is not of this family or its certificate does not fit the analysis.
    """
    family, model = artifact.family, artifact.model_config
    if family.structure != NAME or family.loop_gain is None:
        raise ValueError(
            f"recheck_smith_artifact needs a {NAME!r} artifact, got {family.structure!r}"
        )
    law = SmithLPV(family.loop_gain, model.omega, model.lambda_)
    flat = np.stack(np.meshgrid(*artifact.grid, indexing="ij"), axis=-1).reshape(-1, 3)
    scaling = scaling_of(artifact)
    cert = {**artifact.coefficients, "time_scale_s": scaling.time_s}
    return recheck_certificate(
        smith_loops(law, model, flat),
        *_analysis_inputs(flat, model, scaling),
        cert,
        artifact.gamma,
        P_DEPENDENCE,
        _k_scaling(flat, model, law),
    )


def design_smith(cfg: DesignConfig, progress: Progress | None = None) -> ControllerArtifact:
    """Certify the config's Smith law on its design grid and package the artifact.

    Raises
    ------
    SmithDesignError
        If the analysis does not certify the law on the grid (no artifact then).
    """
    return design_in_form(cfg, SHIPPED_FORM, progress)


def design_in_form(
    cfg: DesignConfig, form: WirtingerForm, progress: Progress | None = None
) -> ControllerArtifact:
    """:func:`design_smith` with the analysis written in ``form`` (for :mod:`research.synthesis_forms`;
    raises as it does)."""
    family = cfg.controller
    if family.structure != NAME or family.loop_gain is None:
        raise ValueError(f"design_smith needs a {NAME!r} design, got {family.structure!r}")
    model = cfg.model
    law = SmithLPV(family.loop_gain, model.omega, model.lambda_)
    pd = dims(model)
    scaling = Scaling.for_box(model.box, cfg.solver.time_scale_s, pd.n)
    grid = cfg.grid()
    mesh = np.stack(np.meshgrid(*grid, indexing="ij"), axis=-1)  # (nK, nT, ntau, 3)
    flat = mesh.reshape(-1, 3)
    say = progress or (lambda _msg: None)
    say(
        f"smith loop gain {family.loop_gain:g}: Wirtinger analysis on the design grid "
        f"{cfg.grid_points} ({flat.shape[0]} points), P {P_DEPENDENCE}, rate-bound form"
    )
    res = certify_in_form(
        form,
        smith_loops(law, model, flat),
        flat,
        nominal_centre(law, model),
        model,
        scaling,
        progress=progress,
        epsilon=DESIGN_EPSILON,
        law=law,
    )
    if not res.certified or res.gamma is None or res.certificate is None:
        margin = float(np.nanmin(res.margins)) if np.isfinite(res.margins).any() else None
        raise SmithDesignError(
            f"loop gain {family.loop_gain:g} not certified on the design grid "
            f"{cfg.grid_points} (status {res.status}, gamma {res.gamma}, worst margin {margin})"
        )
    say(f"certified: gamma {res.gamma:.4g} ({res.solve_time_s:.1f} s)")
    analysis = f"wirtinger, {form.coordinates}, rate_form {form.rate_form}"
    basis = f"certificate P {P_DEPENDENCE} in rho_hat (1, rho_i, rho_i^2/2)"
    return package_artifact(cfg, res, analysis, basis)
