"""The ``phenylephrine-2c`` patient model: label kinetics, effect site, Emax, counter-regulation.

Written from published equations, independently of the paper's model (:mod:`pressor.hil_sim.patients.patient`)
and of :mod:`pressor.hil_sim.patients.pkpd`. With the delivered rate R (ml/h) of a syringe at c µg/ml
(:data:`~pressor.contracts.controller.DESIGN_CONCENTRATION_UG_ML`), rate constants in 1/min::

    u(t)      = R(t − d) · c / 60                                   µg/min, after the line delay d
    dA1/dt    = u − (k10 + k12)·A1 + k21·A2                          central amount (µg)
    dA2/dt    = k12·A1 − k21·A2                                      peripheral amount (µg)
    C1        = A1 / V1                                              plasma level (ng/ml = µg/l)
    dCe/dt    = ke0 · (C1 − Ce)                                      effect site (ng/ml)
    E         = Emax · Ce / (EC50 + Ce)                              drug effect on MAP (mmHg)
    dF/dt     = (g · E − F) / τ_cr                                   counter-regulation (mmHg)
    MAP       = baseline + E − F

Sources and ranges (drawn per patient, :data:`RANGES`):

* **Kinetics.** The US label of phenylephrine hydrochloride injection (FDA NDA 203826) gives a
  two-compartment model for a 70 kg adult, re-analysing Hengstmann and Goronzy (Eur J Clin
  Pharmacol 1982): V1 20.4 l, k10 0.124, k12 0.155, k21 0.0314 per min, so CL = k10·V1 ≈ 2.5 l/min
  and half-lives ≈ 2.3 min and ≈ 53 min. Under a constant infusion the plasma level is then only
  ≈ 45 % of its steady state after 10 min and ≈ 72 % after 60 min (tested): the gain a controller
  sees keeps creeping for an hour. Here V1 scales with a body weight of 50-100 kg and k10, k12,
  k21 vary by ×/÷ 1.3, 1.2, 1.2 around the label (log-uniform): the label gives no spread, these
  are assumptions.
* **Effect site.** The link model of Sheiner et al. (Clin Pharmacol Ther 1979): Ce follows C1 with
  the rate ke0. ke0 ≈ 0.7 per min is the value open teaching simulators use; drawn in 0.35-1.0 per
  min, consistent with the label's onset within a minute and a peak within 1-2 min of a bolus.
* **Line delay.** d in 10-35 s: the dead space of the line and the venous transit, the delay range
  of the seed paper's group.
* **Emax.** The hyperbolic (Hill coefficient 1) concentration-effect curve; Emax 30-60 mmHg and
  EC50 30-80 ng/ml are assumptions chosen so that the apparent K below spans ≈ 0.06-1 mmHg/(ml/h)
  at low doses, an order of magnitude as published vasopressor PD models spread.
* **Counter-regulation.** A baroreflex-like turnover state takes back the fraction g of a sustained
  effect with the time constant τ_cr, the tolerance-like return of the vascular-resistance
  turnover model of Su et al. (Br J Anaesth 2023: k_out ≈ 0.072 per min, a return time of a
  sustained effect ≈ 8 min); τ_cr in 5-15 min, g in 0.1-0.4 (an assumption).
* **Baseline.** MAP without drug 45-60 mmHg, the hypotensive range of the paper model's cohort.

Steady state under a constant R: every level is Css = R·c / (60·k10·V1) ng/ml and
ΔMAP = (1 − g)·Emax·Css/(EC50 + Css) (:meth:`Phenylephrine2C.steady_state_delta_mmhg`).

As a :class:`~pressor.hil_sim.patients.patient_model.PatientModel`: K, T, τ are *apparent* values, K the MAP
rise one more ml/h gives once the plasma's fast mode settled (peripheral amount and counter-regulation
unmoved: the Emax curve from Ce to Ce + c/(60·V1·(k10 + k12))), T = 60/(k10 + k12) + 60/ke0 s (the
two fast time constants added), τ = d.

Integration on the internal step h: the linear part (A1, A2, Ce) uses its exact discretisation for
an input held over the step (the input being the exact mean of the delayed rate, as in
:mod:`pressor.hil_sim.patients.patient`), F the exact solution for an effect E that moves linearly over the
step.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import ClassVar

import numpy as np
from scipy.linalg import expm

from pressor.contracts.controller import DESIGN_CONCENTRATION_UG_ML
from pressor.hil_sim.patients.drug_patient import DrugPatient, draw_constants

#: the label's 70 kg two-compartment model (FDA NDA 203826): V1 (l), k10, k12, k21 (1/min)
LABEL_V1_L = 20.4
LABEL_K10_PER_MIN = 0.124
LABEL_K12_PER_MIN = 0.155
LABEL_K21_PER_MIN = 0.0314
LABEL_WEIGHT_KG = 70.0

#: per-patient constant -> (low, high) of its draw (units in the names; module docstring)
RANGES: dict[str, tuple[float, float]] = {
    "baseline_mmhg": (45.0, 60.0),
    "delay_s": (10.0, 35.0),
    "v1_l": (LABEL_V1_L * 50.0 / LABEL_WEIGHT_KG, LABEL_V1_L * 100.0 / LABEL_WEIGHT_KG),
    "k10_per_min": (LABEL_K10_PER_MIN / 1.3, LABEL_K10_PER_MIN * 1.3),
    "k12_per_min": (LABEL_K12_PER_MIN / 1.2, LABEL_K12_PER_MIN * 1.2),
    "k21_per_min": (LABEL_K21_PER_MIN / 1.2, LABEL_K21_PER_MIN * 1.2),
    "ke0_per_min": (0.35, 1.0),
    "emax_mmhg": (30.0, 60.0),
    "ec50_ng_ml": (30.0, 80.0),
    "counter_gain": (0.1, 0.4),
    "counter_tau_s": (300.0, 900.0),
}
#: the constants drawn log-uniformly (the rest uniformly)
LOG_UNIFORM = frozenset({"k10_per_min", "k12_per_min", "k21_per_min"})


@dataclass(frozen=True)
class PhenylephrineParams:
    """One patient's constants (units in the names, ranges in :data:`RANGES`)."""

    baseline_mmhg: float
    delay_s: float
    v1_l: float
    k10_per_min: float
    k12_per_min: float
    k21_per_min: float
    ke0_per_min: float
    emax_mmhg: float
    ec50_ng_ml: float
    counter_gain: float
    counter_tau_s: float

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if name == "counter_gain":
                ok, allowed = 0.0 <= value < 1.0, "[0, 1)"
            elif name == "delay_s":
                ok, allowed = 0.0 <= value < math.inf, "[0, inf) s"
            else:
                ok, allowed = 0.0 < value < math.inf, "(0, inf)"
            if not ok:
                raise ValueError(f"phenylephrine-2c {name}={value!r} outside {allowed}")

    @property
    def clearance_l_min(self) -> float:
        """Elimination clearance k10·V1 (l/min)."""
        return self.k10_per_min * self.v1_l


