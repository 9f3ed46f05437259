"""A frozen step of any discrete controller (:class:`pressor.contracts.controller.Controller`) against the
exact zero-order-hold discretisation of the first-order-plus-delay plant.

The plant ``T dy/dt = −y + K u(t − τ)``, with τ = (D + f)·Ts, D integer, 0 ≤ f < 1 and a command
held over each tick, gives exactly::

    y_k+1 = a y_k + K (e^(−(1−f)Ts/T) − a) u_k−D−1 + K (1 − e^(−(1−f)Ts/T)) u_k−D,  a = e^(−Ts/T)

The step starts from rest (y = 0, no infusion before t = 0); the controller is stepped every Ts
with the MAP ``baseline_mmhg + y`` and the target ``baseline_mmhg + step_mmhg`` and scheduled on
the plant's own K, T, τ. Its command is clamped to [0, ``max_rate_ml_h``] as the runtime's
supervisor clamps it, so the pump limit is part of the response. The scheduled Smith baseline
(:mod:`pressor.synthesis.verification.smith_baseline`) and ``pressor verify --controller`` (a plugin) both
run here, and the code generator's frozen-loop checks (:mod:`pressor.codegen.frozen_loop`,
:func:`pressor.codegen.fixed_point.signal_peaks`) sample the same plant through :func:`sampled_fopdt`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pressor.contracts.controller import Controller
from pressor.synthesis.verification.step_response import StepResponse

__all__ = ["SampledFopdt", "StepFailed", "discrete_step_response", "sampled_fopdt"]


class StepFailed(ValueError):
    """The controller returned a non-finite command during the step (names the time, s)."""


@dataclass(frozen=True)
class SampledFopdt:
    """The plant ``T dy/dt = −y + K u(t − τ)`` sampled exactly under a zero-order hold.

    ``y_k+1 = a y_k + b_new u_k−whole + b_old u_k−whole−1`` with τ = (whole + frac)·Ts.
    """

    a: float
    b_new: float
    b_old: float
    whole: int
    frac: float


def sampled_fopdt(k: float, t_s: float, tau_s: float, sample_period_s: float) -> SampledFopdt:
    """The exact zero-order-hold discretisation of the first-order-plus-delay plant.

    Parameters
    ----------
    k, t_s, tau_s
        K (mmHg/(ml/h)), T (s, > 0), τ (s, ≥ 0).
    sample_period_s
        The hold period Ts (s, > 0).

    Returns
    -------
    SampledFopdt
        Its coefficients; a delay within 1e-9 samples below a whole number of samples counts as
        that whole number (an exact multiple of Ts must not lose a tick to rounding).
    """
    ts = float(sample_period_s)
    lags = tau_s / ts
    whole = math.floor(lags + 1e-9)
    frac = max(lags - whole, 0.0)
    a = math.exp(-ts / t_s)
    late = math.exp(-(1.0 - frac) * ts / t_s)  # decay left after the new input starts
    return SampledFopdt(a, k * (1.0 - late), k * (late - a), whole, frac)


def discrete_step_response(
    controller: Controller,
    k: float,
    t_s: float,
    tau_s: float,
    step_mmhg: float,
    t_end_s: float,
    baseline_mmhg: float = 0.0,
) -> tuple[StepResponse, int]:
    """Simulate a target step of ``step_mmhg`` at t = 0 with ``controller``.

    Parameters
    ----------
    controller
        Stepped every ``controller.sample_period_s`` (s); its ``max_rate_ml_h`` is the clamp.
    k, t_s, tau_s
        Frozen plant: K (mmHg/(ml/h), > 0), T (s, > 0), τ (s, ≥ 0); the controller is scheduled
        on the same values.
    step_mmhg
        Target step (mmHg) from rest.
    t_end_s
        Horizon (s), > 0.
    baseline_mmhg
        The MAP (mmHg) the step starts from, as the controller sees it (the response is the
        deviation from it).

    Returns
    -------
    tuple
        The :class:`StepResponse` (MAP deviation, target deviation and the clamped command, one
        sample per tick on [0, t_end]) and the number of ticks whose command was clamped.

    Raises
    ------
    ValueError
        A bad plant or horizon.
    StepFailed
        The controller returned a non-finite command (an exception in ``step`` propagates).
    """
    if not (k > 0.0 and t_s > 0.0 and tau_s >= 0.0 and math.isfinite(k + t_s + tau_s)):
        raise ValueError(f"plant K={k!r}, T={t_s!r}, tau={tau_s!r} must be finite, > 0 (tau >= 0)")
    if not (math.isfinite(t_end_s) and t_end_s > 0.0):
        raise ValueError(f"t_end_s={t_end_s!r} must be > 0 s")
    ts = float(controller.sample_period_s)
    high = float(controller.max_rate_ml_h)
    plant = sampled_fopdt(k, t_s, tau_s, ts)
    a, b_new, b_old, whole = plant.a, plant.b_new, plant.b_old, plant.whole
    steps = math.ceil(t_end_s / ts - 1e-9)
    y = np.zeros(steps + 1)
    u = np.zeros(steps + 1)
    target = baseline_mmhg + step_mmhg
    clamped = 0
    for i in range(steps + 1):
        raw = float(controller.step(baseline_mmhg + y[i], target, k, t_s, tau_s))
        if not math.isfinite(raw):
            raise StepFailed(f"the controller returned {raw!r} ml/h at t = {i * ts:g} s")
        cmd = min(max(raw, 0.0), high)
        clamped += cmd != raw
        u[i] = cmd
        if i == steps:
            break
        j = i - whole
        u_new = u[j] if j >= 0 else 0.0
        u_old = u[j - 1] if j >= 1 else 0.0
        y[i + 1] = a * y[i] + b_new * u_new + b_old * u_old
    t = np.arange(steps + 1) * ts
    return StepResponse(t, y, np.full(steps + 1, float(step_mmhg)), u, float(step_mmhg)), clamped
