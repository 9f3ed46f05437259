"""The paper's nonlinear MAP response to a vasopressor infusion (pure: no clock, no I/O, no RNG).

ΔMAP follows a first-order lag driven by the infusion delayed by a time-varying transport delay::

    T(t) dΔMAP/dt = −ΔMAP + K(t) · i(t − τ(t))            (mmHg; i in ml/h, K in mmHg/(ml/h))
    MAP = MAP_b + ΔMAP (+ disturbances, added by the world)

with the scheduling quantities driven by the (undelayed) pump rate i(t):

``K`` (mmHg/(ml/h))
    a_k dK/dt + K = k0 · exp(−k1 · i),  i in ml/h, t in s, a_k in s; K(0) = k0 (the paper's eq.).
``T`` (s)
    T = sat_[T_min, T_max](T_min + b_T · ∫₀ᵗ i dt),  i in ml/h, t in s.
    Deviation: the paper writes sat(b_T ∫ i dt), which starts at 0 and, with Table 1's b_T and these
    units, sits at T_min for well over an hour; offsetting by T_min lets T rise 15–45 s per hour at
    40 ml/h, inside [100, 200] s (tested).
``τ`` (s)
    y/ī = (b_τ1 s + 1)/(a_τ2 s² + a_τ1 s + 1) with s in 1/min and ī = i / 120 ml/h (dimensionless);
    τ = sat_[τ_min, τ_max](τ_min + 10 s · y) once infusion has started, τ_min before.
    Deviation: the printed third-order ODE integrates the infusion (an extra 1/s), which in ml/h and s
    passes 60 s within a second and then only sits on its saturation. Read without the integrator
    and with time in minutes it matches the paper's description ("a peak shortly after the drug
    injection, decaying afterwards"): the delay peaks 1.5–4.5 min after a rate step at 5–15× its
    final value and settles within ~30 min; a 60 ml/h start saturates at τ_max, a steady 40 ml/h
    gives ≈ 13 s. Ranges: T ∈ [100, 200] s, τ ∈ [10, 35] s (the paper's group's code).

Integration uses a fixed internal step h. The delay is an exact variable-delay buffer: it stores the
cumulative infusion U(t) = ∫ i dt on the h grid (piecewise linear, hence exact for an infusion that is
constant over each internal step) and the input over [t, t+h] is the mean of i over the source
interval [t − τ(t), t + h − τ(t + h)], interpolated, never rounded to the step. The lag, K and the τ
filter use their exact discretisations for an input held over the step.

A *frozen* patient (``FrozenParams``) keeps K, T, τ constant (the nominal-step scenario).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import ClassVar

import numpy as np
from scipy.linalg import expm

T_MIN_S = 100.0
T_MAX_S = 200.0
TAU_MIN_S = 10.0
TAU_MAX_S = 35.0
TAU_GAIN_S = 10.0  # s of delay per unit of normalised filter output
TAU_RATE_REF_ML_H = 120.0  # infusion normalisation of the τ filter
TAU_TIME_UNIT_S = 60.0  # the τ filter's time unit (min)


@dataclass(frozen=True)
class PatientParams:
    """One nonlinear patient: Table 1 coefficients and the baseline MAP.

    Attributes
    ----------
    a_k
        K time constant (s).
    k0
        Sensitivity at zero infusion (mmHg/(ml/h)).
    k1
        Desensitisation rate (1/(ml/h)).
    b_T
        Lag growth (s per (ml/h)·s of infusion).
    a_tau1, a_tau2, b_tau1
        τ filter coefficients (min, min², min).
    baseline_mmhg
        MAP without drug (mmHg).
    """

    a_k: float
    k0: float
    k1: float
    b_T: float
    a_tau1: float
    a_tau2: float
    b_tau1: float
    baseline_mmhg: float

    def to_dict(self) -> dict[str, float]:
        """The coefficients as a JSON-ready dict."""
        return {k: float(v) for k, v in asdict(self).items()}

    def max_delta_map_mmhg(self, max_rate_ml_h: float) -> float:
        """Largest steady-state ΔMAP (mmHg) any rate in [0, max] can hold: max_i k0·i·e^(−k1 i)."""
        i_best = min(max_rate_ml_h, 1.0 / self.k1)
        return self.k0 * i_best * math.exp(-self.k1 * i_best)


#: unit of every coefficient a trial record carries (``coefficients`` of PatientParams/FrozenParams)
COEFFICIENT_UNITS: dict[str, str] = {
    "a_k": "s",
    "k0": "mmHg/(ml/h)",
    "k1": "1/(ml/h)",
    "b_T": "s/((ml/h)·s)",
    "a_tau1": "min",
    "a_tau2": "min²",
    "b_tau1": "min",
    "baseline_mmhg": "mmHg",
    "K": "mmHg/(ml/h)",
    "T_s": "s",
    "tau_s": "s",
}


@dataclass(frozen=True)
class FrozenParams:
    """A linear time-invariant patient K e^(−τs)/(Ts + 1) (frozen nominal-step mode).

    Attributes
    ----------
    K
        Sensitivity (mmHg/(ml/h)).
    T_s
        Lag (s).
    tau_s
        Transport delay (s), not saturated.
    baseline_mmhg
        MAP without drug (mmHg).
    """

    K: float
    T_s: float
    tau_s: float
    baseline_mmhg: float

    def to_dict(self) -> dict[str, float]:
        """The parameters as a JSON-ready dict."""
        return {k: float(v) for k, v in asdict(self).items()}

    def max_delta_map_mmhg(self, max_rate_ml_h: float) -> float:
        """Largest steady-state ΔMAP (mmHg): K·max."""
        return self.K * max_rate_ml_h


class VariableDelayBuffer:
    """Exact variable transport delay of a piecewise-constant input on a fixed step.

    Stores the cumulative input U(t_j) = ∫₀^{t_j} u dt at the grid points t_j = j·h in a ring of
    ceil(max_delay/h) + 3 entries; U is linear between grid points when u is constant over each step,
    so interpolating U is exact. ``u(s) = 0`` for s < 0.

    Parameters
    ----------
    step_s
        Grid step h (s).
    max_delay_s
        Largest delay (s) that will be asked for.
    """

    def __init__(self, step_s: float, max_delay_s: float) -> None:
        if step_s <= 0.0 or max_delay_s < 0.0:
            raise ValueError(f"step_s={step_s!r} must be > 0 and max_delay_s={max_delay_s!r} >= 0")
        self.h = float(step_s)
        self.size = int(math.ceil(max_delay_s / step_s)) + 3
        self._ring = [0.0] * self.size
        self.n = 0  # number of completed steps; U(t_n) is the newest entry
        self._total = 0.0

    def push(self, mean_input: float) -> None:
        """Append one step of input (its mean over the step)."""
        self._total += mean_input * self.h
        self.n += 1
        self._ring[self.n % self.size] = self._total

    def cumulative_at(self, time_s: float) -> float:
        """U(time_s) by interpolation; time_s must lie within the stored window."""
        x = time_s / self.h
        if x <= 0.0:
            return 0.0
        j = int(x)
        if j >= self.n:
            return self._total
        if self.n - j > self.size - 1:
            raise ValueError(f"delay beyond buffer: t={time_s} s, now={self.n * self.h} s")
        frac = x - j
        ring, size = self._ring, self.size
        u0 = ring[j % size]
        return u0 + frac * (ring[(j + 1) % size] - u0)

    def delayed_mean(self, delay_start_s: float, delay_end_s: float) -> float:
        """Mean of u(s − τ(s)) over the step just pushed, τ going linearly from start to end values.

        The step is [t_{n−1}, t_n]; the source interval is [t_{n−1} − τ0, t_n − τ1].
        """
        t_end = self.n * self.h
        a = t_end - self.h - delay_start_s
        b = t_end - delay_end_s
        width = b - a
        if width > 1e-9 * self.h:
            return (self.cumulative_at(b) - self.cumulative_at(a)) / width
        # Source interval degenerate (τ growing at 1 s/s or more): the right-continuous point value
        # of u at its middle (U is piecewise linear, so a tiny forward difference is exact).
        m = 0.5 * (a + b)
        eps = 1e-6 * self.h
        return (self.cumulative_at(m + eps) - self.cumulative_at(m)) / eps


def _tau_filter(p: PatientParams, h: float) -> tuple[tuple[float, ...], tuple[float, float]]:
    """Exact ZOH discretisation of the τ filter (controllable canonical form) for step h (s)."""
    hm = h / TAU_TIME_UNIT_S
    a = np.array([[0.0, 1.0], [-1.0 / p.a_tau2, -p.a_tau1 / p.a_tau2]])
    b = np.array([[0.0], [1.0 / p.a_tau2]])
    m = np.zeros((3, 3))
    m[:2, :2] = a * hm
    m[:2, 2:] = b * hm
    e = expm(m)
    ad, bd = e[:2, :2], e[:2, 2]
    # Python floats, not numpy scalars: the same IEEE doubles, but numpy scalar arithmetic is several
    # times slower and these would otherwise spread into τ, ΔMAP and every MAP reading each step.
    return (
        (float(ad[0, 0]), float(ad[0, 1]), float(ad[1, 0]), float(ad[1, 1])),
        (float(bd[0]), float(bd[1])),
    )


class Patient:
    """Nonlinear (or frozen) patient integrated on a fixed internal step: the ``paper`` model.

    Satisfies :class:`pressor.hil_sim.patients.patient_model.PatientModel` with its true K, T, τ; ``from_seed``
    draws the nonlinear Table 1 patient (:func:`pressor.hil_sim.patients.cohort.draw_patient`).

    Parameters
    ----------
    params
        :class:`PatientParams` (nonlinear) or :class:`FrozenParams` (LTI).
    step_s
        Internal step h (s), in (0, 1].

    Attributes
    ----------
    time_s, delta_map_mmhg, K, T_s, tau_s, infused_ml_h_s
        Current state: time (s), ΔMAP (mmHg), sensitivity, lag (s), delay (s), ∫ i dt ((ml/h)·s).
    """

    #: unit of every coefficient :meth:`coefficients` returns (both parameter kinds)
    coefficient_units: ClassVar[Mapping[str, str]] = COEFFICIENT_UNITS

    def __init__(self, params: PatientParams | FrozenParams, step_s: float = 0.1) -> None:
        if not 0.0 < step_s <= 1.0:
            raise ValueError(f"patient step_s={step_s!r} outside (0, 1] s")
        self.params = params
        self.h = float(step_s)
        self.frozen = isinstance(params, FrozenParams)
        self.time_s = 0.0
        self.delta_map_mmhg = 0.0
        self.infused_ml_h_s = 0.0
        if isinstance(params, FrozenParams):
            if params.K <= 0 or params.T_s <= 0 or params.tau_s < 0:
                raise ValueError(f"frozen patient needs K>0, T>0, tau>=0, got {params}")
            self.K, self.T_s, self.tau_s = params.K, params.T_s, params.tau_s
            self._buffer = VariableDelayBuffer(self.h, params.tau_s)
            self._lag_decay = math.exp(-self.h / params.T_s)
        else:
            self.K = params.k0
            self.T_s = T_MIN_S
            self.tau_s = TAU_MIN_S
            self._buffer = VariableDelayBuffer(self.h, TAU_MAX_S)
            self._k_decay = math.exp(-self.h / params.a_k)
            self._ad, self._bd = _tau_filter(params, self.h)
            self._x1 = 0.0
            self._x2 = 0.0
            self._started = False

    def step(self, rate_ml_h: float) -> None:
        """Advance one internal step with the pump delivering ``rate_ml_h`` (mean over the step)."""
        buf, h = self._buffer, self.h
        buf.push(rate_ml_h)
        self.infused_ml_h_s += rate_ml_h * h
        self.time_s = buf.n * h
        if self.frozen:
            u = buf.delayed_mean(self.tau_s, self.tau_s)
            d = self._lag_decay
            self.delta_map_mmhg = d * self.delta_map_mmhg + (1.0 - d) * self.K * u
            return
        p: PatientParams = self.params  # type: ignore[assignment]
        tau0 = self.tau_s
        # τ filter (input held over the step), then τ at the step's end.
        inp = rate_ml_h / TAU_RATE_REF_ML_H
        a00, a01, a10, a11 = self._ad
        b0, b1 = self._bd
        x1, x2 = self._x1, self._x2
        x1_new = a00 * x1 + a01 * x2 + b0 * inp
        x2_new = a10 * x1 + a11 * x2 + b1 * inp
        self._x1, self._x2 = x1_new, x2_new
        if rate_ml_h > 0.0:
            self._started = True
        if self._started:
            y = x1_new + p.b_tau1 * x2_new
            tau1 = min(max(TAU_MIN_S + TAU_GAIN_S * y, TAU_MIN_S), TAU_MAX_S)
        else:
            tau1 = TAU_MIN_S
        u = buf.delayed_mean(tau0, tau1)
        # Lag with K, T held at their start-of-step values (exact for held parameters).
        K = self.K
        d = math.exp(-h / self.T_s)
        self.delta_map_mmhg = d * self.delta_map_mmhg + (1.0 - d) * K * u
        kd = self._k_decay
        self.K = kd * K + (1.0 - kd) * p.k0 * math.exp(-p.k1 * rate_ml_h)
        self.T_s = min(max(T_MIN_S + p.b_T * self.infused_ml_h_s, T_MIN_S), T_MAX_S)
        self.tau_s = tau1

    @property
    def map_mmhg(self) -> float:
        """MAP without disturbances (mmHg): baseline + ΔMAP."""
        return self.params.baseline_mmhg + self.delta_map_mmhg

    @property
    def baseline_mmhg(self) -> float:
        """MAP without drug (mmHg)."""
        return self.params.baseline_mmhg

    @classmethod
    def from_seed(cls, patient_seed: int, step_s: float) -> Patient:
        """The nonlinear patient of ``patient_seed`` (:func:`pressor.hil_sim.patients.cohort.draw_patient`)."""
        from pressor.hil_sim.patients.cohort import draw_patient  # cohort imports this module

        return cls(draw_patient(patient_seed), step_s)

    def coefficients(self) -> dict[str, float]:
        """The parameters, JSON-ready (``PatientParams`` or ``FrozenParams`` fields)."""
        return self.params.to_dict()

    def max_delta_map_mmhg(self, max_rate_ml_h: float) -> float:
        """Largest steady-state ΔMAP (mmHg) any rate in [0, ``max_rate_ml_h``] (ml/h) holds."""
        return self.params.max_delta_map_mmhg(max_rate_ml_h)
