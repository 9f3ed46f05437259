"""Who the sensitivity sweep runs with which syringe (:mod:`benchmarks.sensitivity_sweep`).

Each patient model is played with its drug (:data:`MODEL_DRUG`) and that drug's entry in the drug
library: the standard syringe (the library's first concentration), the stronger one a clinician
switches to when the standard cannot reach the target (:func:`syringes`), and the limits the
supervisor enforces at each. :func:`reach_plan` sorts a level's patients before anything runs:
those the standard syringe holds at the target, those only the stronger one does, and the
non-responders no syringe of the library holds there for the hour within the dose limits (a
simulated hour at the best rate those limits allow, :mod:`pressor.hil_sim.reach`).

A patient model counts ml/h of one syringe (:data:`MODEL_CONCENTRATION_UG_ML`); a syringe c times
stronger is the same patient at c times the sensitivity
(:func:`pressor.hil_sim.patients.sensitivity.with_sensitivity`), so a level f with a syringe of concentration
c is the model at f·c/c_model.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

from pressor.contracts.controller import DESIGN_CONCENTRATION_UG_ML
from pressor.hil_sim.patients.norepinephrine import CONCENTRATION_UG_ML as NOREPINEPHRINE_UG_ML
from pressor.hil_sim.patients.sensitivity import with_sensitivity
from pressor.hil_sim.reach import hold_shortfall_mmhg
from pressor.hil_sim.scenarios.scenario import Scenario
from pressor.hil_sim.world import World
from pressor.plumbing.parallel import run_ordered
from pressor.runtime.core.dose_guard import DoseLimits
from pressor.runtime.inputs.drug_library import DrugEntry

#: the drug each patient model is a patient of
MODEL_DRUG = {
    "paper": "phenylephrine",
    "pkpd": "phenylephrine",
    "phenylephrine-2c": "phenylephrine",
    "norepinephrine": "norepinephrine",
}
#: the syringe (µg/ml) whose ml/h each drug's patient models count (docs/PATIENTS.md)
MODEL_CONCENTRATION_UG_ML = {
    "phenylephrine": DESIGN_CONCENTRATION_UG_ML,
    "norepinephrine": NOREPINEPHRINE_UG_ML,
}
#: each drug's shipped LPV design, what ``lpv`` in ``--controllers`` runs on its models
DRUG_LPV = {"phenylephrine": "lpv", "norepinephrine": "lpv:norepinephrine"}
#: the weight (kg) per-kg dose limits are converted at: the models draw no weight, and 70 kg is
#: the reference adult of the dosing literature (docs/DRUGS.md)
REFERENCE_WEIGHT_KG = 70.0
#: the loop period (s) the plan's worlds are built at, ``pressor trial``'s
SAMPLE_PERIOD_S = 0.1


@dataclass(frozen=True)
class Syringe:
    """One syringe of a drug and the limits the supervisor enforces with it.

    Attributes
    ----------
    concentration_ug_ml
        The syringe (µg/ml).
    model_concentration_ug_ml
        The syringe whose ml/h the drug's patient models count (µg/ml).
    limits
        The library's limits in ml/h at this syringe (:class:`DoseLimits`).
    max_rate_ml_h
        The largest rate the loop can hold through the scenario's hour (ml/h): the smallest of the
        pump's maximum, the hard dose limit, the soft one (the supervisor cuts to it: nobody
        confirms doses above it here) and the hourly maximum spread over the hour. A patient who
        needs more cannot be held at the target by any controller within the library's limits.
    """

    concentration_ug_ml: float
    model_concentration_ug_ml: float
    limits: DoseLimits
    max_rate_ml_h: float

    @property
    def dir_name(self) -> str:
        """``100ug_ml``: the syringe's directory under a cohort's."""
        return f"{self.concentration_ug_ml:g}ug_ml"

    @property
    def max_dose_ug_min(self) -> float:
        """The largest dose rate (µg/min) the loop can give with this syringe."""
        return self.max_rate_ml_h * self.concentration_ug_ml / 60.0

    def patient_model(self, model: str, level: float) -> str:
        """The patient-model spec of ``model`` at sensitivity ``level`` fed from this syringe.

        Raises
        ------
        pressor.hil_sim.patients.patient_model.PatientModelError
            ``level`` × the syringe's strength outside the sensitivity range.
        """
        return with_sensitivity(
            model, level * self.concentration_ug_ml / self.model_concentration_ug_ml
        )

    def describe(self) -> dict[str, Any]:
        """JSON-ready: ``concentration_ug_ml``, ``max_rate_ml_h`` and the limits' fields."""
        return {
            "concentration_ug_ml": self.concentration_ug_ml,
            "max_rate_ml_h": self.max_rate_ml_h,
            **{k: v for k, v in asdict(self.limits).items() if k != "concentration_ug_ml"},
        }


