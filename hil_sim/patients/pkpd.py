"""The ``pkpd`` patient model: two compartments, effect site, sigmoid Emax, tachyphylaxis.

Written for ``benchmarks/independent_patients.py`` independently of the paper's model
(:mod:`pressor.hil_sim.patients.patient`), and played in ``pressor trial``/``sil``/``device`` as
``--patient-model pkpd`` through :class:`PkpdPatient` (the scenario's disturbances then replace the
model's own). The model is the usual pharmacometric chain for a vasopressor infusion, each block in
the form the literature uses (the numbers are ranges drawn per patient, listed in :data:`RANGES`):

* **Transport delay.** The drug reaches the circulation ``delay_s`` after it leaves the pump
  (dead space of the line and the venous transit): a pure delay on the infusion rate.
* **Two-compartment pharmacokinetics.** A central (plasma) volume ``v1_l`` with elimination
  clearance ``cl_l_min`` exchanges drug with a peripheral volume ``v2_l`` through the
  inter-compartmental clearance ``q_l_min``. Phenylephrine's intravenous kinetics are described
  this way (Hengstmann and Goronzy, Eur J Clin Pharmacol 1982: a distribution half-life of minutes,
  an elimination half-life of hours, a clearance near 2 l/min); so after a rate change the plasma
  level moves fast to a fraction CL/(CL+Q) of its final value, then creeps for hours.
* **Effect compartment.** The effect site follows plasma with the first-order equilibration time
  ``effect_lag_s`` = 1/ke0 (the Sheiner et al. 1979 link model), the lag between plasma level and
  pressure.
* **Sigmoid Emax pharmacodynamics.** The MAP rise is Emax·Ce^h / (EC50^h + Ce^h) over the
  patient's baseline (the Hill equation used for vasopressor dose-response), so the sensitivity
  depends on the operating point: weak at low levels, strongest near EC50, saturating above.
* **Tachyphylaxis.** A tolerance state follows the effect-site level with the time constant
  ``tolerance_tau_s`` and raises the potency: EC50_eff = EC50 + ``tolerance_gain``·Tol (the
  exposure-driven tolerance compartment of Porchet, Benowitz and Sheiner 1988). Under a steady
  infusion the sensitivity so drifts down over tens of minutes.
* **Disturbances on MAP (additive).** A haemorrhage-like drop of ``hemorrhage_mmhg`` that ramps in
  over ``hemorrhage_ramp_s`` from :data:`HEMORRHAGE_AT_S` and stays, and a fluid-bolus-like rise of
  ``bolus_mmhg`` over ``bolus_rise_s`` from :data:`BOLUS_AT_S` that decays with ``bolus_decay_s``.

Units: concentrations in ng/ml (= µg/l), volumes in l, clearances in l/min, times in s, MAP in
mmHg, infusion rates in ml/h of a syringe at ``concentration_ug_ml`` µg/ml. At steady state under a
rate R (ml/h) every concentration equals Css = R·c / (60·CL) ng/ml and the MAP is
``baseline + Emax·Css^h / ((EC50 + g·Css)^h + Css^h)``
(:meth:`IndependentPatient.steady_state_map_mmhg`).
The ranges put the local sensitivity near the target between about 0.1 and 1 mmHg/(ml/h) for
phenylephrine at 100 µg/ml, near the range the runtime's controllers are designed for; they are a
plausible population for a benchmark, not fitted values. Unlike the controllers' design model
(first order plus delay) the response is of higher order: the plasma's fast time constant
V1/(CL+Q) is 1.7-6 min, the effect-site lag 0.5-1.5 min comes after it, and the peripheral creep
and the tolerance keep moving the sensitivity for the whole hour.

As a :class:`~pressor.hil_sim.patients.patient_model.PatientModel` (:class:`PkpdPatient`) the syringe holds
:data:`~pressor.contracts.controller.DESIGN_CONCENTRATION_UG_ML` µg/ml, the patient of ``patient_seed`` is
``draw_patient(patient_seed // 1_000_000, patient_seed % 1_000_000)`` (so the trial's cohort
``(S, n)`` is the benchmark's cohort ``(S, n)``), and K, T, τ are *apparent* values: K the MAP rise
one more ml/h gives once the plasma's fast mode settled (peripheral level and tolerance unmoved:
Emax curve from Ce to Ce + c/(60·(CL + Q))), T = 60·V1/(CL + Q) + ``effect_lag_s`` (the two fast
time constants added), τ the transport delay on the step grid.
"""

