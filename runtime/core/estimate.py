"""One report of the online estimator (:mod:`pressor.runtime.estimation.estimator`): values, uncertainty,
health. Immutable; the estimator hands out the same object until a window's bank update completes.

It lives in the core because a :class:`pressor.runtime.core.scheduling.Schedule` carries it to the recorder,
and the core imports nothing from :mod:`pressor.runtime.estimation` (which builds on the core).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Estimate:
    """One report of the estimator.

    Attributes
    ----------
    K, T_s, tau_s
        Sensitivity (mmHg/(ml/h)), lag (s), delay (s) to schedule on (the prior when
        ``from_prior``).
    K_std, T_std_s
        Standard deviations of K (mmHg/(ml/h)) and T (s).
    tau_lo_s, tau_hi_s
        Interval of τ (s) holding ~90 % of the bank's posterior weight.
    confidence
        0 (nothing learned) … 1 (K within ~5 %, T within ~10 %, one standard deviation).
    healthy
        False when the latest estimate was rejected by the health check (``reason`` says why).
    from_prior
        True when the values are the prior's (learning, or the check rejected the estimate).
    reason
        ``"ok"``, ``"learning"`` or the health check's rejection (``"diverged"``, ``"K
        implausible"``, ``"T implausible"``).
    in_box
        Whether (K, T, τ) lies inside the design box.
    """

    K: float
    T_s: float
    tau_s: float
    K_std: float
    T_std_s: float
    tau_lo_s: float
    tau_hi_s: float
    confidence: float
    healthy: bool
    from_prior: bool
    reason: str
    in_box: bool
