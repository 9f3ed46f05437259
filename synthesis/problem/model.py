"""The LPV state-delayed MAP model of the paper (physical units, time in s).

Plant ``T·dΔMAP/dt + ΔMAP = K·u(t − τ)`` with the input filter ``u = Ω/(s + Λ) u_a`` (part of the
implemented controller: the infusion command is the filter state u) and the tracking integral
``dx_e/dt = e = r − ΔMAP − d_o``. Augmented state ``x_a = [ΔMAP (mmHg), u (ml/h), x_e (mmHg·s),
weight states…]``, scheduling ``ρ = (K [mmHg/(ml/h)], T [s], τ [s])``::

    dx_a/dt = A x_a + Ad x_a(t − τ) + B1 w + B2 u_a
    z       = C1 x_a + C1d x_a(t − τ) + D11 w + D12 u_a
    y       = C2 x_a + C2d x_a(t − τ) + D21 w

Deviations from the paper (docs/DESIGN-CHOICES.md):

* ``w = [r, d_o, n_xe]``: a third input, the measurement noise on the x_e channel, weighted by η.
* ``y = [e; x_e + η n_xe]`` instead of the printed ``C2 = [1 0 0], D21 = [0 1]``: with the printed
  measurement (or e alone) the integral state x_e is undetectable and the LMIs are infeasible.
  The controller computes x_e itself by integrating e. Without the noise weight η the optimum puts a
  huge gain on x_e and cancels it inside the controller (fast poles that sampling breaks).

Performance output (``weights.performance``):

* ``"integral"`` (the paper's text, the shipped default): ``z = [φ x_e; ξ u_a]``, 3 states.
  φ x_e is the weight φ/s on e: the certificate asks ``|S(jω)| ≤ γ ω/φ`` and nothing else.
* ``"shaped"`` (mixed sensitivity): ``z = [W_e(s) e/√2; W_u(s) u/√2; ξ u_a]`` with::

      W_e(s) = (s/M + ω_b)/(s + ω_b A)          (tracking error, low-pass)
      W_u(s) = (s + ω_u/M_u)/(ε_u s + ω_u)       (infusion u, high-pass: roll-off of K·S)

  r and d_o both enter e (and u) with gain 1, so ``‖[r; d_o] ↦ e‖ = √2 |S|``; the 1/√2 makes
  γ ≤ 1 mean exactly ``|W_e S| ≤ 1`` and ``|W_u K S| ≤ 1`` at every frozen ρ (and the L2 versions
  for varying ρ), i.e. |S| ≤ A at DC, |S| ≲ ω/ω_b below ω_b (crossover ω_b sets the bandwidth),
  |S| ≤ M at high frequency, and |K S| ≤ M_u (ml/h per mmHg) at low frequency, falling as ω_u/ω
  above ω_u (down to ε_u). Realisation, ``a = ω_b A``::

      W_e = 1/M + ω_b(1 − A/M)/(s + a):  dx_we/dt = −a x_we + e,  √2 z1 = e/M + ω_b(1 − A/M) x_we

  With A = 0 the weight state is ∫e, which *is* x_e: no new state (√2 z1 = e/M + ω_b x_e); the
  integral action does not depend on A (the controller measures x_e in every case). With A > 0 a
  state x_we is appended. Likewise ``c = ω_u/ε_u``, ``b = ω_u/M_u``::

      ε_u > 0:  dx_wu/dt = −c x_wu + u,  √2 z2 = u/ε_u + (b − c)/ε_u · x_wu   (one state appended)
      ε_u = 0:  √2 z2 = (du/dt + b u)/ω_u = (Ω u_a + (b − Λ) u)/ω_u        (improper, no state)

  ξ u_a stays as a third output row (it keeps D12 of full column rank when ε_u > 0).

  The certified bandwidth ω_b/γ levels off (figures: docs/notes/benchmarks.md, "Design
  measurements"): the bound is set at K_min and DC, by the integral loop gain K·k_I the certificate
  allows there (the frozen loops' worst |W_e S| sits at ω → 0 on the K = 0.25 face), so a speed
  demand only raises γ.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pressor.synthesis.problem.config import ModelConfig

#: Dimensions of the shipped ("integral") generalised plant; :func:`dims` gives them for any config.
N_STATE = 3
N_W = 3
N_Z = 2
N_Y = 2

#: Indices of the plant states every configuration shares.
I_MAP, I_U, I_XE = 0, 1, 2


@dataclass(frozen=True)
class PlantDims:
    """Dimensions of the generalised plant: states n, disturbances nw, outputs nz, measurements ny.

    ``has_we``/``has_wu``: whether the tracking / infusion weight adds a state (appended after
    x_e in that order).
    """

    n: int
    nw: int
    nz: int
    ny: int
    has_we: bool
    has_wu: bool


def dims(cfg: ModelConfig) -> PlantDims:
    """The generalised-plant dimensions for a model configuration."""
    if cfg.shaping is None:
        return PlantDims(N_STATE, N_W, N_Z, N_Y, False, False)
    has_we = cfg.shaping.e_dc > 0.0
    has_wu = cfg.shaping.u_hf > 0.0
    return PlantDims(3 + int(has_we) + int(has_wu), N_W, 3, N_Y, has_we, has_wu)


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
    d = dims(cfg)
    n, nw, nz, ny = d.n, d.nw, d.nz, d.ny
    g = rho.shape[0]
    K, T = rho[:, 0], rho[:, 1]
    A = np.zeros((g, n, n))
    A[:, I_MAP, I_MAP] = -1.0 / T
    A[:, I_U, I_U] = -cfg.lambda_
    A[:, I_XE, I_MAP] = -1.0
    Ad = np.zeros((g, n, n))
    Ad[:, I_MAP, I_U] = K / T
    B1 = np.zeros((g, n, nw))
    B1[:, I_XE, 0] = 1.0  # r
    B1[:, I_XE, 1] = -1.0  # d_o
    B2 = np.zeros((g, n, 1))
    B2[:, I_U, 0] = cfg.omega
    C1 = np.zeros((g, nz, n))
    C1d = np.zeros((g, nz, n))
    D11 = np.zeros((g, nz, nw))
    D12 = np.zeros((g, nz, 1))
    D12[:, nz - 1, 0] = cfg.xi
    if getattr(cfg, "k_rate_relative", False):
        # a design on a log-K scale weighs K u_a (mmHg of effect per s): every K looks alike
        D12[:, nz - 1, 0] *= K
    if cfg.shaping is None:
        C1[:, 0, I_XE] = cfg.phi
    else:
        _shaped_rows(A, B1, C1, D11, D12, cfg, d)
    C2 = np.zeros((g, ny, n))
    C2[:, 0, I_MAP] = -1.0  # e = r - x - d_o
    C2[:, 1, I_XE] = 1.0  # x_e
    C2d = np.zeros((g, ny, n))
    D21 = np.zeros((g, ny, nw))
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


def _shaped_rows(
    A: np.ndarray,
    B1: np.ndarray,
    C1: np.ndarray,
    D11: np.ndarray,
    D12: np.ndarray,
    cfg: ModelConfig,
    d: PlantDims,
) -> None:
    """Fill the weight states and the W_e, W_u output rows in place (see the module docstring)."""
    s = cfg.shaping
    assert s is not None
    h = 1.0 / np.sqrt(2.0)  # r and d_o each reach e and u with gain 1 (module docstring)
    # z1 = W_e(s) e / √2, e = r - ΔMAP - d_o
    we_state = I_XE
    if d.has_we:
        we_state = 3
        A[:, we_state, we_state] = -s.e_crossover_rad_s * s.e_dc
        A[:, we_state, I_MAP] = -1.0
        B1[:, we_state, 0] = 1.0
        B1[:, we_state, 1] = -1.0
    C1[:, 0, I_MAP] = -h / s.e_peak
    D11[:, 0, 0] = h / s.e_peak
    D11[:, 0, 1] = -h / s.e_peak
    C1[:, 0, we_state] = h * s.e_crossover_rad_s * (1.0 - s.e_dc / s.e_peak)
    # z2 = W_u(s) u / √2
    b = s.u_crossover_rad_s / s.u_dc
    if d.has_wu:
        wu_state = 3 + int(d.has_we)
        c = s.u_crossover_rad_s / s.u_hf
        A[:, wu_state, wu_state] = -c
        A[:, wu_state, I_U] = 1.0
        C1[:, 1, I_U] = h / s.u_hf
        C1[:, 1, wu_state] = h * (b - c) / s.u_hf
    else:
        C1[:, 1, I_U] = h * (b - cfg.lambda_) / s.u_crossover_rad_s
        D12[:, 1, 0] = h * cfg.omega / s.u_crossover_rad_s


def plant_at(rho: tuple[float, float, float] | np.ndarray, cfg: ModelConfig) -> PlantMatrices:
    """Plant matrices at one frozen ρ = (K, T_s, tau_s), physical units (time in s).

    The delay τ does not enter the matrices; it is the delay of the ``x_a(t − τ)`` term.
    """
    r = np.asarray(rho, dtype=float).reshape(3)
    if not np.all(np.isfinite(r)) or r[1] <= 0.0:
        raise ValueError(f"rho={r.tolist()!r}: K, T_s, tau_s must be finite and T_s > 0")
    b = plant_batch(r[None, :], cfg)
    return PlantMatrices(**{k: v[0] for k, v in b.items()})