from __future__ import annotations

import math
import random
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import ClassVar

from pressor.contracts.controller import DESIGN_CONCENTRATION_UG_ML

#: when the haemorrhage-like drop starts (s after the run's start)
HEMORRHAGE_AT_S = 1200.0
#: when the fluid-bolus-like rise starts (s after the run's start)
BOLUS_AT_S = 2400.0

#: per-patient parameter -> (low, high), drawn uniformly (units in the field names)
RANGES: dict[str, tuple[float, float]] = {
    "baseline_mmhg": (50.0, 60.0),
    "delay_s": (15.0, 45.0),
    "cl_l_min": (1.8, 2.8),
    "v1_l": (8.0, 16.0),
    "q_l_min": (0.8, 2.0),
    "v2_l": (150.0, 350.0),
    "effect_lag_s": (30.0, 90.0),
    "emax_mmhg": (45.0, 75.0),
    "ec50_ng_ml": (15.0, 35.0),
    "hill": (1.0, 1.8),
    "tolerance_tau_s": (1200.0, 3600.0),
    "tolerance_gain": (0.1, 0.4),
    "hemorrhage_mmhg": (8.0, 14.0),
    "hemorrhage_ramp_s": (30.0, 120.0),
    "bolus_mmhg": (6.0, 10.0),
    "bolus_rise_s": (60.0, 120.0),
    "bolus_decay_s": (480.0, 900.0),
}

#: the one-compartment variant (``draw_patient(..., model="one-compartment")``): no peripheral
#: compartment (Q = 0), no tolerance, a Hill effect and a wider spread of kinetics and potency
ONE_COMPARTMENT_RANGES: dict[str, tuple[float, float]] = RANGES | {
    "delay_s": (10.0, 60.0),
    "cl_l_min": (1.5, 4.0),
    "v1_l": (4.0, 12.0),
    "q_l_min": (0.0, 0.0),
    "effect_lag_s": (20.0, 90.0),
    "emax_mmhg": (40.0, 100.0),
    "ec50_ng_ml": (15.0, 80.0),
    "hill": (1.0, 2.5),
    "tolerance_gain": (0.0, 0.0),
}
#: the models :func:`draw_patient` draws from
MODELS = {"two-compartment": RANGES, "one-compartment": ONE_COMPARTMENT_RANGES}


@dataclass(frozen=True)
class PatientParams:
    """One patient's constants (units in the names; ranges in :data:`RANGES`)."""

    baseline_mmhg: float
    delay_s: float
    cl_l_min: float
    v1_l: float
    q_l_min: float
    v2_l: float
    effect_lag_s: float
    emax_mmhg: float
    ec50_ng_ml: float
    hill: float
    tolerance_tau_s: float
    tolerance_gain: float
    hemorrhage_mmhg: float
    hemorrhage_ramp_s: float
    bolus_mmhg: float
    bolus_rise_s: float
    bolus_decay_s: float


def draw_patient(seed: int, index: int, model: str = "two-compartment") -> PatientParams:
    """Patient ``index`` of the cohort ``seed``: every parameter uniform in its range of
    :data:`MODELS` [``model``] (:data:`RANGES` for the default two-compartment model).

    The draw depends on ``(seed, index, model)`` only, so a patient is the same in any cohort size
    (and the two-compartment draws are those of the model's first version).
    """
    if model not in MODELS:
        raise ValueError(f"model={model!r} not one of {tuple(MODELS)}")
    ranges = MODELS[model]
    tag = "" if model == "two-compartment" else f"{model}:"
    rng = random.Random(f"independent-patient:{tag}{seed}:{index}")
    return PatientParams(**{f.name: rng.uniform(*ranges[f.name]) for f in fields(PatientParams)})


