"""One member of the estimator's delay bank: an output-error Kalman filter for a fixed delay.

On windowed data (window Δ s) the model simulates the drug response x̂ (mmHg) from the delayed
mean rate ū (ml/h) and fits θ = (a, b, c) by the recursive prediction-error method::

    x̂_j = a·x̂_{j−1} + b·ū_{j−d},      ȳ_j − y_ref = x̂_j + c + e_j

with a = e^(−Δ/T), b = K·(1 − a) (mmHg/(ml/h)) and c the baseline's shift (mmHg); θ are random
walks, the gradient is ψ = (∂x̂/∂a, ∂x̂/∂b, 1). See :mod:`pressor.runtime.estimation.estimator` for why.
Pure Python floats, preallocated lists: no allocation per update.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

_INF = math.inf


@dataclass(frozen=True, slots=True)
class FilterSettings:
    """Settings shared by the bank's models (all per window of ``window_s``).

    Attributes
    ----------
    window_s
        Window Δ (s).
    prior_K, prior_T_s
        Prior sensitivity (mmHg/(ml/h)) and lag (s).
    prior_rel_std
        Relative standard deviation of the prior's K and T.
    baseline_std_mmhg
        Standard deviation of the offset c at a (re)start (mmHg).
    q_a2, q_b2, q_c2
        Random-walk variances of a (1), b ((mmHg/(ml/h))²), c (mmHg²).
    jump2
        Squared normalised innovation above which the offset takes the innovation as a jump.
    forget
        Per-window forgetting factor of the log-likelihood.
    a_lo, a_hi
        Range a is kept in (T within [T_lo/2, 2 T_hi]: wider than the plausible range, so the
        health check sees an estimate that escapes it).
    """

    window_s: float
    prior_K: float
    prior_T_s: float
    prior_rel_std: float
    baseline_std_mmhg: float
    q_a2: float
    q_b2: float
    q_c2: float
    jump2: float
    forget: float
    a_lo: float
    a_hi: float


class DelayModel:
    """The filter of one delay (``delay_windows`` windows).

    Attributes
    ----------
    theta
        [a, b, c].
    P
        Covariance of θ, symmetric, stored as [00, 01, 02, 11, 12, 22].
    sim
        [x̂ (mmHg), ∂x̂/∂a, ∂x̂/∂b, last ū (ml/h)].
    nll
        Exponentially forgotten negative log-likelihood of the innovations.
    age
        Windows of data since the model last started from the prior.
    """

    __slots__ = ("delay_windows", "settings", "theta", "P", "sim", "nll", "age")

    def __init__(self, delay_windows: int, settings: FilterSettings) -> None:
        self.delay_windows = delay_windows
        self.settings = settings
        self.theta = [0.0, 0.0, 0.0]
        self.P = [0.0] * 6
        self.sim = [0.0] * 4
        self.nll = 0.0
        self.age = 0
        self.reset(math.nan, 0.0)

    def reset(self, y_dev_mmhg: float, nll: float) -> None:
        """Back to the prior θ and covariance, the simulation at the prior's steady state.

        The simulated response is set to K0·ū (the last rate) and the offset to what the newest
        window (``y_dev_mmhg`` = ȳ − y_ref, NaN if none) then leaves over, so a restarted model
        predicts the current MAP; ``nll`` is its new log-likelihood.
        """
        st = self.settings
        a = math.exp(-st.window_s / st.prior_T_s)
        th, P, sim = self.theta, self.P, self.sim
        x = st.prior_K * sim[3]
        th[0], th[1] = a, st.prior_K * (1.0 - a)
        th[2] = y_dev_mmhg - x if y_dev_mmhg == y_dev_mmhg else 0.0
        sa = a * st.window_s / st.prior_T_s * st.prior_rel_std  # a from T0·(1 ± rel)
        sb = th[1] * st.prior_rel_std  # b from K0·(1 ± rel)
        sc = st.baseline_std_mmhg
        P[0], P[1], P[2], P[3], P[4], P[5] = sa * sa, 0.0, 0.0, sb * sb, 0.0, sc * sc
        sim[0], sim[1], sim[2] = x, x / (1.0 - a), sim[3] / (1.0 - a)
        self.nll = nll
        self.age = 0

    def copy_from(self, other: DelayModel, nll: float) -> None:
        """Take ``other``'s θ, covariance, simulation and age; ``nll`` is the new log-likelihood."""
        self.theta[:] = other.theta
        self.P[:] = other.P
        self.sim[:] = other.sim
        self.age = other.age
        self.nll = nll

    def step(self, u_ml_h: float, y_dev_mmhg: float, dT_s: float, r2: float) -> bool:
        """Simulate one window with the delayed rate, then fit the window's ȳ − y_ref (mmHg).

        ``dT_s`` (s, >= 0) is the lag's expected rise over the window (the T-drift prior): before
        a fit, θ moves to T + ``dT_s`` at the same K. ``r2`` (mmHg², > 0) is the variance of the
        window's output error. A NaN rate holds the last one; a NaN
        ``y_dev_mmhg`` only simulates (θ does not move). Returns whether the filter was updated; a
        filter whose covariance loses positivity restarts from the prior.
        """
        st, sim, th, P = self.settings, self.sim, self.theta, self.P
        if dT_s > 0.0 and y_dev_mmhg == y_dev_mmhg and 0.0 < th[0] < 1.0:
            a_old = th[0]
            K = th[1] / (1.0 - a_old)
            a_new = math.exp(-st.window_s / (dT_s - st.window_s / math.log(a_old)))
            th[0] = min(a_new, st.a_hi)
            th[1] = K * (1.0 - th[0])
        u = u_ml_h if u_ml_h == u_ml_h else sim[3]
        sim[3] = u
        a, b, c = th
        x = sim[0]
        x_new = a * x + b * u
        pa = x + a * sim[1]  # ∂x̂/∂a, ∂x̂/∂b: the output-error gradient
        pb = u + a * sim[2]
        sim[0], sim[1], sim[2] = x_new, pa, pb
        if y_dev_mmhg != y_dev_mmhg:
            return False
        p00, p01, p02 = P[0] + st.q_a2, P[1], P[2]
        p11, p12, p22 = P[3] + st.q_b2, P[4], P[5] + st.q_c2
        e = y_dev_mmhg - x_new - c
        g0 = p00 * pa + p01 * pb + p02
        g1 = p01 * pa + p11 * pb + p12
        g2 = p02 * pa + p12 * pb + p22
        s = pa * g0 + pb * g1 + g2 + r2
        nu2 = e * e / s
        self.nll = st.forget * self.nll + min(nu2, 25.0) + math.log(s)
        if nu2 > st.jump2:  # unexplained jump: a baseline shift, let the offset take it
            p22 += e * e
            g2 += e * e
            s += e * e
        inv = 1.0 / s
        k = e * inv
        th[0] = min(max(a + g0 * k, st.a_lo), st.a_hi)
        th[1] = b + g1 * k
        th[2] = c + g2 * k
        P[0] = p00 - g0 * g0 * inv
        P[1] = p01 - g0 * g1 * inv
        P[2] = p02 - g0 * g2 * inv
        P[3] = p11 - g1 * g1 * inv
        P[4] = p12 - g1 * g2 * inv
        P[5] = p22 - g2 * g2 * inv
        self.age += 1
        if not (P[0] > 0.0 and P[3] > 0.0 and P[5] > 0.0 and math.isfinite(th[1] + th[2] + x_new)):
            self.reset(y_dev_mmhg, self.nll)
        return True

    def verdict(self, K_range: tuple[float, float], T_range_s: tuple[float, float]) -> str:
        """The health check: ``"ok"``, ``"diverged"``, ``"K implausible"`` or ``"T implausible"``."""
        a, b, c = self.theta
        p0, p1, p2, p3, p4, p5 = self.P
        # -inf < x < 1e300 is isfinite(x) and x < 1e300 (False for NaN), without a generator:
        # this runs for every model at every window close, up to three times
        if not (
            math.isfinite(a + b + c)
            and -_INF < p0 < 1e300
            and -_INF < p1 < 1e300
            and -_INF < p2 < 1e300
            and -_INF < p3 < 1e300
            and -_INF < p4 < 1e300
            and -_INF < p5 < 1e300
        ):
            return "diverged"
        if not 0.0 < a < 1.0:
            return "T implausible"
        if not K_range[0] <= b / (1.0 - a) <= K_range[1]:
            return "K implausible"
        if not T_range_s[0] <= -self.settings.window_s / math.log(a) <= T_range_s[1]:
            return "T implausible"
        return "ok"
