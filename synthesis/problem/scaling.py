"""Scaling of the synthesis problem: time by t_s (the nominal delay), x_e and y accordingly, ρ to [−1, 1].

Unscaled, Clarabel returns NumericalError even on analysis problems; with the scaling below
solves reach "optimal". With t = t_s·t̂, x = Sx x̂, y = Sy ŷ (u_a, w, z unscaled,
so the L2 gain is unchanged)::

    Â = t_s Sx⁻¹ A Sx,  Âd = t_s Sx⁻¹ Ad Sx,  B̂1 = t_s Sx⁻¹ B1,  B̂2 = t_s Sx⁻¹ B2,
    Ĉ1 = C1 Sx,  Ĉ2 = Sy⁻¹ C2 Sx,  D̂21 = Sy⁻¹ D21,   τ̂ = τ / t_s.

The L2 norm of a signal scales by √t_s under time scaling for w and z alike, so γ is unchanged.
A controller found for the scaled plant maps back to physical units by :func:`unscale_controller`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Scaling:
    """Affine maps between physical and scaled quantities.

    Attributes
    ----------
    time_s
        t_s: one scaled time unit in s.
    sx, sy
        Diagonal state and measurement scalings (physical = S · scaled).
    rho_center, rho_half
        ρ = center + half · ρ̂ (physical units).
    """

    time_s: float
    sx: np.ndarray
    sy: np.ndarray
    rho_center: np.ndarray
    rho_half: np.ndarray

    @classmethod
    def for_box(cls, box: np.ndarray, time_s: float, n_state: int = 3) -> Scaling:
        """Scaling for a (3, 2) box: x_e and the x_e measurement divided by t_s.

        States after x_e (the frequency-weight states of :mod:`pressor.synthesis.problem.model`, integrals
        of e or u over their weight's time constant) are divided by t_s as well.
        """
        b = np.asarray(box, dtype=float)
        return cls(
            time_s=float(time_s),
            sx=np.array([1.0, 1.0] + [time_s] * (n_state - 2)),
            sy=np.array([1.0, time_s]),
            rho_center=0.5 * (b[:, 0] + b[:, 1]),
            rho_half=0.5 * (b[:, 1] - b[:, 0]),
        )

    def to_hat(self, rho: np.ndarray) -> np.ndarray:
        """Physical ρ (…, 3) -> scaled ρ̂ in [−1, 1]."""
        return (np.asarray(rho, dtype=float) - self.rho_center) / self.rho_half

    def from_hat(self, rho_hat: np.ndarray) -> np.ndarray:
        """Scaled ρ̂ -> physical ρ."""
        return self.rho_center + self.rho_half * np.asarray(rho_hat, dtype=float)

    def rate_hat(self, rate_bounds: np.ndarray) -> np.ndarray:
        """Bounds on |dρ̂i/dt̂| = t_s |ρ̇i| / half_i."""
        return self.time_s * np.asarray(rate_bounds, dtype=float) / self.rho_half

    def plant(self, p: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Scale a batch of plant matrices (as from :func:`pressor.synthesis.problem.model.plant_batch`)."""
        ts = self.time_s
        sx, sxi = self.sx, 1.0 / self.sx
        syi = 1.0 / self.sy
        return {
            "A": ts * sxi[:, None] * p["A"] * sx[None, :],
            "Ad": ts * sxi[:, None] * p["Ad"] * sx[None, :],
            "B1": ts * sxi[:, None] * p["B1"],
            "B2": ts * sxi[:, None] * p["B2"],
            "C1": p["C1"] * sx[None, :],
            "C1d": p["C1d"] * sx[None, :],
            "D11": p["D11"],
            "D12": p["D12"],
            "C2": syi[:, None] * p["C2"] * sx[None, :],
            "C2d": syi[:, None] * p["C2d"] * sx[None, :],
            "D21": syi[:, None] * p["D21"],
        }


def unscale_controller(k: dict[str, np.ndarray], scaling: Scaling) -> dict[str, np.ndarray]:
    """Map a scaled-time controller to physical units (time in s), keeping its state coordinates.

    ``dx_k/dt̂ = Âk x_k + Âdk x_k(t̂−τ̂) + B̂k ŷ``, ``u_a = Ĉk x_k + Ĉdk x_k(·) + D̂k ŷ`` with
    ŷ = Sy⁻¹ y gives ``Ak = Âk/t_s``, ``Adk = Âdk/t_s``, ``Bk = B̂k Sy⁻¹/t_s``, ``Ck = Ĉk``,
    ``Cdk = Ĉdk``, ``Dk = D̂k Sy⁻¹``.
    """
    ts = scaling.time_s
    syi = 1.0 / scaling.sy
    return {
        "Ak": k["Ak"] / ts,
        "Adk": k["Adk"] / ts,
        "Bk": k["Bk"] * syi[..., None, :] / ts,
        "Ck": k["Ck"].copy(),
        "Cdk": k["Cdk"].copy(),
        "Dk": k["Dk"] * syi[..., None, :],
    }