def draw_params(patient_seed: int) -> PhenylephrineParams:
    """The patient of ``patient_seed``: stream 0 of :func:`pressor.hil_sim.patients.cohort.patient_rng` draws
    the :data:`RANGES` in their order, uniformly, the rate constants log-uniformly."""
    return PhenylephrineParams(**draw_constants(patient_seed, RANGES, LOG_UNIFORM))


class Phenylephrine2C(DrugPatient):
    """The ``phenylephrine-2c`` patient (module docstring), stepped every ``step_s`` s.

    Parameters
    ----------
    params
        The patient's constants.
    step_s
        Internal step (s), in (0, 10] (the discretisation is exact, the step only sets the grid).

    Attributes
    ----------
    time_s, a1_ug, a2_ug, ce_ng_ml, counter_mmhg
        Time (s), central and peripheral amounts (µg), effect-site level (ng/ml), F (mmHg).
    """

    model_name = "phenylephrine-2c"
    coefficient_units: ClassVar[Mapping[str, str]] = {
        "baseline_mmhg": "mmHg",
        "delay_s": "s",
        "v1_l": "l",
        "k10_per_min": "1/min",
        "k12_per_min": "1/min",
        "k21_per_min": "1/min",
        "ke0_per_min": "1/min",
        "emax_mmhg": "mmHg",
        "ec50_ng_ml": "ng/ml",
        "counter_gain": "1",
        "counter_tau_s": "s",
    }

    def __init__(self, params: PhenylephrineParams, step_s: float) -> None:
        super().__init__(params, step_s, DESIGN_CONCENTRATION_UG_ML, params.counter_tau_s)
        p = params
        k10, k12, k21, ke0 = (
            x / 60.0 for x in (p.k10_per_min, p.k12_per_min, p.k21_per_min, p.ke0_per_min)
        )  # 1/s
        m = np.zeros((4, 4))
        m[:3, :3] = [[-(k10 + k12), k21, 0.0], [k12, -k21, 0.0], [ke0 / p.v1_l, 0.0, -ke0]]
        m[0, 3] = 1.0  # input in µg/s into A1
        e = expm(m * self.h)
        self._ad = tuple(tuple(float(v) for v in row[:3]) for row in e[:3])
        self._bd = tuple(float(v) for v in e[:3, 3])
        self._fast_dc_ng_ml = self.conc_ug_ml / (60.0 * p.v1_l * (p.k10_per_min + p.k12_per_min))
        self._t_app_s = 60.0 / (p.k10_per_min + p.k12_per_min) + 60.0 / p.ke0_per_min
        self.a1_ug = self.a2_ug = self.ce_ng_ml = 0.0

    @classmethod
    def from_seed(cls, patient_seed: int, step_s: float) -> Phenylephrine2C:
        """The patient of ``patient_seed`` (:func:`draw_params`) at the step ``step_s`` (s)."""
        return cls(draw_params(patient_seed), step_s)

    def effect_mmhg(self, ce_ng_ml: float) -> float:
        """The Emax curve: MAP rise (mmHg) at the effect-site level ``ce_ng_ml`` (ng/ml)."""
        p = self.params
        return p.emax_mmhg * ce_ng_ml / (p.ec50_ng_ml + ce_ng_ml) if ce_ng_ml > 0.0 else 0.0

    def step(self, rate_ml_h: float) -> None:
        """Advance one internal step with the pump delivering ``rate_ml_h`` (ml/h, mean)."""
        u_ug_s = self._delayed_rate_ml_h(rate_ml_h) * self.conc_ug_ml / 3600.0
        (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = self._ad
        b0, b1, b2 = self._bd
        x0, x1, x2 = self.a1_ug, self.a2_ug, self.ce_ng_ml
        e0 = self._effect_before_step()
        self.a1_ug = a00 * x0 + a01 * x1 + a02 * x2 + b0 * u_ug_s
        self.a2_ug = a10 * x0 + a11 * x1 + a12 * x2 + b1 * u_ug_s
        self.ce_ng_ml = a20 * x0 + a21 * x1 + a22 * x2 + b2 * u_ug_s
        self._regulate(e0, self.effect_mmhg(self.ce_ng_ml))

    @property
    def plasma_ng_ml(self) -> float:
        """Plasma level C1 = A1/V1 now (ng/ml)."""
        return self.a1_ug / self.params.v1_l

    @property
    def K(self) -> float:
        """Apparent sensitivity now (mmHg/(ml/h)): the fast MAP rise of one more ml/h."""
        ce = self.ce_ng_ml
        return self.effect_mmhg(ce + self._fast_dc_ng_ml) - self._effect_before_step()

    @property
    def T_s(self) -> float:
        """Apparent lag (s): 60/(k10 + k12) + 60/ke0."""
        return self._t_app_s

    def steady_state_delta_mmhg(self, rate_ml_h: float) -> float:
        """ΔMAP (mmHg) after an endless infusion at ``rate_ml_h`` (ml/h): (1 − g)·E(Css)."""
        p = self.params
        css = rate_ml_h * self.conc_ug_ml / (60.0 * p.clearance_l_min)
        return (1.0 - p.counter_gain) * self.effect_mmhg(css)
