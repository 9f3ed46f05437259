"""Frozen-parameter step responses of the closed loop (continuous time, exact delay buffer).

The nominal step of docs/DESIGN-CHOICES.md: K = 0.55 mmHg/(ml/h), T = 150 s, tau = 40 s, a +20 mmHg
target step at t = 0 from rest, no noise, no pump saturation (the linear loop the paper plots; the
largest and smallest commanded rate are reported so a reader sees whether the pump limits would have
been touched).

Integration: a linear single-delay system ``dx/dt = A x + Ad x(t - tau) + b r(t) + bd r(t - tau)``
with a piecewise-constant reference is stepped with a fixed step h that divides tau exactly
(h = tau / ceil(tau / h_max)), so the delayed state is read straight from the buffer of past
samples. Over one step the delayed state is the first-order-hold (linear) interpolation between
its two buffered samples and everything else is integrated exactly (one augmented matrix
exponential); the local error is O(h^3) in the delayed term only, so h = 0.05 s is far below the
0.1 s resolution the metrics are quoted to (a test halves h and compares).

:func:`simulate_prefiltered_step` runs the two-degree-of-freedom structure of
:mod:`pressor.synthesis.problem.reference`: the loop's reference is the prefilter's r_m(t) and the plant
input gets the feedforward u_ff(t − τ) on top of the loop's command, both the closed-form
continuous-time law; between grid samples they enter with a first-order hold (exact for the
piecewise-exponential signals up to O(h^2), and exact at the step itself, which sits on the grid).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from pressor.synthesis.problem.closed_loop import DelaySystem
from pressor.synthesis.problem.config import NOMINAL_RHO

__all__ = [
    "NOMINAL_K",
    "NOMINAL_STEP_MMHG",
    "NOMINAL_T_S",
    "NOMINAL_TAU_S",
    "StepLoop",
    "StepResponse",
    "loop_from_closed_loop",
    "simulate_prefiltered_step",
    "simulate_step",
]

# K [mmHg/(ml/h)], T [s], tau [s]: the nominal plant of the design config
NOMINAL_K, NOMINAL_T_S, NOMINAL_TAU_S = NOMINAL_RHO
NOMINAL_STEP_MMHG = 20.0  # mmHg target step

Vector = NDArray[np.float64]


@dataclass(frozen=True)
class StepLoop:
    """A closed loop driven by the target r (mmHg), ready for :func:`simulate_step`.

    ``dx/dt = A x + Ad x(t - tau) + b_r r(t) + bd_r r(t - tau)``,
    ``MAP deviation = c_map . x`` (mmHg), ``infusion = c_u . x + d_u r`` (ml/h).
    """

    A: NDArray[np.float64]
    Ad: NDArray[np.float64]
    b_r: Vector
    bd_r: Vector
    c_map: Vector
    c_u: Vector
    d_u: float
    tau_s: float


@dataclass(frozen=True)
class StepResponse:
    """Sampled step response (t0 = 0, MAP and target as deviations from the pre-step level).

    Attributes
    ----------
    t_s
        Sample times (s), uniform, starting at 0.
    map_mmhg, target_mmhg
        MAP deviation and target (mmHg).
    infusion_ml_h
        Commanded infusion rate (ml/h), unsaturated.
    step_mmhg
        The step size (mmHg).
    """

    t_s: Vector
    map_mmhg: Vector
    target_mmhg: Vector
    infusion_ml_h: Vector
    step_mmhg: float


def loop_from_closed_loop(cl: DelaySystem, map_index: int = 0, u_index: int = 1) -> StepLoop:
    """Drive an LPV closed loop (w = [r, d_o, n_xe]) by r alone.

    The plant states x_a = [dMAP, u, x_e] come first in x_cl, so by default MAP is state 0 and the
    filtered infusion command u (ml/h) is state 1.
    """
    n = cl.n
    c_map = np.zeros(n)
    c_map[map_index] = 1.0
    c_u = np.zeros(n)
    c_u[u_index] = 1.0
    return StepLoop(cl.A, cl.Ad, cl.B[:, 0].copy(), np.zeros(n), c_map, c_u, 0.0, cl.tau)


def _one_step_maps(
    a: NDArray[np.float64], ad: NDArray[np.float64], b: NDArray[np.float64], h: float, slope: bool
) -> tuple[NDArray[np.float64], ...]:
    """Exact one-step maps for ``dx/dt = A x + Ad (p + s q) + B (v + s dv)`` over one step h.

    p, q, v (and dv) are constant over the step. Returns (Phi, G_p, G_q, G_v), plus G_dv when
    ``slope`` (a first-order hold of the inputs); without it the inputs are held constant (dv = 0)
    and the augmented matrix leaves the dv block out.
    """
    n, m = a.shape[0], b.shape[1]
    size = 3 * n + (2 * m if slope else m)
    big = np.zeros((size, size))
    big[:n, :n] = a
    big[:n, n : 2 * n] = ad  # delayed state p(s) = p0 + s q
    big[n : 2 * n, 2 * n : 3 * n] = np.eye(n)  # dp/ds = q
    big[:n, 3 * n : 3 * n + m] = b
    if slope:
        big[3 * n : 3 * n + m, 3 * n + m :] = np.eye(m)  # dv/ds = dv
    e = scipy.linalg.expm(big * h)
    maps = [e[:n, :n], e[:n, n : 2 * n], e[:n, 2 * n : 3 * n], e[:n, 3 * n : 3 * n + m]]
    if slope:
        maps.append(e[:n, 3 * n + m :])
    return tuple(maps)


def _march(
    phi: NDArray[np.float64],
    g_p: NDArray[np.float64],
    g_q: NDArray[np.float64],
    h: float,
    lag: int,
    steps: int,
    drive: Callable[[int, Vector], Vector],
) -> NDArray[np.float64]:
    """States x_0 = 0 .. x_steps of the delay system from rest, delayed states read from the buffer.

    Over step k the delayed state is the linear interpolation between the buffered x_{k-lag} and
    x_{k-lag+1} (zero before t = 0); ``drive(k, Phi x_k)`` adds the inputs' contribution.
    """
    g_q = g_q / h  # q = (x_{k-lag+1} - x_{k-lag}) / h
    g_p = g_p - g_q  # collect x_{k-lag} terms
    x = np.zeros((steps + 1, phi.shape[0]))
    for k in range(steps):
        nxt = drive(k, phi @ x[k])
        j = k - lag
        if lag and j + 1 >= 0:  # the history before t = 0 is rest (zero)
            nxt += g_q @ x[j + 1]
            if j >= 0:
                nxt += g_p @ x[j]
        x[k + 1] = nxt
    return x


def _time_grid(
    loop: StepLoop, step_mmhg: float, t_end_s: float, h_max_s: float
) -> tuple[int, float, int, NDArray[np.float64], NDArray[np.float64]]:
    """Check a step simulation's arguments; return (delay in steps, step h s, number of steps, A, Ad).

    The step h is the largest that is ≤ ``h_max_s`` and divides the delay exactly; with no delay
    the delayed term is folded into A (Ad returned as zeros).
    """
    if not (np.isfinite(step_mmhg) and step_mmhg != 0.0):
        raise ValueError(f"step_mmhg={step_mmhg!r} must be finite and non-zero")
    if not (np.isfinite(t_end_s) and t_end_s > 0.0):
        raise ValueError(f"t_end_s={t_end_s!r} must be > 0 s")
    if not (np.isfinite(h_max_s) and h_max_s > 0.0):
        raise ValueError(f"h_max_s={h_max_s!r} must be > 0 s")
    tau = float(loop.tau_s)
    lag = int(np.ceil(tau / h_max_s - 1e-9)) if tau > 0.0 else 0
    h = tau / lag if lag else h_max_s
    a = np.asarray(loop.A, dtype=float)
    ad = np.asarray(loop.Ad, dtype=float)
    if lag == 0:
        a, ad = a + ad, np.zeros_like(ad)
    return lag, h, int(np.ceil(t_end_s / h)), a, ad


def simulate_step(
    loop: StepLoop,
    step_mmhg: float = NOMINAL_STEP_MMHG,
    t_end_s: float = 1500.0,
    h_max_s: float = 0.05,
) -> StepResponse:
    """Simulate a target step of ``step_mmhg`` at t = 0 from rest (zero history).

    Parameters
    ----------
    loop
        The closed loop.
    step_mmhg
        Target step (mmHg), finite and non-zero.
    t_end_s
        Simulated horizon (s), > 0.
    h_max_s
        Largest integration step (s); the step used divides tau exactly.

    Returns
    -------
    StepResponse
        Samples every h on [0, t_end].
    """
    lag, h, steps, a, ad = _time_grid(loop, step_mmhg, t_end_s, h_max_s)
    b = np.column_stack([loop.b_r, loop.bd_r])
    phi, g_p, g_q, g_w = _one_step_maps(a, ad, b, h, slope=False)
    w_before = g_w @ np.array([step_mmhg, 0.0])  # r(t - tau) still zero while t < tau
    w_after = g_w @ np.array([step_mmhg, step_mmhg])
    x = _march(phi, g_p, g_q, h, lag, steps, lambda k, y: y + (w_after if k >= lag else w_before))
    t = np.arange(steps + 1) * h
    r = np.full(steps + 1, float(step_mmhg))
    map_mmhg = x @ np.asarray(loop.c_map, dtype=float)
    infusion = x @ np.asarray(loop.c_u, dtype=float) + loop.d_u * r
    return StepResponse(t, map_mmhg, r, infusion, float(step_mmhg))


def simulate_prefiltered_step(
    loop: StepLoop,
    b_ff: Vector,
    reference: Callable[[Vector], tuple[Vector, Vector]],
    step_mmhg: float = NOMINAL_STEP_MMHG,
    t_end_s: float = 1500.0,
    h_max_s: float = 0.05,
) -> StepResponse:
    """Target step of ``step_mmhg`` at t = 0 through the two-degree-of-freedom structure.

    ``dx/dt = A x + Ad x(t − τ) + b_r r_m(t) + bd_r r_m(t − τ) + b_ff u_ff(t − τ)``; MAP deviation
    ``c_map . x``; infusion ``c_u . x + d_u r_m + u_ff`` (feedback plus feedforward, unsaturated).

    Parameters
    ----------
    loop
        The feedback loop (its reference input is driven by r_m).
    b_ff
        Where the delayed feedforward enters the loop state (e.g. K/T on the MAP state).
    reference
        t (s) -> (u_ff(t) ml/h, r_m(t) − m0 mmHg), zero for t < 0
        (:func:`pressor.synthesis.problem.reference.frozen_step_reference` with the design's parameters).
    step_mmhg, t_end_s, h_max_s
        As :func:`simulate_step`.
    """
    lag, h, steps, a, ad = _time_grid(loop, step_mmhg, t_end_s, h_max_s)
    t = np.arange(steps + 1) * h
    u_ff, r_m = reference(t)
    u_ff_d, r_m_d = reference(t - float(loop.tau_s))
    v = np.column_stack([r_m, r_m_d, u_ff_d])  # inputs on the grid, first-order hold between
    b = np.column_stack([loop.b_r, loop.bd_r, np.asarray(b_ff, dtype=float)])
    phi, g_p, g_q, g_v, g_dv = _one_step_maps(a, ad, b, h, slope=True)
    g_dv = g_dv / h
    x = _march(phi, g_p, g_q, h, lag, steps, lambda k, y: y + g_v @ v[k] + g_dv @ (v[k + 1] - v[k]))
    target = np.full(steps + 1, float(step_mmhg))
    map_mmhg = x @ np.asarray(loop.c_map, dtype=float)
    infusion = x @ np.asarray(loop.c_u, dtype=float) + loop.d_u * r_m + u_ff
    return StepResponse(t, map_mmhg, target, infusion, float(step_mmhg))


def response_metrics(response: StepResponse, max_rate_ml_h: float = 120.0) -> dict[str, object]:
    """The metrics (docs/METRICS.md) of a noise-free step (computed by :mod:`pressor.contracts.metrics`).

    Returns the step metrics (``overshoot_pct``, ``rise_time_s``, ``settling_time_s``,
    ``steady_state_dev_mmhg``, ``iae_mmhg_s``; 2 % band) plus ``max_rate_ml_h``,
    ``drug_total_ml``, ``time_at_limit_pct`` and ``stable`` of the unsaturated command, and
    ``min_rate_ml_h`` (a negative value means the linear loop asked the pump to run backwards).
    """
    from pressor.contracts.metrics import run_metrics, step_metrics

    out: dict[str, object] = dict(
        step_metrics(response.t_s, response.map_mmhg, response.target_mmhg, 0.0, response.step_mmhg)
    )
    run = run_metrics(
        response.t_s,
        response.map_mmhg,
        response.target_mmhg,
        response.infusion_ml_h,
        max_rate_ml_h,
        step_time_s=0.0,
        step_mmhg=response.step_mmhg,
    )
    for key in ("max_rate_ml_h", "drug_total_ml", "time_at_limit_pct", "stable"):
        out[key] = run[key]
    out["min_rate_ml_h"] = float(np.min(response.infusion_ml_h))
    return out
