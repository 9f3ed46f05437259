"""The synthesis certificate carried back to the closed loop (plant + reconstructed controller).

:func:`closed_loop_analysis` builds the 5-block analysis matrix of
:mod:`pressor.synthesis.families.theorem3.lmi` from the closed-loop matrices and the certificate mapped back
by Π1; :func:`certificate_margins` evaluates it at arbitrary points of the box (e.g. cell midpoints
the synthesis never saw).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from pressor.synthesis.families.theorem3.lmi import Problem, assemble, make_problem
from pressor.synthesis.problem import basis
from pressor.synthesis.problem.closed_loop import close_loop
from pressor.synthesis.problem.config import DesignConfig

__all__ = ["certificate_margins", "closed_loop_analysis"]


def closed_loop_analysis(
    prob: Problem, coefs: dict[str, np.ndarray], ctrl: dict[str, np.ndarray], g: int, gamma: float
) -> np.ndarray:
    """The 5-block *analysis* matrix of the closed loop (plant + controller) at node ``g``.

    Independent of the change of variables: the closed-loop matrices are built from the plant and
    the controller ``ctrl`` (scaled coordinates, as from
    :func:`pressor.synthesis.problem.reconstruct.reconstruct_scaled`), and the certificate is carried back
    by Π1 = [[Y, I], [I, 0]] (M = I): ``P = Π1⁻ᵀP̃Π1⁻¹`` (likewise Q, R, Ṗ) and the slack ``𝒳 = Π2
    Π1⁻¹`` with Π2 = [[I, X], [0, Nᵀ]]. Ṗ is taken at the 2³ true rate vertices (not the Z bound),
    so this is the paper's condition.

    Returns
    -------
    numpy.ndarray
        (8, m, m), one matrix per rate vertex; the closed loop is certified at the node if all are
        negative definite.
    """
    rh = prob.rho_hat[g : g + 1]
    p = {k: v[g] for k, v in prob.plant.items()}
    n = prob.layout.n
    X = basis.evaluate(coefs["X"], rh)[0]
    Y = basis.evaluate(coefs["Y"], rh)[0]
    Pt = basis.evaluate(coefs["P"], rh)[0]
    dW = prob.dweights[g]  # (3, nb)
    dPt = np.einsum("ib,brc->irc", dW, coefs["P"])
    Qt, Rt = coefs["Q"][0], coefs["R"][0]
    # the delay value does not enter the matrices (the LMI uses τ̄ only)
    cl = close_loop(SimpleNamespace(**p), SimpleNamespace(**ctrl), 0.0)
    eye, zero = np.eye(n), np.zeros((n, n))
    N = eye - X @ Y
    Pi1 = np.block([[Y, eye], [eye, zero]])
    Pi2 = np.block([[eye, X], [zero, N.T]])
    Pi1i = np.linalg.inv(Pi1)
    Xcl = Pi2 @ Pi1i
    Xcl = 0.5 * (Xcl + Xcl.T)

    def back(m: np.ndarray) -> np.ndarray:
        return Pi1i.T @ m @ Pi1i

    gam = float(gamma)
    out = []
    for s in prob.vertices:
        pdot = back(np.einsum("i,irc->rc", s * prob.nu_hat, dPt))
        out.append(
            assemble(
                Xcl,
                back(Pt),
                pdot,
                back(Qt),
                back(Rt),
                Xcl @ cl.A,
                Xcl @ cl.Ad,
                Xcl @ cl.B,
                cl.C,
                cl.Cd,
                cl.D,
                np.array(gam),
                np.array(s[2] * prob.nu_tau),
                prob.tau_bar_hat,
                prob.cfg.solver.lambda2,
                prob.cfg.solver.lambda3,
            )
        )
    return np.array(out)


def certificate_margins(artifact, rho: np.ndarray) -> np.ndarray:
    """Largest eigenvalue of the closed-loop analysis matrix (all rate vertices) at each ρ.

    Evaluates the *synthesis* certificate (P̃(ρ), Q̃, R̃, X(ρ), Y from the artifact's basis
    coefficients) with the reconstructed controller at arbitrary points, e.g. cell midpoints the
    synthesis never saw. Negative everywhere means the same LKF certifies those frozen points too.
    Not a substitute for the independent verification (:mod:`pressor.synthesis.verification.verify`).

    Parameters
    ----------
    artifact
        A :class:`~pressor.synthesis.artifact.ControllerArtifact`.
    rho
        (G, 3) physical points inside the box.

    Returns
    -------
    numpy.ndarray
        (G,) largest eigenvalues (< 0: certified at that point).
    """
    from dataclasses import replace as _replace

    from pressor.synthesis.problem.config import SolverConfig
    from pressor.synthesis.problem.reconstruct import reconstruct_scaled

    meta = artifact.metadata
    solver = SolverConfig(**meta["design"]["solver"])
    solver = _replace(solver, lambda2=float(meta["lambda2"]), lambda3=float(meta["lambda3"]))
    cfg = DesignConfig(
        model=artifact.model_config,
        grid_points=tuple(len(g) for g in meta["grid"]),  # type: ignore[arg-type]
        solver=solver,
    )
    prob = make_problem(cfg, rho=np.atleast_2d(rho))
    ctrl = reconstruct_scaled(artifact.coefficients, prob.plant, prob.rho_hat)
    out = np.empty(prob.rho.shape[0])
    for g in range(prob.rho.shape[0]):
        kg = {k: v[g] for k, v in ctrl.items()}
        F = closed_loop_analysis(prob, artifact.coefficients, kg, g, artifact.gamma)
        out[g] = np.linalg.eigvalsh(F).max()
    return out
