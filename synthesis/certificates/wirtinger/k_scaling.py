"""K-scaled state coordinates for the Wirtinger analysis: the ml/h states measured in mmHg.

The scheduled Smith loop's gains scale like 1/K, so a Lyapunov functional that is constant (or
polynomial) in the original state cannot follow it over K in [0.25, 1]. In the coordinates
``x~ = D(K) x`` with ``D = diag(d_j)``, ``d_j = K`` on the states that carry ml/h (in the closed
loop of :func:`pressor.synthesis.problem.closed_loop.close_loop` with the Smith controller: the plant's
infusion u and the controller's model input û) and 1 elsewhere, those states are in mmHg and the
frozen loops look alike over the whole box (measured in docs/notes/certificate-structure.md, section 2c).

With K = K(t) moving, the x~ system is, for ``dx/dt = A x + Ad x(t - tau) + B w``::

    dx~/dt = (D A D^-1 + kappa Pi) x~ + D A_d D^-1 (I + (r - 1) Pi) x~(t - tau) + D B w
    z      = C D^-1 x~ + C_d D^-1 (I + (r - 1) Pi) x~(t - tau) + D_w w

with ``Pi = diag(1 on the scaled states)``, ``kappa = dK/dt / K`` (1/s) and
``r = K(t) / K(t - tau)`` (``D(K(t)) D(K(t - tau))^-1 = I + (r - 1) Pi``). With |dK/dt| <= nu:
``|kappa| <= nu / K`` and ``|K(t) - K(t - tau)| <= nu tau_max``, so at a point with K(t) = K,
``r in [K / (K + nu tau_max), K / (K - nu tau_max)]``. Both enter the analysis as two more rate
coordinates: kappa on the rate vertex of K itself (its sign is that of dK/dt), r on a vertex of its
own (:mod:`pressor.synthesis.certificates.wirtinger.lmi`). The delayed output must not read a scaled state
(``C_d Pi = 0``; true for the Smith loop, whose delayed output is the model output ŷ), so z does
not depend on r.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pressor.synthesis.problem.closed_loop import DelaySystem

__all__ = ["KScaling", "k_scaled_system", "k_terms"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class KScaling:
    """What the K-scaled functional needs per grid point.

    Attributes
    ----------
    k
        (m,) the sensitivity K (mmHg/(ml/h)) at each grid point, > 0, in the order of the systems.
    k_rate_per_s
        Bound on |dK/dt| (mmHg/(ml/h) per s), >= 0: the same bound as the K entry of the rate
        vector (``rate_hat_per_s`` times the normalisation half-width); the K rate vertex carries
        both.
    states
        Indices of the closed-loop states scaled by K (the ml/h states), e.g. ``(1, 3)`` for the
        shipped plant + Smith controller: u and û.
    k_index
        Index of K in ``rho_hat`` (its rate vertex).
    """

    k: Array
    k_rate_per_s: float
    states: tuple[int, ...]
    k_index: int = 0

    def check(self, m: int, n: int, n_params: int, tau_max_s: float) -> None:
        """Raise ValueError unless this fits m systems of n states and ``n_params`` parameters."""
        k = np.asarray(self.k, dtype=float)
        if k.shape != (m,) or not np.all(np.isfinite(k)) or np.any(k <= 0):
            raise ValueError(f"k_scaling.k must hold {m} finite values > 0")
        if not (np.isfinite(self.k_rate_per_s) and self.k_rate_per_s >= 0):
            raise ValueError(f"k_scaling.k_rate_per_s={self.k_rate_per_s!r} must be >= 0")
        st = tuple(int(i) for i in self.states)
        if not st or len(set(st)) != len(st) or any(not 0 <= i < n for i in st):
            raise ValueError(f"k_scaling.states={self.states!r}: distinct indices in 0..{n - 1}")
        if not 0 <= self.k_index < n_params:
            raise ValueError(f"k_scaling.k_index={self.k_index!r} not in 0..{n_params - 1}")
        if np.any(k - self.k_rate_per_s * tau_max_s <= 0):
            raise ValueError("K may reach 0 within one delay (k - k_rate_per_s * tau_max <= 0)")


def k_scaled_system(system: DelaySystem, k: float, states: Sequence[int]) -> DelaySystem:
    """The frozen loop in ``x~ = D(k) x`` (r = 1, kappa = 0): ``D A D^-1``, ``D A_d D^-1``, ``D B``,
    ``C D^-1``, ``C_d D^-1``.

    Raises
    ------
    ValueError
        The delayed output reads a scaled state (``C_d Pi != 0``).
    """
    d = np.ones(system.n)
    d[list(states)] = float(k)
    if np.any(system.Cd[:, list(states)] != 0.0):
        raise ValueError("the delayed output C_d reads a K-scaled state: not supported")
    return DelaySystem(
        system.A * d[:, None] / d[None, :],
        system.Ad * d[:, None] / d[None, :],
        system.B * d[:, None],
        system.C / d[None, :],
        system.Cd / d[None, :],
        system.D,
        system.tau,
    )


def k_terms(
    ks: KScaling, ad_scaled: Array, tx: Array, txi: Array, time_scale_s: float, tau_max_s: float
) -> tuple[Array, Array, Array, Array]:
    """The r centre factor and the two rate directions of ``Ga = [A Ad 0 B]`` per point, factored.

    With ``S`` the (n, n_s) selector of the scaled states, ``Pi = S S'`` and in the analysis'
    state ``x^`` (``x~ = tx x^``) ``txi Pi tx = (txi S)(S' tx)``: the kappa direction of A is
    ``u_kappa (S' tx)`` and the r direction of A_d is ``u_r (S' tx)``.

    Parameters
    ----------
    ks
        The scaling.
    ad_scaled
        (m, n, n) ``ts txi D A_d D^-1 tx`` (r = 1) of every point, scaled time and state.
    tx, txi
        The constant state transform of the analysis (``x~ = tx x^``) and its inverse.
    time_scale_s, tau_max_s
        Time unit of the scaled problem and the largest delay (s).

    Returns
    -------
    tuple
        ``ad_centre`` (m, n, n): A_d at the centre ``r_c`` of each point's r interval;
        ``u_kappa`` (m, n, n_s): ``ts nu/K txi S`` (the K rate vertex +1);
        ``u_r`` (m, n, n_s): half-width of the r interval times ``A_d txi S`` (r vertex +1);
        ``s_tx`` (n_s, n): ``S' tx``.
    """
    k = np.asarray(ks.k, dtype=float)
    n = ad_scaled.shape[1]
    sel = np.eye(n)[:, list(ks.states)]
    txi_s, s_tx = txi @ sel, sel.T @ tx
    reach = ks.k_rate_per_s * tau_max_s
    r_lo, r_hi = k / (k + reach), k / (k - reach)
    r_c, r_half = 0.5 * (r_lo + r_hi), 0.5 * (r_hi - r_lo)
    ad_s = ad_scaled @ txi_s
    ad_centre = ad_scaled + (r_c - 1.0)[:, None, None] * (ad_s @ s_tx)
    u_kappa = (time_scale_s * ks.k_rate_per_s / k)[:, None, None] * txi_s[None]
    return ad_centre, u_kappa, r_half[:, None, None] * ad_s, s_tx