class IndependentPatient:
    """The patient of the module docstring, advanced one sample period per :meth:`step`.

    Parameters
    ----------
    params
        The patient's constants.
    sample_period_s
        The step (s); the delay line holds ``round(delay_s / sample_period_s)`` periods.
    concentration_ug_ml
        The syringe's drug concentration (µg/ml).
    disturbances
        False: no haemorrhage and no bolus (the bare pharmacology).
    """

    def __init__(
        self,
        params: PatientParams,
        sample_period_s: float,
        concentration_ug_ml: float,
        disturbances: bool = True,
    ):
        self.p, self.ts_s, self.conc_ug_ml = params, sample_period_s, concentration_ug_ml
        self.disturbances = disturbances
        self.pipe = deque([0.0] * max(1, round(params.delay_s / sample_period_s)))
        self.a1_ug = self.a2_ug = 0.0  # drug amounts, central and peripheral (µg)
        self.ce_ng_ml = self.tol_ng_ml = 0.0  # effect-site level and tolerance state (ng/ml)
        self.t_s = 0.0

    def disturbance_mmhg(self, t_s: float) -> float:
        """The additive haemorrhage + bolus MAP disturbance at time ``t_s`` (mmHg)."""
        if not self.disturbances:
            return 0.0
        p, out = self.p, 0.0
        if t_s > HEMORRHAGE_AT_S:
            out -= p.hemorrhage_mmhg * min(1.0, (t_s - HEMORRHAGE_AT_S) / p.hemorrhage_ramp_s)
        dt = t_s - BOLUS_AT_S
        if dt > 0.0:
            rise = min(1.0, dt / p.bolus_rise_s)
            out += p.bolus_mmhg * rise * math.exp(-max(0.0, dt - p.bolus_rise_s) / p.bolus_decay_s)
        return out

    def effect_mmhg(self, ce_ng_ml: float, tol_ng_ml: float) -> float:
        """The sigmoid Emax MAP rise (mmHg) at effect-site level ``ce`` and tolerance ``tol``."""
        p = self.p
        if ce_ng_ml <= 0.0:
            return 0.0
        ec50 = p.ec50_ng_ml + p.tolerance_gain * tol_ng_ml
        x = (ce_ng_ml / ec50) ** p.hill
        return p.emax_mmhg * x / (1.0 + x)

    @property
    def map_mmhg(self) -> float:
        """True MAP now (mmHg)."""
        rise = self.effect_mmhg(self.ce_ng_ml, self.tol_ng_ml)
        return self.p.baseline_mmhg + rise + self.disturbance_mmhg(self.t_s)

    def step(self, rate_ml_h: float) -> None:
        """Advance one sample period with the pump delivering ``rate_ml_h`` (ml/h).

        Explicit Euler at the sample period: every time constant of the model is at least 100
        sample periods, so the error is far below the monitor's resolution.
        """
        p, h = self.p, self.ts_s
        self.pipe.append(rate_ml_h)
        in_ug_s = self.pipe.popleft() * self.conc_ug_ml / 3600.0
        c1, c2 = self.a1_ug / p.v1_l, self.a2_ug / p.v2_l  # ng/ml
        transfer_ug_s = p.q_l_min / 60.0 * (c1 - c2)
        self.a1_ug += h * (in_ug_s - p.cl_l_min / 60.0 * c1 - transfer_ug_s)
        self.a2_ug += h * transfer_ug_s
        self.tol_ng_ml += h * (self.ce_ng_ml - self.tol_ng_ml) / p.tolerance_tau_s
        self.ce_ng_ml += h * (c1 - self.ce_ng_ml) / p.effect_lag_s
        self.t_s += h

    def steady_state_map_mmhg(self, rate_ml_h: float) -> float:
        """MAP (mmHg) after an infinitely long infusion at ``rate_ml_h``, without disturbances.

        Every concentration is then Css = R·c / (60·CL) ng/ml, the tolerance too.
        """
        css = rate_ml_h * self.conc_ug_ml / (60.0 * self.p.cl_l_min)
        return self.p.baseline_mmhg + self.effect_mmhg(css, css)

    def steady_state_rate_ml_h(self, map_mmhg: float, max_rate_ml_h: float) -> float | None:
        """The steady infusion (ml/h) that holds ``map_mmhg``; None above what ``max_rate_ml_h``
        reaches. Bisection on the monotone :meth:`steady_state_map_mmhg`."""
        if map_mmhg <= self.p.baseline_mmhg:
            return 0.0
        if self.steady_state_map_mmhg(max_rate_ml_h) < map_mmhg:
            return None
        lo, hi = 0.0, max_rate_ml_h
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.steady_state_map_mmhg(mid) < map_mmhg else (lo, mid)
        return 0.5 * (lo + hi)

    def fast_gain_mmhg_per_ml_h(self, rate_ml_h: float) -> float:
        """Local sensitivity (mmHg per ml/h) around ``rate_ml_h`` a few minutes after a change.

        The peripheral compartment and the tolerance have not moved yet (they stay at the
        steady state of ``rate_ml_h``), the plasma has: ∂C1/∂R = c / (60·(CL + Q)).
        """
        p = self.p
        css = rate_ml_h * self.conc_ug_ml / (60.0 * p.cl_l_min)
        dc = self.conc_ug_ml / (60.0 * (p.cl_l_min + p.q_l_min))
        return self.effect_mmhg(css + dc, css) - self.effect_mmhg(css, css)  # per 1 ml/h


