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

Relative rates (``KScaling.relative``): with -nu_d <= d(ln K)/dt <= nu_u instead,
``kappa in [-nu_d, nu_u]`` and ``r in [e^(-nu_d tau_max), e^(nu_u tau_max)]`` at every K: the
terms no longer depend on the box's K, which may then span any factor (the frozen loops in these
coordinates do not depend on K at all). A falling K is the benign direction of both terms (kappa
< 0 damps the scaled states, r < 1 is less plant gain than the controller expects), so a
certificate may allow it much faster than a rise; an asymmetric interval shifts A and A_d to the
interval's centre and keeps the half-width as the rate vertex.

A controller realised so that it absorbs a change of K (``KScaling.kappa_rows``, the Smith law's
"bumpless" integral, :mod:`pressor.synthesis.families.smith.law`) has, besides ``kappa Pi``, a kappa term
on other rows of the state equation: ``dx~/dt += kappa (E x~ + E_d x~(t - tau) + E_w w)``, the
rows ``[E, E_d, E_w]`` (n, 2n + nw) given per point in K-scaled coordinates. The kappa direction
of ``Ga = [A Ad 0 B]`` is then ``[Pi + E, E_d, 0, E_w]``, factored over the selectors of the
columns it reads (:func:`k_terms`).
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
    relative
        False: ``k_rate_per_s`` bounds |dK/dt|; True: it bounds |d(ln K)/dt| (1/s).
    k_rate_up_per_s
        Relative rates only: a separate bound on the rise of ln K (1/s), so that
        ``-k_rate_per_s <= d(ln K)/dt <= k_rate_up_per_s``; None: the same as the fall.
    kappa_rows
        None, or (m, n, 2n + nw): per point, the rows ``[E, E_d, E_w]`` of the extra kappa term
        (module docstring), in K-scaled coordinates.
    """

    k: Array
    k_rate_per_s: float
    states: tuple[int, ...]
    k_index: int = 0
    relative: bool = False
    kappa_rows: Array | None = None
    k_rate_up_per_s: float | None = None

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
        if not self.relative and np.any(k - self.k_rate_per_s * tau_max_s <= 0):
            raise ValueError("K may reach 0 within one delay (k - k_rate_per_s * tau_max <= 0)")
        if self.kappa_rows is not None and np.shape(self.kappa_rows)[:2] != (m, n):
            raise ValueError(f"k_scaling.kappa_rows must have shape ({m}, {n}, 2n + nw)")


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
    ks: KScaling,
    ad_scaled: Array,
    tx: Array,
    txi: Array,
    time_scale_s: float,
    tau_max_s: float,
    nw: int,
) -> tuple[Array, tuple[Array, Array], tuple[Array, Array], Array]:
    """The r centre factor and the two rate directions of ``Ga = [A Ad 0 B]`` per point, factored.

    With ``S`` the (n, n_s) selector of the scaled states, ``Pi = S S'`` and in the analysis'
    state ``x^`` (``x~ = tx x^``) ``txi Pi tx = (txi S)(S' tx)``: the kappa direction of A is
    ``U_kappa Phi_kappa`` with ``Phi_kappa = [S' tx, 0, 0, 0]`` over ``[x, x(t - tau), int x, w]``,
    and the r direction of A_d is ``U_r Phi_r``, ``Phi_r = [0, S' tx, 0, 0]``. With
    ``ks.kappa_rows`` the kappa factor also selects every column the extra rows read (unit
    selectors, transformed like the state), so ``Phi_kappa`` is the same at every point and the
    point's coefficients sit in ``U_kappa``. Each ``Phi`` has unit norm (its scale is in ``U``).

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
    nw
        Number of exogenous inputs (columns of B).

    Returns
    -------
    tuple
        ``ad_centre`` (m, n, n): A_d at the centre ``r_c`` of each point's r interval;
        ``(U_kappa (m, n, q_k), Phi_kappa (q_k, big))``: the K rate vertex +1 (half-width of the
        kappa interval); ``(U_r (m, n, q_r), Phi_r (q_r, big))``: the r vertex +1 (half-width of
        the r interval); ``ga_centre`` (m, n, big): what the kappa interval's centre adds to
        ``Ga`` (zero unless the relative rates are asymmetric).
    """
    k = np.asarray(ks.k, dtype=float)
    m, n = ad_scaled.shape[:2]
    big = 3 * n + nw
    sel = np.eye(n)[:, list(ks.states)]
    txi_s, s_tx = txi @ sel, sel.T @ tx
    nu = ks.k_rate_per_s
    kap_c = np.zeros(m)
    if ks.relative:
        nu_u = nu if ks.k_rate_up_per_s is None else ks.k_rate_up_per_s
        r_lo = np.full(m, np.exp(-nu * tau_max_s))
        r_hi = np.full(m, np.exp(nu_u * tau_max_s))
        kap = np.full(m, time_scale_s * 0.5 * (nu_u + nu))
        kap_c = np.full(m, time_scale_s * 0.5 * (nu_u - nu))
    else:
        reach = nu * tau_max_s
        r_lo, r_hi = k / (k + reach), k / (k - reach)
        kap = time_scale_s * nu / k
    r_c, r_half = 0.5 * (r_lo + r_hi), 0.5 * (r_hi - r_lo)
    ad_s = ad_scaled @ txi_s
    ad_centre = ad_scaled + (r_c - 1.0)[:, None, None] * (ad_s @ s_tx)
    phi_r = np.zeros((len(ks.states), big))
    phi_r[:, n : 2 * n] = s_tx
    u_r = r_half[:, None, None] * ad_s
    phi_k = np.zeros((len(ks.states), big))
    phi_k[:, :n] = s_tx
    u_k = kap[:, None, None] * txi_s[None]
    if ks.kappa_rows is not None:
        rows = np.asarray(ks.kappa_rows, dtype=float)  # (m, n, 2n + nw) over [x, x_d, w]
        cols = np.flatnonzero(np.any(rows != 0.0, axis=(0, 1)))
        extra_phi = np.zeros((len(cols), big))
        extra_u = np.zeros((m, n, len(cols)))
        for q, c in enumerate(cols):
            if c < 2 * n:  # a state column: x (c < n) or x(t - tau); the analysis reads tx x^
                off = 0 if c < n else n
                extra_phi[q, off : off + n] = tx[c - off]
            else:  # an exogenous input, not transformed
                extra_phi[q, 3 * n + (c - 2 * n)] = 1.0
            # the column's coefficient in every row, in the analysis' state and scaled time
            extra_u[:, :, q] = kap[:, None] * (rows[:, :, c] @ txi.T)
        phi_k = np.concatenate([phi_k, extra_phi])
        u_k = np.concatenate([u_k, extra_u], axis=2)

    def unit(u: Array, phi: Array) -> tuple[Array, Array]:
        scale = np.linalg.norm(phi, 2)
        return scale * u, phi / scale

    # the kappa interval's centre: the direction (u_k holds it at the half-width kap) times kap_c
    ratio = np.divide(kap_c, kap, out=np.zeros(m), where=kap > 0)
    ga_centre = np.einsum("mnq,qb->mnb", ratio[:, None, None] * u_k, phi_k)
    return ad_centre, unit(u_k, phi_k), unit(u_r, phi_r), ga_centre
