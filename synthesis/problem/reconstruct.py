"""Controller reconstruction from the Theorem 3 variables, at any ρ in the box.

Factorisation (deviation from the paper's "any N, M with I − XY = N Mᵀ"): **M = I, N = I − X(ρ)Y**,
the same smooth, deterministic choice at every ρ (never a per-point SVD), so all ρ share one
controller state coordinate system and codegen may interpolate between nodes. It is also the
choice that keeps the congruence Π1 = [[Y, I], [Mᵀ, 0]] constant when Y is constant
(see :mod:`pressor.synthesis.families.theorem3.lmi`). N is invertible because Ṽ = [[Y, I], [I, X]] ≻ 0
implies X ≻ Y⁻¹.

Inverting the paper's change of variables with M = I (scaled coordinates)::

    Dk  = D̂k
    Cdk = Ĉd − Dk C2d Y
    Ck  = Ĉ  − Dk C2 Y
    Bk  = N⁻¹ (B̂ − X B2 Dk)
    Adk = N⁻¹ (Âd − X Ad Y − X B2 Dk C2d Y − N Bk C2d Y − X B2 Cdk)
    Ak  = N⁻¹ (Â  − X A Y  − X B2 Dk C2 Y  − N Bk C2 Y  − X B2 Ck)

then :func:`pressor.synthesis.problem.scaling.unscale_controller` maps to physical units (time in s).

:func:`controller_at` checks ρ against the box and asks the artifact's family for its controller
there (:meth:`pressor.synthesis.families.registry.Family.controller_at`: this reconstruction for the
Theorem-3 family, a closed-form law for the shipped one), so codegen, ``pressor verify`` and the
closed-loop tools all see the same law.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from pressor.synthesis.problem import basis
from pressor.synthesis.problem.model import plant_batch
from pressor.synthesis.problem.scaling import Scaling, unscale_controller

if TYPE_CHECKING:
    # type-only: the artifact is built from problem/ (config, model, reference), so loading it here
    # would point problem/ back up at artifact.py
    from pressor.synthesis.artifact import ControllerArtifact


@dataclass(frozen=True)
class DelayedController:
    """The full-order delayed controller at one frozen ρ, physical units (time in s)::

        dx_k/dt = Ak x_k + Adk x_k(t − τ) + Bk y,     u_a = Ck x_k + Cdk x_k(t − τ) + Dk y

    with ``y = [e (mmHg), x_e (mmHg·s)]``, e = target − MAP, x_e = ∫ e dt, and the infusion
    command u (ml/h) the state of ``du/dt = −Λ u + Ω u_a``.
    """

    Ak: np.ndarray
    Adk: np.ndarray
    Bk: np.ndarray
    Ck: np.ndarray
    Cdk: np.ndarray
    Dk: np.ndarray
    rho: np.ndarray
    tau_s: float


def scaling_of(artifact: ControllerArtifact) -> Scaling:
    """The :class:`~pressor.synthesis.problem.scaling.Scaling` stored in the artifact."""
    s = artifact.metadata["scaling"]
    return Scaling(
        time_s=float(s["time_s"]),
        sx=np.asarray(s["sx"], dtype=float),
        sy=np.asarray(s["sy"], dtype=float),
        rho_center=np.asarray(s["rho_center"], dtype=float),
        rho_half=np.asarray(s["rho_half"], dtype=float),
    )


def reconstruct_scaled(
    coefs: dict[str, np.ndarray], plant_s: dict[str, np.ndarray], rho_hat: np.ndarray
) -> dict[str, np.ndarray]:
    """Controller matrices in scaled coordinates at a batch of points.

    Parameters
    ----------
    coefs
        Decision coefficients name -> (nb, r, c).
    plant_s
        Scaled plant matrices, name -> (G, r, c).
    rho_hat
        (G, 3) scaled parameters.

    Returns
    -------
    dict
        ``Ak, Adk, Bk, Ck, Cdk, Dk`` with leading axis G.
    """

    def ev(name: str) -> np.ndarray:
        return basis.evaluate(coefs[name], rho_hat)

    X, Y = ev("X"), ev("Y")
    Ah, Adh, Bh, Ch, Cdh, Dk = (ev(k) for k in ("Ah", "Adh", "Bh", "Ch", "Cdh", "Dk"))
    A, Ad, B2 = plant_s["A"], plant_s["Ad"], plant_s["B2"]
    C2, C2d = plant_s["C2"], plant_s["C2d"]
    n = X.shape[-1]
    N = np.eye(n) - X @ Y
    Cdk = Cdh - Dk @ C2d @ Y
    Ck = Ch - Dk @ C2 @ Y
    Bk = np.linalg.solve(N, Bh - X @ B2 @ Dk)
    XB2 = X @ B2
    Adk = np.linalg.solve(N, Adh - X @ Ad @ Y - XB2 @ Dk @ C2d @ Y - N @ Bk @ C2d @ Y - XB2 @ Cdk)
    Ak = np.linalg.solve(N, Ah - X @ A @ Y - XB2 @ Dk @ C2 @ Y - N @ Bk @ C2 @ Y - XB2 @ Ck)
    return {"Ak": Ak, "Adk": Adk, "Bk": Bk, "Ck": Ck, "Cdk": Cdk, "Dk": Dk}


def controllers_at(
    coefs: dict[str, np.ndarray], rho: np.ndarray, scaling: Scaling, model_cfg
) -> dict[str, np.ndarray]:
    """Physical-unit controllers at a batch of physical ρ (G, 3): name -> (G, r, c)."""
    rho = np.atleast_2d(np.asarray(rho, dtype=float))
    ps = scaling.plant(plant_batch(rho, model_cfg))
    k = reconstruct_scaled(coefs, ps, scaling.to_hat(rho))
    return unscale_controller(k, scaling)


def controller_at(
    artifact: ControllerArtifact, rho: tuple[float, float, float] | np.ndarray
) -> DelayedController:
    """The delayed controller at ρ = (K [mmHg/(ml/h)], T [s], τ [s]) inside the artifact's box.

    The artifact's family gives the controller
    (:meth:`pressor.synthesis.families.registry.Family.controller_at`).

    Raises
    ------
    ValueError
        If ρ is not finite or lies outside the design box (callers clamp first; this function
        never extrapolates).
    """
    r = np.asarray(rho, dtype=float).reshape(3)
    box = artifact.box
    tol = 1e-9 * np.maximum(1.0, np.abs(box).max(axis=1))
    if not np.all(np.isfinite(r)) or np.any(r < box[:, 0] - tol) or np.any(r > box[:, 1] + tol):
        raise ValueError(f"rho={r.tolist()!r} outside the design box {box.tolist()!r}")
    return artifact.family.impl.controller_at(artifact, np.clip(r, box[:, 0], box[:, 1]))
