"""The scheduled Smith-predictor baseline's frozen step on the synthesis side (discrete time).

The controller is the runtime's own (:class:`baselines.smith.SmithController`, the one
``--controller smith`` runs), stepped at its sample period Ts against the exact zero-order-hold
discretisation of the first-order-plus-delay plant ``T dy/dt = −y + K u(t − τ)``: with
τ = (D + f)·Ts, D integer, 0 ≤ f < 1, a command held over each tick gives exactly::

    y_k+1 = a y_k + K (e^(−(1−f)Ts/T) − a) u_k−D−1 + K (1 − e^(−(1−f)Ts/T)) u_k−D,  a = e^(−Ts/T)

The step starts from rest (y = 0, no infusion before t = 0); the command is clamped by the
controller to the pump range, so unlike the linear LPV/PI steps the pump limit is part of the
response. The result is a :class:`synthesis.step_response.StepResponse` sampled at the ticks, so
the same metrics apply.
"""

from __future__ import annotations

import math

import numpy as np

from baselines.smith import LAMBDA_DEFAULT_S, SmithController
from synthesis.step_response import StepResponse

__all__ = ["smith_step_response"]


def smith_step_response(
    k: float,
    t_s: float,
    tau_s: float,
    step_mmhg: float,
    t_end_s: float,
    max_rate_ml_h: float = 120.0,
    sample_period_s: float = 0.1,
    lambda_s: float = LAMBDA_DEFAULT_S,
) -> StepResponse:
    """Simulate a target step of ``step_mmhg`` at t = 0 with the discrete Smith controller.

    Parameters
    ----------
    k, t_s, tau_s
        Frozen plant: K (mmHg/(ml/h), > 0), T (s, > 0), τ (s, ≥ 0); the controller is scheduled
        on the same values.
    step_mmhg
        Target step (mmHg) from rest.
    t_end_s
        Horizon (s), > 0.
    max_rate_ml_h
        Pump limit (ml/h).
    sample_period_s
        Controller period Ts (s).
    lambda_s
        Closed-loop time constant λ (s).

    Returns
    -------
    StepResponse
        MAP deviation, target and the command sent, one sample per tick on [0, t_end].
    """
    if not (k > 0.0 and t_s > 0.0 and tau_s >= 0.0 and math.isfinite(k + t_s + tau_s)):
        raise ValueError(f"plant K={k!r}, T={t_s!r}, tau={tau_s!r} must be finite, > 0 (tau >= 0)")
    if not (math.isfinite(t_end_s) and t_end_s > 0.0):
        raise ValueError(f"t_end_s={t_end_s!r} must be > 0 s")
    ctrl = SmithController(sample_period_s, max_rate_ml_h, lambda_s=lambda_s)
    ts = ctrl.sample_period_s
    lags = tau_s / ts
    whole = math.floor(lags + 1e-9)  # an exact multiple of Ts must not lose a tick to rounding
    frac = max(lags - whole, 0.0)
    a = math.exp(-ts / t_s)
    late = math.exp(-(1.0 - frac) * ts / t_s)  # decay left after the new input starts
    b_new, b_old = k * (1.0 - late), k * (late - a)
    steps = math.ceil(t_end_s / ts - 1e-9)
    y = np.zeros(steps + 1)
    u = np.zeros(steps + 1)
    for i in range(steps + 1):
        u[i] = ctrl.step(y[i], step_mmhg, k, t_s, tau_s)
        if i == steps:
            break
        j = i - whole
        u_new = u[j] if j >= 0 else 0.0
        u_old = u[j - 1] if j >= 1 else 0.0
        y[i + 1] = a * y[i] + b_new * u_new + b_old * u_old
    t = np.arange(steps + 1) * ts
    return StepResponse(t, y, np.full(steps + 1, float(step_mmhg)), u, float(step_mmhg))