def _syringe(entry: DrugEntry, concentration_ug_ml: float, pump_max_ml_h: float) -> Syringe:
    weight = REFERENCE_WEIGHT_KG if entry.per_kg else None
    limits = entry.limits(concentration_ug_ml, weight)
    sustained = min(
        pump_max_ml_h,
        limits.hard_max_ml_h,
        limits.soft_max_ml_h if not limits.confirm_above_soft else math.inf,
        limits.max_ml_per_hour / 1.0,  # ml per hour, spread over one hour: ml/h
    )
    return Syringe(concentration_ug_ml, MODEL_CONCENTRATION_UG_ML[entry.name], limits, sustained)


def syringes(entry: DrugEntry, pump_max_ml_h: float) -> tuple[Syringe, Syringe | None]:
    """The drug's standard syringe and the stronger one a clinician switches to (or ``None``).

    The standard syringe is the library's first concentration. The stronger one is the weakest
    concentration that gives the largest dose the library allows within the pump's maximum
    (``pump_max_ml_h``, ml/h) and the dose limits (:attr:`Syringe.max_rate_ml_h`): a dilute
    syringe the pump cannot push to the limit is no use, and a stronger one than needed only coarsens the dosing.
    ``None`` when no concentration gives more than the standard (phenylephrine's one syringe).
    """
    standard = _syringe(entry, entry.concentrations_ug_ml[0], pump_max_ml_h)
    others = [
        _syringe(entry, c, pump_max_ml_h)
        for c in sorted(entry.concentrations_ug_ml)
        if c != standard.concentration_ug_ml
    ]
    best = max((s.max_dose_ug_min for s in others), default=0.0)
    if best <= standard.max_dose_ug_min:
        return standard, None
    # the hard limit is rounded down to a rate per syringe: equal doses differ in the last bits
    stronger = next(s for s in others if s.max_dose_ug_min >= best * (1.0 - 1e-9))
    return standard, stronger


def sort_patient(task: tuple[Scenario, str, int, float, float | None]) -> tuple[str, float]:
    """One patient's group and shortfall (mmHg; ``nan`` when held): ``task`` is (scenario, patient
    model spec, seed, the standard syringe's sustained rate, the stronger one's in the standard's
    ml/h or ``None``). A module-level function of one task, for :func:`reach_plan`'s workers."""
    scenario, spec, seed, standard_ml_h, stronger_ml_h = task
    world = World(scenario, seed, SAMPLE_PERIOD_S, patient_model=spec)
    band = world.band_mmhg()
    short = hold_shortfall_mmhg(world, standard_ml_h)
    if short <= band:
        return "standard", math.nan
    if stronger_ml_h is not None:
        short = hold_shortfall_mmhg(world, max(standard_ml_h, stronger_ml_h))
        if short <= band:
            return "switched", math.nan
    return "non_responders", short if math.isfinite(short) else math.inf


def reach_plan(
    scenario: Scenario,
    model: str,
    level: float,
    seeds: Sequence[int],
    standard: Syringe,
    stronger: Syringe | None,
    jobs: int = 1,
) -> dict[str, list[Any]]:
    """Sort a level's patients by the syringe that holds them at the target, on ``jobs`` local
    worker processes (:func:`sort_patient`; the same plan whatever ``jobs``).

    Returns
    -------
    dict
        ``standard`` (seeds the standard syringe holds within the metrics' band of the target for
        the rest of the hour once there, :func:`pressor.hil_sim.reach.holds`), ``switched`` (seeds
        only the stronger one does), ``non_responders`` (the rest) and ``shortfall_mmhg`` (per
        non-responder: how far the best syringe's capacity falls short of the scenario's ask at
        worst, mmHg, :func:`pressor.hil_sim.reach.hold_shortfall_mmhg`).
    """
    spec = standard.patient_model(model, level)
    # the stronger syringe's ml/h in the standard's: the same patient fed c/c_std times more
    stronger_ml_h = (
        None
        if stronger is None
        else stronger.max_rate_ml_h * stronger.concentration_ug_ml / standard.concentration_ug_ml
    )
    tasks = [(scenario, spec, seed, standard.max_rate_ml_h, stronger_ml_h) for seed in seeds]
    plan: dict[str, list[Any]] = {
        "standard": [], "switched": [], "non_responders": [], "shortfall_mmhg": [],
    }  # fmt: skip
    for seed, (group, short) in zip(
        seeds, run_ordered(sort_patient, tasks, jobs=jobs), strict=True
    ):
        plan[group].append(seed)
        if group == "non_responders":
            plan["shortfall_mmhg"].append(short)
    return plan
