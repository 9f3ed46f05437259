"""The closed-loop delay system: augmented MAP plant + delayed full-order LPV controller.

At a frozen parameter point rho = (K, T, tau) the plant (``pressor.synthesis.problem.model.plant_at``; state
x_a = [dMAP mmHg, u ml/h, x_e mmHg*s], the input filter du/dt = -Lambda u + Omega u_a already part
of A and B2) and the reconstructed controller (``pressor.synthesis.problem.reconstruct.controller_at``;
state x_k) close into (paper eq. "closed-loop system", physical units, time in s)::

    dx_cl/dt = A_cl x_cl + Ad_cl x_cl(t - tau) + B_cl w
    z        = C_cl x_cl + Cd_cl x_cl(t - tau) + D_cl w,        x_cl = [x_a; x_k]

    A_cl  = [[A + B2 Dk C2,   B2 Ck], [Bk C2,   Ak ]]
    Ad_cl = [[Ad + B2 Dk C2d, B2 Cdk], [Bk C2d, Adk]]
    B_cl  = [[B1 + B2 Dk D21], [Bk D21]]
    C_cl  = [C1 + D12 Dk C2,  D12 Ck],  Cd_cl = [C1d + D12 Dk C2d, D12 Cdk],  D_cl = D11 + D12 Dk D21

Only plain matrices go in: any object with the ``PlantMatrices`` field names and any object with
``Ak, Adk, Bk, Ck, Cdk, Dk`` attributes will do, so the verification can close loops the synthesis
never produced (e.g. a PI baseline written as a static output feedback on y = [e; x_e]).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["DelaySystem", "OutputFeedback", "close_loop"]

Matrix = NDArray[np.float64]


@dataclass(frozen=True)
class OutputFeedback:
    """A delayed controller in the LPV controller's matrix interface (time in s).

    ``dx_k/dt = Ak x_k + Adk x_k(t - tau) + Bk y``, ``u = Ck x_k + Cdk x_k(t - tau) + Dk y``.
    """

    Ak: NDArray[np.float64]
    Adk: NDArray[np.float64]
    Bk: NDArray[np.float64]
    Ck: NDArray[np.float64]
    Cdk: NDArray[np.float64]
    Dk: NDArray[np.float64]


@dataclass(frozen=True)
class DelaySystem:
    """A linear system with one state delay, ``dx/dt = A x + Ad x(t - tau) + B w``.

    Attributes
    ----------
    A, Ad, B
        Dynamics (1/s) and exogenous input matrix.
    C, Cd, D
        Performance output ``z = C x + Cd x(t - tau) + D w``.
    tau
        The delay in s (the frozen value at this parameter point).
    """

    A: Matrix
    Ad: Matrix
    B: Matrix
    C: Matrix
    Cd: Matrix
    D: Matrix
    tau: float

    @property
    def n(self) -> int:
        """State dimension."""
        return int(self.A.shape[0])


def _m(obj: Any, name: str) -> Matrix:
    value = np.atleast_2d(np.asarray(getattr(obj, name), dtype=float))
    if not np.all(np.isfinite(value)):
        raise ValueError(f"{name} has non-finite entries")
    return value


def close_loop(plant: Any, controller: Any, tau_s: float) -> DelaySystem:
    """Close ``plant`` (PlantMatrices) with ``controller`` (DelayedController) at delay ``tau_s``.

    Parameters
    ----------
    plant
        Object with ``A, Ad, B1, B2, C1, C1d, C2, C2d, D11, D12, D21`` (physical units, time in s).
    controller
        Object with ``Ak, Adk, Bk, Ck, Cdk, Dk`` (same units; ``Ak`` may be 0 x 0 for a static
        output feedback, then ``Bk, Ck, Cdk`` are empty of matching shape).
    tau_s
        The delay (s) shared by plant and controller at this frozen point, >= 0.

    Returns
    -------
    DelaySystem
        The closed loop on x_cl = [x_a; x_k].
    """
    if not (np.isfinite(tau_s) and tau_s >= 0.0):
        raise ValueError(f"tau_s={tau_s!r} must be finite and >= 0 s")
    a, ad, b1, b2 = (_m(plant, k) for k in ("A", "Ad", "B1", "B2"))
    c1, c1d, c2, c2d = (_m(plant, k) for k in ("C1", "C1d", "C2", "C2d"))
    d11, d12, d21 = (_m(plant, k) for k in ("D11", "D12", "D21"))
    dk = _m(controller, "Dk")
    ak_raw = np.asarray(controller.Ak, dtype=float)
    nk = int(ak_raw.shape[0]) if ak_raw.size else 0
    ny, nu = c2.shape[0], b2.shape[1]
    if nk:
        ak, adk, bk, ck, cdk = (_m(controller, k) for k in ("Ak", "Adk", "Bk", "Ck", "Cdk"))
    else:
        ak = adk = np.zeros((0, 0))
        bk = np.zeros((0, ny))
        ck = cdk = np.zeros((nu, 0))
    if dk.shape != (nu, ny):
        raise ValueError(f"Dk shape {dk.shape} does not match (n_u, n_y) = {(nu, ny)}")
    acl = np.block([[a + b2 @ dk @ c2, b2 @ ck], [bk @ c2, ak]])
    adcl = np.block([[ad + b2 @ dk @ c2d, b2 @ cdk], [bk @ c2d, adk]])
    bcl = np.vstack([b1 + b2 @ dk @ d21, bk @ d21])
    ccl = np.hstack([c1 + d12 @ dk @ c2, d12 @ ck])
    cdcl = np.hstack([c1d + d12 @ dk @ c2d, d12 @ cdk])
    dcl = d11 + d12 @ dk @ d21
    return DelaySystem(acl, adcl, bcl, ccl, cdcl, dcl, float(tau_s))
