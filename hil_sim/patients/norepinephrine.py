"""The ``norepinephrine`` patient model: one-compartment kinetics, effect site, Hill, feedback.

Written from published equations, independently of the other models. With the delivered rate R
(ml/h) of a syringe at c = :data:`CONCENTRATION_UG_ML` µg/ml (4 mg in 250 ml), rates in 1/min::

    u(t)   = R(t − d) · c / 60                          µg/min, d = line dead space + effect lag
    dC/dt  = (u + P_endo)/V − (CL/V) · C                plasma level (ng/ml = µg/l)
    dCe/dt = ke0 · (C − Ce)                             effect site (ng/ml)
    H(x)   = Emax · xⁿ / (EC50ⁿ + xⁿ)                   Hill curve (mmHg)
    E      = H(Ce) − H(C_endo),  C_endo = P_endo / CL   drug effect on MAP (mmHg)
    dF/dt  = k_cr · (g · E − F)                         counter-regulation (mmHg)
    MAP    = baseline + E − F

Sources and ranges (drawn per patient, :data:`RANGES`; "assumption" marks a spread the sources do
not give):

* **Kinetics** (Beloeil et al., Br J Anaesth 2005;95:782, septic and trauma patients): one
  compartment, V ≈ 8.8 l, clearance falling with severity from ≈ 3 l/min at SAPS II 20 to
  ≈ 0.9 l/min at SAPS II 60 (half-life 2 → 6.8 min). SAPS II is drawn in [20, 60] and
  CL = 3 · 0.3^((SAPS − 20)/40) l/min (log-linear between the two published points); V is drawn
  log-uniformly in 8.8 ×/÷ 1.25 l (assumption).
* **Endogenous production** (Li et al., Clin Pharmacokinet 2024, volunteers): ≈ 0.5 µg/min;
  drawn in 0.3-0.8 µg/min (assumption). The patient starts at the endogenous steady state.
* **Effect lag** (Joachim et al., Br J Clin Pharmacol 2024): ≈ 25 s, drawn in 15-35 s
  (assumption), a pure delay added to a line dead space of 5-20 s (assumption: a carrier-flushed
  central line). An effect site with 1/ke0 in 10-40 s (assumption, the circulation's mixing time)
  smooths the arrival.
* **Hill curve** (Joachim et al.): EC50 ≈ 15 nmol/l = 2.54 ng/ml (169.18 g/mol), drawn
  log-uniformly in 2.54 ×/÷ 3 ng/ml (the order-of-magnitude spread of published sensitivities);
  Hill exponent ≈ 1.5, drawn in 1.2-1.8 (assumption).
* **Counter-regulation** (Su et al., Br J Anaesth 2023, a turnover model of vascular resistance
  with feedback): k_out ≈ 0.072 per min and a feedback exponent γ ≈ 0.66, drawn in 0.05-0.10 per
  min and 0.4-0.9 (assumption). Linearised about baseline, a turnover dR/dt = k_out·((1 + S)·R^−γ
  − R) returns to its steady state with the rate k_cr = k_out·(1 + γ) (1/8.4 min at the typical
  values) and keeps the fraction 1/(1 + γ) of the stimulus: here g = γ/(1 + γ) of the direct
  effect is taken back with the rate k_cr.
* **Maximum effect** (Oualha et al., Br J Clin Pharmacol 2014;78:886, children): a net maximum
  MAP rise of ≈ 12-32 mmHg. The drawn constant is the net maximum Emax·(1 − g), in 20-50 mmHg
  (the upper end an assumption for adults, so that a +20 mmHg target is reachable for most of
  the cohort); the direct Emax is that divided by 1 − g.
* **Baseline.** MAP without drug 45-60 mmHg, the hypotensive range of the paper model's cohort.

Steady state under a constant R: C = Ce = Css = C_endo + R·c/(60·CL), ΔMAP = (1 − g)·E(Css)
(:meth:`Norepinephrine1C.steady_state_delta_mmhg`).

As a :class:`~pressor.hil_sim.patients.patient_model.PatientModel`: K, T, τ are *apparent*. K is the MAP rise
one more ml/h gives once the kinetics settled, counter-regulation unmoved (the Hill curve from Ce to
Ce + c/(60·CL)); T = 60·V/CL + 60/ke0 s (the two time constants added); τ = d.

Integration on the internal step h: (C, Ce) uses its exact discretisation for the input held over
the step (the exact mean of the delayed rate), F the exact solution for an E moving linearly over
the step.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import ClassVar

import numpy as np
from scipy.linalg import expm

from pressor.hil_sim.patients.drug_patient import DrugPatient, draw_constants

#: syringe concentration (µg/ml) the model's ml/h count: 4 mg in 250 ml (docs/DRUGS.md)
CONCENTRATION_UG_ML = 16.0
#: Beloeil et al. 2005: clearance (l/min) at SAPS II 20 and at SAPS II 60
CL_MILD_L_MIN = 3.0
CL_SEVERE_L_MIN = 0.9
SAPS_MILD, SAPS_SEVERE = 20.0, 60.0
#: Beloeil et al. 2005: volume of distribution (l)
V_TYPICAL_L = 8.8
#: Joachim et al. 2024: EC50 15 nmol/l at 169.18 g/mol (ng/ml)
EC50_TYPICAL_NG_ML = 15.0 * 0.16918

#: per-patient constant -> (low, high) of its draw (units in the names; module docstring)
RANGES: dict[str, tuple[float, float]] = {
    "baseline_mmhg": (45.0, 60.0),
    "line_delay_s": (5.0, 20.0),
    "effect_lag_s": (15.0, 35.0),
    "saps2": (SAPS_MILD, SAPS_SEVERE),
    "v_l": (V_TYPICAL_L / 1.25, V_TYPICAL_L * 1.25),
    "endogenous_ug_min": (0.3, 0.8),
    "effect_tau_s": (10.0, 40.0),
    "ec50_ng_ml": (EC50_TYPICAL_NG_ML / 3.0, EC50_TYPICAL_NG_ML * 3.0),
    "hill": (1.2, 1.8),
    "net_emax_mmhg": (20.0, 50.0),
    "k_out_per_min": (0.05, 0.10),
    "feedback_exponent": (0.4, 0.9),
}
#: the constants drawn log-uniformly (the rest uniformly)
LOG_UNIFORM = frozenset({"v_l", "ec50_ng_ml"})


@dataclass(frozen=True)
class NorepinephrineParams:
    """One patient's constants (units in the names, ranges in :data:`RANGES`)."""

    baseline_mmhg: float
    line_delay_s: float
    effect_lag_s: float
    saps2: float
    v_l: float
    endogenous_ug_min: float
    effect_tau_s: float
    ec50_ng_ml: float
    hill: float
    net_emax_mmhg: float
    k_out_per_min: float
    feedback_exponent: float

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if name in ("line_delay_s", "effect_lag_s", "endogenous_ug_min", "feedback_exponent"):
                ok, allowed = 0.0 <= value < math.inf, "[0, inf)"
            elif name == "saps2":
                ok, allowed = 0.0 <= value <= 163.0, "[0, 163] (the SAPS II scale)"
            else:
                ok, allowed = 0.0 < value < math.inf, "(0, inf)"
            if not ok:
                raise ValueError(f"norepinephrine {name}={value!r} outside {allowed}")

    @property
    def clearance_l_min(self) -> float:
        """Clearance (l/min), log-linear in SAPS II: Beloeil's 3 l/min (20) and 0.9 l/min (60)."""
        frac = (self.saps2 - SAPS_MILD) / (SAPS_SEVERE - SAPS_MILD)
        return CL_MILD_L_MIN * (CL_SEVERE_L_MIN / CL_MILD_L_MIN) ** frac

    @property
    def counter_gain(self) -> float:
        """g = γ/(1 + γ): the fraction of a sustained direct effect taken back."""
        return self.feedback_exponent / (1.0 + self.feedback_exponent)

    @property
    def counter_rate_per_min(self) -> float:
        """k_cr = k_out·(1 + γ) (1/min)."""
        return self.k_out_per_min * (1.0 + self.feedback_exponent)

    @property
    def emax_mmhg(self) -> float:
        """Direct maximum effect (mmHg): the net maximum divided by 1 − g."""
        return self.net_emax_mmhg / (1.0 - self.counter_gain)

    @property
    def delay_s(self) -> float:
        """Transport delay d = line dead space + effect lag (s)."""
        return self.line_delay_s + self.effect_lag_s

    @property
    def endogenous_ng_ml(self) -> float:
        """Endogenous steady plasma level P_endo/CL (ng/ml)."""
        return self.endogenous_ug_min / self.clearance_l_min


