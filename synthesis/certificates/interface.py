"""What every delay-dependent analysis LMI shares: the accepted inputs and the result.

Both analyses (:mod:`pressor.synthesis.certificates.jensen.analysis`, the Jensen functional of Theorem 1,
and :mod:`pressor.synthesis.certificates.wirtinger.analysis`) take the same closed loops, normalised
parameters, rate bounds and delay range, validated by :func:`checked_inputs`, and return an
:class:`AnalysisResult`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pressor.synthesis.problem.basis import P_DEPENDENCES
from pressor.synthesis.problem.closed_loop import DelaySystem

__all__ = ["P_DEPENDENCES", "AnalysisResult", "checked_inputs"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class AnalysisResult:
    """Outcome of :func:`analyse`.

    Attributes
    ----------
    certified
        Status "optimal", every re-evaluated LMI negative definite, every P(rho_k) positive.
    status
        Clarabel's outcome as a cvxpy status string ("optimal", "optimal_inaccurate", ...).
    gamma
        The certified L2-gain bound (None when the solve failed).
    margins
        (m,) smallest ``-lambda_max`` of the LMI at each point over the rate vertices (scaled).
    p_min_eig
        (m,) smallest eigenvalue of P(rho_k) (scaled).
    n_lmis
        Number of matrix inequalities (points x rate vertices).
    solve_time_s
        Wall time of assembly + solve (s).
    p_dependence
        "constant", "affine" or "quadratic".
    p0_phys
        The constant term P0 of the certificate mapped back to the original (unscaled,
        untransformed) state coordinates, up to a positive factor (None when the solve failed); used
        to whiten the state for a better-conditioned second solve
        (:func:`pressor.synthesis.certificates.state_transform.whitening_transform`).
    certificate
        The Lyapunov-Krasovskii matrices divided by gamma, with the state transform and time
        scale they live in, for analyses that return them
        (:mod:`pressor.synthesis.certificates.wirtinger.analysis`); None here.
    """

    certified: bool
    status: str
    gamma: float | None
    margins: Array
    p_min_eig: Array
    n_lmis: int
    solve_time_s: float
    p_dependence: str
    notes: list[str] = field(default_factory=list)
    p0_phys: Array | None = None
    certificate: dict[str, Any] | None = None


def checked_inputs(
    systems: Sequence[DelaySystem],
    rho_hat: Array,
    rate_hat_per_s: Array,
    dtau_drho_hat_s: Array,
    tau_max_s: float,
    p_dependence: str,
    zero_delay_ok: bool = True,
) -> tuple[Array, Array, Array, float, Array]:
    """Validate the arguments every analysis LMI shares; return rho_hat, rates, dtau, tau_max, taus.

    Raises
    ------
    ValueError
        An unknown ``p_dependence``, a rho_hat row count that differs from the systems, a negative
        or non-finite rate, a delay outside [0, tau_max] ((0, tau_max] without ``zero_delay_ok``)
        or a delay that may change at 1 s/s or faster.
    """
    if p_dependence not in P_DEPENDENCES:
        raise ValueError(f"p_dependence={p_dependence!r} must be one of {P_DEPENDENCES}")
    m = len(systems)
    rho = np.atleast_2d(np.asarray(rho_hat, dtype=float))
    if m == 0 or rho.shape[0] != m:
        raise ValueError(f"need one rho_hat row per system, got {rho.shape} for {m} systems")
    s = rho.shape[1]
    rate = np.asarray(rate_hat_per_s, dtype=float).reshape(s)
    dtau = np.asarray(dtau_drho_hat_s, dtype=float).reshape(s)
    if np.any(rate < 0) or not np.all(np.isfinite(rate)):
        raise ValueError(f"rate_hat_per_s={rate.tolist()} must be finite and >= 0")
    tau_max = float(tau_max_s)
    taus = np.array([sys_.tau for sys_ in systems])
    low_bad = taus < 0 if zero_delay_ok else taus <= 0
    if np.any(taus > tau_max * (1 + 1e-12)) or np.any(low_bad):
        lo = "[0" if zero_delay_ok else "(0"
        raise ValueError(f"every delay must lie in {lo}, tau_max_s={tau_max}] s")
    if float(np.sum(rate * np.abs(dtau))) >= 1.0:
        raise ValueError("the delay may change at >= 1 s/s: the functional needs |dtau/dt| < 1")
    return rho, rate, dtau, tau_max, taus
