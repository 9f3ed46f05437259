"""The LPV state-delayed MAP model of the paper (physical units, time in s).

Plant ``T·dΔMAP/dt + ΔMAP = K·u(t − τ)`` with the input filter ``u = Ω/(s + Λ) u_a`` (part of the
implemented controller: the infusion command is the filter state u) and the tracking integral
``dx_e/dt = e = r − ΔMAP − d_o``. Augmented state ``x_a = [ΔMAP (mmHg), u (ml/h), x_e (mmHg·s)]``,
scheduling ``ρ = (K [mmHg/(ml/h)], T [s], τ [s])``::

    dx_a/dt = A x_a + Ad x_a(t − τ) + B1 w + B2 u_a
    z       = C1 x_a + C1d x_a(t − τ) + D11 w + D12 u_a
    y       = C2 x_a + C2d x_a(t − τ) + D21 w

Deviations from the paper (DESIGN.md §4):

* ``w = [r, d_o, n_xe]``: a third input, the measurement noise on the x_e channel, weighted by η.
* ``y = [e; x_e + η n_xe]`` instead of the printed ``C2 = [1 0 0], D21 = [0 1]``: with the printed
  measurement (or e alone) the integral state x_e is undetectable and the LMIs are infeasible.
  The controller computes x_e itself by integrating e. Without the noise weight η the optimum puts a
  huge gain on x_e and cancels it inside the controller (fast poles that sampling breaks).
* ``z = [φ x_e; ξ u_a]`` as in the paper's text (``C1 = [0 0 φ; 0 0 0]``, ``D12 = [0; ξ]``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from synthesis.config import ModelConfig

N_STATE = 3
N_W = 3
N_Z = 2
N_Y = 2


@dataclass(frozen=True)
class PlantMatrices:
    """Generalised-plant matrices at one frozen ρ (physical units, time in s)."""

    A: np.ndarray
    Ad: np.ndarray
    B1: np.ndarray
    B2: np.ndarray
    C1: np.ndarray
    C1d: np.ndarray
    C2: np.ndarray
    C2d: np.ndarray
    D11: np.ndarray
    D12: np.ndarray
    D21: np.ndarray


def plant_batch(rho: np.ndarray, cfg: ModelConfig) -> dict[str, np.ndarray]:
    """Plant matrices for a batch of ρ, each with a leading batch axis.

    Parameters
    ----------
    rho
        (G, 3) array of (K [mmHg/(ml/h)], T [s], τ [s]).
    cfg
        The design's model configuration.

    Returns
    -------
    dict
        Name -> (G, rows, cols) array, the fields of :class:`PlantMatrices`.
    """
    rho = np.atleast_2d(np.asarray(rho, dtype=float))
    g = rho.shape[0]
    K, T = rho[:, 0], rho[:, 1]
    A = np.zeros((g, 3, 3))
    A[:, 0, 0] = -1.0 / T
    A[:, 1, 1] = -cfg.lambda_
    A[:, 2, 0] = -1.0
    Ad = np.zeros((g, 3, 3))
    Ad[:, 0, 1] = K / T
    B1 = np.zeros((g, 3, 3))
    B1[:, 2, 0] = 1.0  # r
    B1[:, 2, 1] = -1.0  # d_o
    B2 = np.zeros((g, 3, 1))
    B2[:, 1, 0] = cfg.omega
    C1 = np.zeros((g, 2, 3))
    C1[:, 0, 2] = cfg.phi
    C1d = np.zeros((g, 2, 3))
    D11 = np.zeros((g, 2, 3))
    D12 = np.zeros((g, 2, 1))
    D12[:, 1, 0] = cfg.xi
    C2 = np.zeros((g, 2, 3))
    C2[:, 0, 0] = -1.0  # e = r - x - d_o
    C2[:, 1, 2] = 1.0  # x_e
    C2d = np.zeros((g, 2, 3))
    D21 = np.zeros((g, 2, 3))
    D21[:, 0, 0] = 1.0
    D21[:, 0, 1] = -1.0
    D21[:, 1, 2] = cfg.eta_xe
    return {
        "A": A,
        "Ad": Ad,
        "B1": B1,
        "B2": B2,
        "C1": C1,
        "C1d": C1d,
        "C2": C2,
        "C2d": C2d,
        "D11": D11,
        "D12": D12,
        "D21": D21,
    }


def plant_at(rho: tuple[float, float, float] | np.ndarray, cfg: ModelConfig) -> PlantMatrices:
    """Plant matrices at one frozen ρ = (K, T_s, tau_s), physical units (time in s).

    The delay τ does not enter the matrices; it is the delay of the ``x_a(t − τ)`` term.
    """
    r = np.asarray(rho, dtype=float).reshape(3)
    if not np.all(np.isfinite(r)) or r[1] <= 0.0:
        raise ValueError(f"rho={r.tolist()!r}: K, T_s, tau_s must be finite and T_s > 0")
    b = plant_batch(r[None, :], cfg)
    return PlantMatrices(**{k: v[0] for k, v in b.items()})