def draw_params(patient_seed: int) -> NorepinephrineParams:
    """The patient of ``patient_seed``: stream 0 of :func:`pressor.hil_sim.patients.cohort.patient_rng` draws
    the :data:`RANGES` in their order, uniformly, ``v_l`` and ``ec50_ng_ml`` log-uniformly."""
    return NorepinephrineParams(**draw_constants(patient_seed, RANGES, LOG_UNIFORM))


class Norepinephrine1C(DrugPatient):
    """The ``norepinephrine`` patient (module docstring), stepped every ``step_s`` s.

    Parameters
    ----------
    params
        The patient's constants.
    step_s
        Internal step (s), in (0, 10] (the discretisation is exact, the step only sets the grid).

    Attributes
    ----------
    time_s, plasma_ng_ml, ce_ng_ml, counter_mmhg
        Time (s), plasma and effect-site levels (ng/ml), F (mmHg).
    """

    model_name = "norepinephrine"
    coefficient_units: ClassVar[Mapping[str, str]] = {
        "baseline_mmhg": "mmHg",
        "line_delay_s": "s",
        "effect_lag_s": "s",
        "saps2": "1",
        "v_l": "l",
        "endogenous_ug_min": "ug/min",
        "effect_tau_s": "s",
        "ec50_ng_ml": "ng/ml",
        "hill": "1",
        "net_emax_mmhg": "mmHg",
        "k_out_per_min": "1/min",
        "feedback_exponent": "1",
    }

    def __init__(self, params: NorepinephrineParams, step_s: float) -> None:
        super().__init__(params, step_s, CONCENTRATION_UG_ML, 60.0 / params.counter_rate_per_min)
        p = params
        kel = p.clearance_l_min / p.v_l / 60.0  # 1/s
        ke0 = 1.0 / p.effect_tau_s  # 1/s
        m = np.zeros((3, 3))
        m[:2, :2] = [[-kel, 0.0], [ke0, -ke0]]
        m[0, 2] = 1.0 / p.v_l  # input in µg/s into C (µg/l per s)
        e = expm(m * self.h)
        self._ad = tuple(tuple(float(v) for v in row[:2]) for row in e[:2])
        self._bd = tuple(float(v) for v in e[:2, 2])
        self._dc_ng_ml = self.conc_ug_ml / (60.0 * p.clearance_l_min)
        self._t_app_s = 60.0 * p.v_l / p.clearance_l_min + p.effect_tau_s
        # the Hill curve's constants as plain floats: the curve is evaluated twice a tick, and
        # the parameters' derived properties (Emax through g) are chains of Python calls
        self._emax_mmhg, self._ec50_ng_ml, self._hill = p.emax_mmhg, p.ec50_ng_ml, p.hill
        #: H (mmHg) at the effect-site level the last step left (``None`` before the first), for K
        self._hill_now: float | None = None
        self._h_endo = self.hill_mmhg(p.endogenous_ng_ml)
        self.plasma_ng_ml = self.ce_ng_ml = p.endogenous_ng_ml

    @classmethod
    def from_seed(cls, patient_seed: int, step_s: float) -> Norepinephrine1C:
        """The patient of ``patient_seed`` (:func:`draw_params`) at the step ``step_s`` (s)."""
        return cls(draw_params(patient_seed), step_s)

    def hill_mmhg(self, level_ng_ml: float) -> float:
        """The Hill curve H (mmHg) at the level ``level_ng_ml`` (ng/ml)."""
        if level_ng_ml <= 0.0:
            return 0.0
        x = (level_ng_ml / self._ec50_ng_ml) ** self._hill
        return self._emax_mmhg * x / (1.0 + x)

    def effect_mmhg(self, ce_ng_ml: float) -> float:
        """Direct drug effect E (mmHg) at the effect-site level ``ce_ng_ml`` (ng/ml)."""
        return self.hill_mmhg(ce_ng_ml) - self._h_endo

    def step(self, rate_ml_h: float) -> None:
        """Advance one internal step with the pump delivering ``rate_ml_h`` (ml/h, mean)."""
        u_ug_s = (
            self._delayed_rate_ml_h(rate_ml_h) * self.conc_ug_ml / 3600.0
            + self.params.endogenous_ug_min / 60.0
        )
        (a00, a01), (a10, a11) = self._ad
        b0, b1 = self._bd
        x0, x1 = self.plasma_ng_ml, self.ce_ng_ml
        e0 = self._effect_before_step()
        self.plasma_ng_ml = a00 * x0 + a01 * x1 + b0 * u_ug_s
        self.ce_ng_ml = a10 * x0 + a11 * x1 + b1 * u_ug_s
        self._hill_now = h1 = self.hill_mmhg(self.ce_ng_ml)
        self._regulate(e0, h1 - self._h_endo)  # effect_mmhg(ce), its H kept for K

    @property
    def K(self) -> float:
        """Apparent sensitivity now (mmHg/(ml/h)): the settled MAP rise of one more ml/h."""
        ce = self.ce_ng_ml
        h_now = self.hill_mmhg(ce) if self._hill_now is None else self._hill_now
        return self.hill_mmhg(ce + self._dc_ng_ml) - h_now

    @property
    def T_s(self) -> float:
        """Apparent lag (s): 60·V/CL + 1/ke0."""
        return self._t_app_s

    def steady_state_delta_mmhg(self, rate_ml_h: float) -> float:
        """ΔMAP (mmHg) after an endless infusion at ``rate_ml_h`` (ml/h): (1 − g)·E(Css)."""
        p = self.params
        css = p.endogenous_ng_ml + rate_ml_h * self._dc_ng_ml
        return (1.0 - p.counter_gain) * self.effect_mmhg(css)
