"""The scheduled Smith-predictor baseline's frozen step on the synthesis side (discrete time).

The controller is the runtime's own (:class:`pressor.baselines.smith.SmithController`, the one
``--controller smith`` runs), stepped at its sample period Ts against the exact zero-order-hold
discretisation of the first-order-plus-delay plant (:mod:`pressor.synthesis.verification.discrete_step`).
The step starts from rest (y = 0, no infusion before t = 0); the command is clamped by the
controller to the pump range, so unlike the linear LPV/PI steps the pump limit is part of the
response. The result is a :class:`pressor.synthesis.verification.step_response.StepResponse` sampled at the
ticks, so the same metrics apply.
"""

from __future__ import annotations

from pressor.baselines.smith import LAMBDA_DEFAULT_S, SmithController
from pressor.synthesis.verification.discrete_step import discrete_step_response
from pressor.synthesis.verification.step_response import StepResponse

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
    ctrl = SmithController(sample_period_s, max_rate_ml_h, lambda_s=lambda_s)
    return discrete_step_response(ctrl, k, t_s, tau_s, step_mmhg, t_end_s)[0]
