"""A scheduled Smith predictor with a PI on the predicted output: the control engineer's baseline.

Standard library only. Units: MAP and target in mmHg, commands in ml/h, K in mmHg/(ml/h), T, τ, λ
and Ts in s.

Law (one tick k of period Ts, all quantities sampled at the tick)::

    ym_k                        delay-free first-order model output (mmHg), model state
    ym(k − τ/Ts)                the model output τ seconds ago, read from a delay line
    y_p,k = MAP_k + ym_k − ym(k − τ/Ts)           predicted (delay-free) MAP, mmHg
    e_k   = target_k − y_p,k                      mmHg
    u_k   = clamp(Kc·e_k + I_k, 0, max_rate_ml_h)  ml/h, the command sent
    I_k+1 = I_k + (Kc/Ti)·Ts·e_k                   skipped while clamped and e_k drives further in
    ym_k+1 = a·ym_k + (1 − a)·K·u_k,  a = exp(−Ts/T)

The model ``T dym/dt = −ym + K u`` is advanced exactly over the tick for the command actually sent
(the clamped one, held over the tick, i.e. zero-order hold) with the tick's K and T. On a plant
equal to the model the delayed model output cancels the measured MAP's delayed response, so the PI
sees the delay-free plant K/(Ts+1).

Tuning (direct synthesis / IMC for a first-order plant): ``Kc = T/(K·λ)`` (ml/h per mmHg) and
``Ti = T`` (s), so Kc/Ti = 1/(K·λ). The zero of the PI cancels the model pole and the delay-free
loop is 1/(λs + 1): the closed-loop time constant λ is the one tuning knob (default 30 s, fixed so
comparisons stay fixed; allowed [LAMBDA_MIN_S, LAMBDA_MAX_S]). The gains follow the schedule every
tick; the integral term is stored in ml/h, so a gain change does not make the command jump.

Delay line: a preallocated ring buffer of ceil(tau_max/Ts) + 1 model samples (lags 0 … N−1), one
write and two reads per tick (O(1)). τ is read as a fractional delay d = τ/Ts ticks, linearly
interpolated between lags floor(d) and floor(d) + 1. Before the first tick the model has rested at
zero (zero infusion), which is what the buffer holds after :meth:`SmithController.reset`.

Anti-windup: conditional integration, as :mod:`pressor.baselines.pi` (no integration while the
command is clamped and the error pushes further into the limit). The model always runs on the
clamped command, so saturation does not corrupt the prediction.

Scheduling limits (documented physical range; both counted in :attr:`SmithController.status`):

- K clamped to [0.02, 5] mmHg/(ml/h): Kc grows as 1/K, so the lower end caps the gain at
  T/(0.02·λ); the cohort's smallest sensitivity is ≈ 0.04 (k0 0.1, full pump). T clamped to
  [10, 1000] s and τ to [0, tau_max_s] (default 120 s, the delay line's length).
- rate limits |dK/dt| ≤ 0.02 mmHg/(ml/h)/s, |dT/dt| ≤ 2 s/s, |dτ/dt| ≤ 5 s/s: about ten times the
  fastest physiological change in the simulator (K moves with a time constant ≥ 500 s, T by at
  most 0.04 s/s, τ by ~1 s/s), so true changes pass and a glitching estimator cannot make the
  model jump. The first schedule after :meth:`reset` is taken as is (clamped only).
- a non-finite K, T or τ keeps that parameter's last valid value (the nominal plant before any).

Sampling semantics: :meth:`step` is called once per Ts with the MAP sampled at the tick and returns
the command held until the next tick. A non-finite MAP or target holds the previous command without
integrating (the supervisor decides about the bad sample; the controller never returns NaN); the
model and the delay line still advance with that held command, since the pump keeps delivering it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pressor.baselines.pi import check_period_and_limit
from pressor.contracts.checks import check_range

LAMBDA_DEFAULT_S = 30.0
LAMBDA_MIN_S = 5.0
LAMBDA_MAX_S = 600.0
TAU_MAX_DEFAULT_S = 120.0

#: (low, high) clamp of K (mmHg/(ml/h)), T (s); τ is clamped to [0, tau_max_s]
K_RANGE = (0.02, 5.0)
T_RANGE_S = (10.0, 1000.0)
#: |dK/dt| (mmHg/(ml/h)/s), |dT/dt| (s/s), |dτ/dt| (s/s)
SCHEDULE_RATE_LIMITS = (0.02, 2.0, 5.0)
#: the schedule used until a finite one arrives: the nominal plant (K, T s, τ s)
INITIAL_SCHEDULE = (0.55, 150.0, 40.0)


@dataclass
class SmithStatus:
    """Flags of the last step and counts since :meth:`SmithController.reset`.

    Attributes
    ----------
    saturated
        The command was clamped to [0, max_rate_ml_h].
    rho_clamped, rho_rate_limited
        K, T or τ was clamped to its range / rate-limited on this step.
    rho_clamped_count, rho_rate_limited_count
        Steps with ``rho_clamped`` / ``rho_rate_limited`` since the last reset.
    """

    saturated: bool = False
    rho_clamped: bool = False
    rho_rate_limited: bool = False
    rho_clamped_count: int = 0
    rho_rate_limited_count: int = 0


def _limit(value: float, previous: float, max_step: float) -> float:
    return min(max(value, previous - max_step), previous + max_step)


class SmithController:
    """Scheduled Smith predictor + PI implementing :class:`pressor.contracts.controller.Controller`.

    Parameters
    ----------
    sample_period_s
        Sample period Ts in s, in (0, 10].
    max_rate_ml_h
        Pump limit in ml/h, in (0, 10000].
    lambda_s
        Closed-loop time constant λ in s, in [LAMBDA_MIN_S, LAMBDA_MAX_S] (default 30).
    tau_max_s
        Longest delay the delay line holds (s), in [0, 600]; τ is clamped to [0, tau_max_s].

    Bound to no drug (``DRUG_AGNOSTIC``, :func:`pressor.contracts.drug.drug_agnostic`): it is scheduled
    on the K, T, τ it is given, in ml/h of whatever syringe the schedule counts.
    """

    DRUG_AGNOSTIC = True

    def __init__(
        self,
        sample_period_s: float = 0.1,
        max_rate_ml_h: float = 120.0,
        lambda_s: float = LAMBDA_DEFAULT_S,
        tau_max_s: float = TAU_MAX_DEFAULT_S,
    ) -> None:
        check_period_and_limit(sample_period_s, max_rate_ml_h)
        check_range("lambda_s", lambda_s, LAMBDA_MIN_S, LAMBDA_MAX_S, unit="s")
        check_range("tau_max_s", tau_max_s, 0.0, 600.0, unit="s")
        self.sample_period_s = float(sample_period_s)
        self.max_rate_ml_h = float(max_rate_ml_h)
        self.lambda_s = float(lambda_s)
        self.tau_max_s = float(tau_max_s)
        # lags 0 .. N-1; the 1e-9 keeps an exact multiple (120 s / 0.1 s) from rounding up
        self._n = math.ceil(self.tau_max_s / self.sample_period_s - 1e-9) + 1
        self._line = [0.0] * self._n
        dts = self.sample_period_s
        self._max_steps = (
            SCHEDULE_RATE_LIMITS[0] * dts,
            SCHEDULE_RATE_LIMITS[1] * dts,
            SCHEDULE_RATE_LIMITS[2] * dts,
        )
        self.reset()

    def reset(self) -> None:
        """Empty the delay line, zero the model, integrator and held command, clear the status."""
        for i in range(self._n):
            self._line[i] = 0.0
        self._head = 0
        self._ym_mmhg = 0.0
        self._integral_ml_h = 0.0
        self._last_command_ml_h = 0.0
        self._schedule: tuple[float, float, float] | None = None
        self._raw = INITIAL_SCHEDULE
        self._status = SmithStatus()

    @property
    def status(self) -> SmithStatus:
        """Flags of the last step and counts since reset."""
        return self._status

    def scheduled_rho(self) -> tuple[float, float, float]:
        """K (mmHg/(ml/h)), T (s) and τ (s) the last step used, after the clamp and the rate
        limit; NaN before the first step."""
        if self._schedule is None:
            return (math.nan, math.nan, math.nan)
        return self._schedule

    def _sanitise(self, K: float, T: float, tau: float) -> tuple[float, float, float, bool, bool]:
        """Hold non-finite values, clamp to the range, rate-limit against the previous tick."""
        # written out per parameter: this runs every tick
        raw_k, raw_t, raw_tau = self._raw
        if math.isfinite(K):
            raw_k = K
        if math.isfinite(T):
            raw_t = T
        if math.isfinite(tau):
            raw_tau = tau
        self._raw = (raw_k, raw_t, raw_tau)
        k = min(max(raw_k, K_RANGE[0]), K_RANGE[1])
        t_s = min(max(raw_t, T_RANGE_S[0]), T_RANGE_S[1])
        tau_s = min(max(raw_tau, 0.0), self.tau_max_s)
        was_clamped = k != raw_k or t_s != raw_t or tau_s != raw_tau
        was_limited = False
        if self._schedule is not None:
            (prev_k, prev_t, prev_tau), (dk, dt, dtau) = self._schedule, self._max_steps
            lim_k, lim_t, lim_tau = (
                _limit(k, prev_k, dk),
                _limit(t_s, prev_t, dt),
                _limit(tau_s, prev_tau, dtau),
            )
            was_limited = lim_k != k or lim_t != t_s or lim_tau != tau_s
            k, t_s, tau_s = lim_k, lim_t, lim_tau
        self._schedule = (k, t_s, tau_s)
        return k, t_s, tau_s, was_clamped, was_limited

    def _delayed_model(self, tau_s: float) -> float:
        """The model output τ ago (mmHg), linear interpolation between the two nearest ticks."""
        d = tau_s / self.sample_period_s
        lag = int(d)
        frac = d - lag
        if lag >= self._n - 1:  # only at τ = tau_max (a multiple of Ts): no fraction left
            lag, frac = self._n - 1, 0.0
        line, n, head = self._line, self._n, self._head
        newer = line[(head - lag) % n]
        if frac == 0.0:
            return newer
        return (1.0 - frac) * newer + frac * line[(head - lag - 1) % n]

    def step(self, map_mmhg: float, target_mmhg: float, K: float, T: float, tau: float) -> float:
        """Return the infusion command (ml/h) for this tick; see the module docstring."""
        k, t_s, tau_s, was_clamped, was_limited = self._sanitise(K, T, tau)
        self._head = (self._head + 1) % self._n
        self._line[self._head] = self._ym_mmhg
        error_mmhg = target_mmhg - (map_mmhg + self._ym_mmhg - self._delayed_model(tau_s))
        saturated = False
        if math.isfinite(error_mmhg):
            kc = t_s / (k * self.lambda_s)
            unclamped = kc * error_mmhg + self._integral_ml_h
            command = min(max(unclamped, 0.0), self.max_rate_ml_h)
            saturated = command != unclamped
            winding_up = (unclamped > self.max_rate_ml_h and error_mmhg > 0.0) or (
                unclamped < 0.0 and error_mmhg < 0.0
            )
            if not winding_up:
                # Kc/Ti = 1/(K·λ) with Ti = T
                self._integral_ml_h += self.sample_period_s * error_mmhg / (k * self.lambda_s)
            self._last_command_ml_h = command
        command = self._last_command_ml_h
        a = math.exp(-self.sample_period_s / t_s)
        self._ym_mmhg = a * self._ym_mmhg + (1.0 - a) * k * command
        st = self._status  # updated in place, as the generated modules do: no allocation per tick
        st.saturated = saturated
        st.rho_clamped = was_clamped
        st.rho_rate_limited = was_limited
        st.rho_clamped_count += was_clamped
        st.rho_rate_limited_count += was_limited
        return command
