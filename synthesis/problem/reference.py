"""Two-degree-of-freedom tracking: a scheduled reference prefilter outside the certified loop.

The certified LPV controller regulates the *model error*: its target input is a reference MAP
trajectory r_m generated from the target by a scheduled first-order-plus-delay model of the
patient, and its output is added to the feedforward infusion u_ff that makes that model follow
r_m. The prefilter is open loop with respect to the measured MAP (it never reads it after the
anchor), so it cannot destabilise the certified loop; it only changes the reference the loop sees
and the input it gets added to. Speed of tracking then comes from the prefilter, not from the
feedback bandwidth.

The law (physical units, time in s; K mmHg/(ml/h), T s, tau s the model: the feedback's own
scheduled values, clamped to the design box and rate limited to its certified rates, K not below
``k_min``, T the fixed ``lag_s`` when the design sets one; lambda_s, pump_fraction, k_min and lag_s
from the design's ``[reference]`` section)::

    m0      = MAP at the first valid sample after reset            (the anchor, mmHg)
    Δr(t)   = target(t) − m0                                         (mmHg)
    p       = y0 + (y_m − y0(t − τ))                                 (prediction, mmHg)
    u_law   = (p + T·(Δr − p)/λ) / K                                 (ml/h)
    cap     = max(α·u_max, min(u_max, Δr/K))                         (ml/h)
    u_ff    = clamp(u_law, 0, cap)
    T·dy0/dt = −y0 + K·u_ff(t)                                       (delay-free model, mmHg)
    T·dy_m/dt = −y_m + K·u_ff(t − τ)                                 (the model with its delay)
    T·ds/dt  = −s + max(0, Δr − K·u_max)                             (what the model cannot reach)
    r_m     = m0 + y_m + s                                           (reference MAP, mmHg)

* The model runs on the feedback's K, T, τ after the generated module's clamp and rate limit, so
  the feedforward never pushes harder than the certified feedback is scheduled for: an estimate
  that jumps (or a K below the box) reaches the feedforward at the certified rate, as it reaches
  the feedback (before, the model took the reported K unlimited, and a feedback at K 0.69 ran
  beside a feedforward sized for 0.25: issue 41).
* s: when the model's K cannot reach the target at the pump's maximum, r_m still goes there, so
  the feedback brings MAP to the target whenever the pump can (before, r_m stopped at
  m0 + K·u_max and MAP settled short with the pump at 60 ml/h).
* p is a Smith predictor of the delayed model: with constant τ, y_m(t) = y0(t − τ) and p = y0.
  When τ moves (a vasopressor's transport delay stretches while the infusion is high), the
  delayed input is played slower or faster than it was sent and y_m departs from y0(t − τ); the
  correction feeds that departure back into the law so the model still lands on the target
  (without it, a delay growing at ~1 s/s during the transient overshot the target by 3–6 %).
* Unsaturated with constant τ, u_law makes the delay-free model follow dy0/dt = (Δr − y0)/λ, i.e.
  y0 = Δr/(λs + 1) and u_ff = (Ts + 1)/(K(λs + 1)) Δr, the textbook model-following feedforward.
* The clamp keeps u_ff within a share α = ``pump_fraction`` of the pump limit u_max, so the
  feedback keeps (1 − α)·u_max of headroom during the transient; the model is driven by the
  *clamped* u_ff, so r_m is always a trajectory the model can follow within the pump limit. With a
  small λ the profile is close to time optimal under that limit (full share, then a first-order
  landing); the landing with time constant λ keeps the feedforward continuous after t = 0.
* The cap is raised to the steady-state infusion Δr/K when that exceeds α·u_max (never beyond
  u_max), so the model's final value is the target whenever the model can reach it at all.
* Target changes mid-run are inputs of the same model: no re-anchoring, no jump of r_m or y0.
  The anchor m0 only sets the feedforward's steady level: if the patient was not at rest at the
  anchor, the feedback integral absorbs the difference (r_m still ends at the target).
* K, T, τ vary over time: the model is simulated with the current (rate-limited) values (the
  delayed model has the patient's own structure, K(t)·u(t − τ(t))), so on a patient that is this
  model the MAP is r_m and the feedback sees no error at all.

Anti-windup with the feedback: the total command is u_fb + u_ff, clamped to [0, u_max]; the
feedback's own command state is therefore clamped to [−u_ff, u_max − u_ff] and its integrators
are frozen while the total sits at a limit and the error pushes further into it (the generated
step's conditional integration, with the feedforward's share taken out). The feedback never winds
up against the feedforward.

This module holds the configuration and the continuous-time solution of the law for frozen
parameters (the nominal step of ``pressor verify``). The per-sample law is emitted by
:mod:`pressor.codegen.emit_python` and :mod:`pressor.codegen.emit_c`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["ReferenceConfig", "frozen_step_reference"]

#: Allowed ranges of the [reference] fields.
LAMBDA_RANGE_S = (1.0, 1000.0)
PUMP_FRACTION_RANGE = (0.1, 1.0)
K_MIN_RANGE = (1e-4, 10.0)
LAG_RANGE_S = (1.0, 2000.0)


@dataclass(frozen=True)
class ReferenceConfig:
    """The ``[reference]`` design section: the two-degree-of-freedom prefilter.

    Attributes
    ----------
    enabled
        Whether the generated controller runs the prefilter (False: the LPV sees the target).
    lambda_s
        Time constant λ (s) of the reference model's landing (its linear phase).
    pump_fraction
        α in (0, 1]: the feedforward stays at or below α·max_rate during the transient.
    k_min
        Floor (mmHg/(ml/h)) of the model gain K. The model runs on the feedback's own K (clamped
        to the design box and rate limited), never below this floor.
    lag_s
        None (default): the model's lag is the feedback's scheduled T (clamped, rate limited).
        A number (s): the model's lag, fixed. The feedforward's opening push is T/λ times the
        steady infusion; a fixed lag at the box's low T keeps that push to what the fastest
        patient of the box follows without overshoot, whatever T the feedback is scheduled on
        (the cautious start, docs/notes/cautious-start.md).
    """

    enabled: bool = False
    lambda_s: float = 10.0
    pump_fraction: float = 0.9
    k_min: float = 0.05
    lag_s: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the artifact's ``reference`` metadata entry; ``lag_s`` only when
        set, so older artifacts keep their bytes)."""
        out: dict[str, Any] = {
            "enabled": bool(self.enabled),
            "lambda_s": float(self.lambda_s),
            "pump_fraction": float(self.pump_fraction),
            "k_min": float(self.k_min),
        }
        if self.lag_s is not None:
            out["lag_s"] = float(self.lag_s)
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ReferenceConfig:
        """Inverse of :meth:`to_dict`; raises ValueError naming the field on a bad value."""
        enabled = d["enabled"]
        if not isinstance(enabled, bool):
            raise ValueError(f"reference.enabled = {enabled!r}: must be true or false")
        lam = float(d["lambda_s"])
        frac = float(d["pump_fraction"])
        if not (math.isfinite(lam) and LAMBDA_RANGE_S[0] <= lam <= LAMBDA_RANGE_S[1]):
            raise ValueError(f"reference.lambda_s = {lam!r}: must be in {list(LAMBDA_RANGE_S)} s")
        if not (math.isfinite(frac) and PUMP_FRACTION_RANGE[0] <= frac <= PUMP_FRACTION_RANGE[1]):
            raise ValueError(
                f"reference.pump_fraction = {frac!r}: must be in {list(PUMP_FRACTION_RANGE)}"
            )
        k_min = float(d["k_min"])
        if not (math.isfinite(k_min) and K_MIN_RANGE[0] <= k_min <= K_MIN_RANGE[1]):
            raise ValueError(f"reference.k_min = {k_min!r}: must be in {list(K_MIN_RANGE)}")
        lag = d.get("lag_s")
        if lag is not None:
            lag = float(lag)
            if not (math.isfinite(lag) and LAG_RANGE_S[0] <= lag <= LAG_RANGE_S[1]):
                raise ValueError(f"reference.lag_s = {lag!r}: must be in {list(LAG_RANGE_S)} s")
        return cls(enabled, lam, frac, k_min, lag)