#: the constants a :class:`PkpdPatient` acts on (its disturbance constants are not used)
PHARMACOLOGY = (
    "baseline_mmhg",
    "delay_s",
    "cl_l_min",
    "v1_l",
    "q_l_min",
    "v2_l",
    "effect_lag_s",
    "emax_mmhg",
    "ec50_ng_ml",
    "hill",
    "tolerance_tau_s",
    "tolerance_gain",
)


class PkpdPatient(IndependentPatient):
    """The ``pkpd`` :class:`~pressor.hil_sim.patients.patient_model.PatientModel`: this module's patient,
    without its own disturbances, on a 100 µg/ml syringe (module docstring: seeds, apparent K, T, τ).

    Parameters
    ----------
    params
        The patient's constants.
    step_s
        Internal step (s), in (0, 1] (explicit Euler; every time constant is at least 30 s).
    """

    coefficient_units: ClassVar[Mapping[str, str]] = {
        "baseline_mmhg": "mmHg",
        "delay_s": "s",
        "cl_l_min": "l/min",
        "v1_l": "l",
        "q_l_min": "l/min",
        "v2_l": "l",
        "effect_lag_s": "s",
        "emax_mmhg": "mmHg",
        "ec50_ng_ml": "ng/ml",
        "hill": "1",
        "tolerance_tau_s": "s",
        "tolerance_gain": "1",
    }

    #: µg/ml of the model's drug (phenylephrine) each ml/h carries
    SYRINGE_UG_ML: ClassVar[float] = DESIGN_CONCENTRATION_UG_ML
    #: the :func:`draw_patient` model of :meth:`from_seed`
    COHORT: ClassVar[str] = "two-compartment"

    def __init__(self, params: PatientParams, step_s: float) -> None:
        if not 0.0 < step_s <= 1.0:
            raise ValueError(f"pkpd patient step_s={step_s!r} outside (0, 1] s")
        super().__init__(params, step_s, self.SYRINGE_UG_ML, disturbances=False)
        p = params
        self._fast_dc_ng_ml = self.conc_ug_ml / (60.0 * (p.cl_l_min + p.q_l_min))
        self._t_app_s = 60.0 * p.v1_l / (p.cl_l_min + p.q_l_min) + p.effect_lag_s
        self._tau_s = len(self.pipe) * step_s

    @classmethod
    def from_seed(cls, patient_seed: int, step_s: float) -> PkpdPatient:
        """Patient ``patient_seed % 1_000_000`` of the benchmark's cohort ``patient_seed //
        1_000_000`` (:func:`draw_patient` of :attr:`COHORT`)."""
        seed, index = divmod(int(patient_seed), 1_000_000)
        return cls(draw_patient(seed, index, cls.COHORT), step_s)

    @property
    def baseline_mmhg(self) -> float:
        """MAP without drug (mmHg)."""
        return self.p.baseline_mmhg

    @property
    def delta_map_mmhg(self) -> float:
        """The drug's MAP rise now (mmHg)."""
        return self.effect_mmhg(self.ce_ng_ml, self.tol_ng_ml)

    @property
    def K(self) -> float:
        """Apparent sensitivity now (mmHg/(ml/h)): the fast MAP rise of one more ml/h."""
        ce, tol = self.ce_ng_ml, self.tol_ng_ml
        return self.effect_mmhg(ce + self._fast_dc_ng_ml, tol) - self.effect_mmhg(ce, tol)

    @property
    def T_s(self) -> float:
        """Apparent lag (s): 60·V1/(CL + Q) + effect_lag_s."""
        return self._t_app_s

    @property
    def tau_s(self) -> float:
        """Transport delay (s), a whole number of internal steps."""
        return self._tau_s

    def coefficients(self) -> dict[str, float]:
        """The constants the model acts on (:data:`PHARMACOLOGY`), JSON-ready."""
        return {name: float(getattr(self.p, name)) for name in PHARMACOLOGY}

    def max_delta_map_mmhg(self, max_rate_ml_h: float) -> float:
        """Steady-state ΔMAP (mmHg) at ``max_rate_ml_h`` (ml/h): the steady state rises with the
        rate, so the largest over [0, max]."""
        return self.steady_state_map_mmhg(max_rate_ml_h) - self.p.baseline_mmhg
