"""The scheduled Smith law on a 200 s delay box, exact or trapezoid integral: a research plugin.

Usage (the plugin spec of :mod:`pressor.runtime.inputs.controller_plugin`)::

    python -m research.schedule_sources --model one-compartment --patients 20 \\
        --lpv research.predicted_error_law:PredictedErrorLaw --runs lpv-stepfit,pi,smith
    ... --lpv research.predicted_error_law:PredictedErrorLaw:law=trapezoid    # the shipped law

The analysis of :mod:`pressor.synthesis.certificates.wirtinger.prediction_error` certifies, on a
τ ≤ 200 s box, the law with the *exact* integral of the predicted error ``q = x_e − ∫_{t−τ}^{t} ŷ`` (a
distributed delay the synthesis controller class and the generated modules cannot carry) and, at
slower rates, the shipped law (the integral written as the trapezoid ``τ(ŷ + ŷ(t − τ))/2``,
:mod:`pressor.synthesis.families.smith.law`). ``pressor synth`` does not run that analysis yet, so no
artifact or generated module of either exists on that box. This module runs both laws in plain
Python behind the same prefilter, so they are compared with everything else equal; with
``law="trapezoid"`` it reproduces the research build of ``research/designs/wide_delay.toml``
(docs/notes/estimation.md).

Per tick of Ts (s), physical units (MAP mmHg, rates ml/h, K mmHg/(ml/h), T and τ s):

* prefilter: the shipped design's reference model and feedforward
  (:mod:`pressor.synthesis.problem.reference`, λ_ref = 10 s, pump share 0.9, K floor 0.05), giving u_ff and the reference MAP r_m;
* feedback on e = r_m − MAP: the filter state u_fb (``u_fb' = −Λ u_fb + Ω u_a``, Ω = Λ = 0.1 1/s),
  the model ``T ŷ' = −ŷ + K u_fb``, the predicted error ``e_p = e − ŷ + ŷ(t − τ)`` and
  ``u_a = Kc e_p + Ki q`` (``Kc = g/K``, ``Ki = g_i/(K T)``, g = ``loop_gain``, default 3,
  g_i = ``integral_gain``, default g),
  ``q' = e_p`` (exact) or
  ``u_a = Kc e_p + Ki (x_e − τ(ŷ + ŷ(t − τ))/2)``, ``x_e' = e`` (trapezoid);
* u_fb is clamped to [−u_ff, u_max − u_ff]; the integrators freeze while the clamp holds and the
  error drives further into it (as the generated modules do); the command is u_ff + u_fb.

The first-order lags are advanced exactly over the tick (zero-order hold). ρ is clamped to the box
(:data:`GRID_LO`, :data:`GRID_HI`) and not rate-limited (the step-fit schedule is constant). Not a
certified product: never load it for a pump.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: the scheduling box (K mmHg/(ml/h), T s, τ s) of research/designs/wide_delay.toml
GRID_LO = (0.15, 100.0, 10.0)
GRID_HI = (3.0, 700.0, 200.0)
#: the rates at which the exact law is certified at τ̄ = 200 s (per s; docs/notes/certificate-structure.md
#: §5; the trapezoid needs 5e-5 / 0.01 / 0.01)
RATE_BOUNDS = (2e-4, 0.03, 0.05)
LOOP_GAIN = 3.0
OMEGA = LAMBDA = 0.1  # 1/s
REF_LAMBDA_S = 10.0
REF_PUMP_FRACTION = 0.9
REF_K_MIN = 0.05
LAWS = ("exact", "trapezoid")


@dataclass
class _Status:
    saturated: bool = False
    rho_clamped: bool = False
    rho_rate_limited: bool = False


class _Line:
    """A delay line of one signal, read at a fractional delay (linear interpolation)."""

    def __init__(self, n: int) -> None:
        self.buf = [0.0] * n
        self.head = 0

    def push(self, value: float) -> None:
        self.head = (self.head + 1) % len(self.buf)
        self.buf[self.head] = value

    def read(self, lag_samples: float) -> float:
        n = int(lag_samples)
        f = lag_samples - n
        size = len(self.buf)
        a = self.buf[(self.head - n) % size]
        b = self.buf[(self.head - n - 1) % size]
        return a + (b - a) * f


class PredictedErrorLaw:
    """The module's law; ``law`` "exact" (default) or "trapezoid", ``loop_gain`` g in (0, 10],
    ``integral_gain`` g_i in (0, 10] (None: g_i = g)."""

    def __init__(
        self,
        sample_period_s: float = 0.1,
        max_rate_ml_h: float = 120.0,
        law: str = "exact",
        loop_gain: float = LOOP_GAIN,
        integral_gain: float | None = None,
    ) -> None:
        if law not in LAWS:
            raise ValueError(f"law={law!r} must be one of {LAWS}")
        if not 0.0 < loop_gain <= 10.0:
            raise ValueError(f"loop_gain={loop_gain!r} must lie in (0, 10]")
        self.loop_gain = float(loop_gain)
        self.integral_gain = float(loop_gain if integral_gain is None else integral_gain)
        if not 0.0 < self.integral_gain <= 10.0:
            raise ValueError(f"integral_gain={integral_gain!r} must lie in (0, 10]")
        self.sample_period_s = float(sample_period_s)
        self.max_rate_ml_h = float(max_rate_ml_h)
        self.law = law
        self._n = math.ceil(GRID_HI[2] / self.sample_period_s) + 2
        self._filter_decay = math.exp(-LAMBDA * self.sample_period_s)  # the input filter, per tick
        self.reset()

    def reset(self) -> None:
        """Zero every state and empty the delay lines."""
        self._anchor: float | None = None
        self._y0 = self._ym = self._yhat = self._u_fb = self._integral = 0.0
        self._y0_line, self._uff_line, self._yhat_line = (_Line(self._n) for _ in range(3))
        self._status = _Status()
        self._last_ml_h = 0.0

    @property
    def status(self) -> _Status:
        """Flags of the last step."""
        return self._status

    def step(self, map_mmhg: float, target_mmhg: float, K: float, T: float, tau: float) -> float:
        """One tick: the infusion command (ml/h) for this tick.

        A non-finite MAP, target or ρ holds the previous command and every state (the supervisor
        judges the sample), as the baselines do.
        """
        if not all(math.isfinite(v) for v in (map_mmhg, target_mmhg, K, T, tau)):
            return self._last_ml_h
        ts, u_max = self.sample_period_s, self.max_rate_ml_h
        rho = [K, T, tau]
        clamped = [min(max(v, lo), hi) for v, lo, hi in zip(rho, GRID_LO, GRID_HI, strict=True)]
        self._status.rho_clamped = clamped != rho
        k, t_s, tau_s = clamped
        lag = tau_s / ts
        decay = math.exp(-ts / t_s)
        if self._anchor is None:
            self._anchor = map_mmhg
        # prefilter: the scheduled reference model and its feedforward
        k_ref = max(K, REF_K_MIN)
        step = target_mmhg - self._anchor
        p = self._y0 + self._ym - self._y0_line.read(lag)
        u_law = (p + t_s * (step - p) / REF_LAMBDA_S) / k_ref
        cap = max(REF_PUMP_FRACTION * u_max, min(u_max, step / k_ref))
        u_ff = min(max(u_law, 0.0), cap)
        u_ff_delayed = self._uff_line.read(lag)
        self._y0 = decay * self._y0 + (1.0 - decay) * k_ref * u_ff
        self._ym = decay * self._ym + (1.0 - decay) * k_ref * u_ff_delayed
        self._y0_line.push(self._y0)
        self._uff_line.push(u_ff)
        reference = self._anchor + self._ym
        # feedback on the model error
        e = reference - map_mmhg
        yhat_delayed = self._yhat_line.read(lag)
        e_p = e - self._yhat + yhat_delayed
        kc = self.loop_gain / k
        ki = self.integral_gain / (k * t_s)
        if self.law == "exact":
            u_a = kc * e_p + ki * self._integral
            drive = e_p
        else:
            u_a = kc * e_p + ki * (self._integral - tau_s * (self._yhat + yhat_delayed) / 2.0)
            drive = e
        f = self._filter_decay
        u_fb = f * self._u_fb + (1.0 - f) * (OMEGA / LAMBDA) * u_a
        low, high = -u_ff, u_max - u_ff
        freeze = (u_fb > high and drive > 0.0) or (u_fb < low and drive < 0.0)
        self._status.saturated = not low <= u_fb <= high
        self._u_fb = min(max(u_fb, low), high)
        if not freeze:
            self._integral += ts * drive
        self._yhat = decay * self._yhat + (1.0 - decay) * k * self._u_fb
        self._yhat_line.push(self._yhat)
        self._last_ml_h = min(max(u_ff + self._u_fb, 0.0), u_max)
        return self._last_ml_h