def _cap(step_mmhg: float, K: float, pump_fraction: float, max_rate_ml_h: float) -> float:
    return max(pump_fraction * max_rate_ml_h, min(max_rate_ml_h, step_mmhg / K))


def frozen_step_reference(
    t_s: NDArray[np.float64],
    step_mmhg: float,
    K: float,
    T_s: float,
    tau_s: float,
    cfg: ReferenceConfig,
    max_rate_ml_h: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Continuous-time u_ff(t) and r_m(t) − m0 for a target step at t = 0 from rest, frozen ρ.

    Closed form of the law in the module docstring: while u_law exceeds the cap the delay-free
    model rises as K·cap·(1 − e^(−t/T)); from the switching level y_s (u_law(y_s) = cap) on it
    lands as Δr − (Δr − y_s)·e^(−(t − t_s)/λ). A step Δr ≤ 0 gives u_ff = 0 and r_m = m0 (a
    vasopressor cannot lower MAP below where it was at rest).

    Parameters
    ----------
    t_s
        Times (s), any order, may be negative (before the step: u_ff = 0, r_m = m0).
    step_mmhg
        Target step Δr (mmHg).
    K, T_s, tau_s
        Frozen model: mmHg/(ml/h), s, s (K > 0, T > 0, tau >= 0); T is ``cfg.lag_s`` when the
        design fixes the model's lag.
    cfg
        The prefilter configuration (``enabled`` is not consulted).
    max_rate_ml_h
        Pump limit u_max (ml/h).

    Returns
    -------
    (u_ff, y_m)
        Feedforward (ml/h) at t and model MAP deviation r_m − m0 (mmHg) at t.
    """
    t = np.asarray(t_s, dtype=float)
    if cfg.lag_s is not None:  # the model's lag is the design's fixed one
        T_s = cfg.lag_s
    if not (K > 0 and T_s > 0 and tau_s >= 0 and max_rate_ml_h > 0):
        raise ValueError(f"need K > 0, T > 0, tau >= 0, max_rate > 0; got {K, T_s, tau_s}")
    lam, dr = cfg.lambda_s, float(step_mmhg)

    def delay_free(tt: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        u = np.zeros_like(tt)
        y = np.zeros_like(tt)
        if dr <= 0.0:
            return u, y
        cap = _cap(dr, K, cfg.pump_fraction, max_rate_ml_h)
        pos = tt >= 0.0
        if T_s * dr / (lam * K) > cap:  # u_law(0) above the cap: saturated phase first
            y_s = (K * cap * lam - T_s * dr) / (lam - T_s)  # u_law(y_s) = cap (lam < T_s here)
            frac = y_s / (K * cap)
            t_sw = -T_s * math.log1p(-frac) if 0.0 <= frac < 1.0 else math.inf
        else:
            y_s, t_sw = 0.0, 0.0
        sat = pos & (tt < t_sw)
        y[sat] = K * cap * -np.expm1(-tt[sat] / T_s)
        u[sat] = cap
        land = pos & (tt >= t_sw)
        y[land] = dr - (dr - y_s) * np.exp(-(tt[land] - t_sw) / lam)
        u[land] = (y[land] + T_s * (dr - y[land]) / lam) / K
        return u, y

    u_ff, _ = delay_free(t)
    _, y_m = delay_free(t - tau_s)
    return u_ff, y_m
