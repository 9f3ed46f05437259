"""The drug and syringe a controller design is bound to, and the dose conversions.

A design's gains are in ml/h of one syringe (K in mmHg/(ml/h)): they hold only for the drug they
were identified for and at the concentration (µg/ml) whose ml/h they count. The binding travels
with the design: the design TOML's ``[drug]`` section, the artifact's ``design.drug`` metadata
(an artifact without it reads as :data:`DEFAULT_BINDING`, the values every design was made for
before the binding existed), the generated module's ``DRUG`` and ``DRUG_CONCENTRATION_UG_ML``
constants (:func:`binding_of` reads them), and ``pressor run``, which refuses a ``--drug``, a
``--concentration-ug-ml`` or a device hello that does not match them (docs/DRUGS.md).

Dose conversions (the rate r in ml/h of a syringe at c µg/ml, a patient of W kg)::

    dose (µg/min)    = r * c / 60
    dose (µg/kg/min) = r * c / (60 * W)
    rate (ml/h)      = dose_ug_min * 60 / c = dose_ug_kg_min * 60 * W / c

Sensitivity in doses. A patient's K counts mmHg per ml/h of the syringe in the pump; the same
patient in mmHg per µg/kg/min does not depend on the syringe, and dividing by the weight removes
part of the spread between patients. With ``f = c / (60 W)`` (µg/kg/min per ml/h)::

    K (mmHg per µg/kg/min) = K (mmHg/(ml/h)) / f,    K (mmHg/(ml/h)) = K (mmHg per µg/kg/min) * f

The scheduled Smith law is homogeneous in K and the command (its gains are 1/K): the law at
``(K * f, u / f)`` is the law at ``(K, u)``. So a controller generated in ml/h serves every syringe
and weight when its K is given in ml/h of the syringe in the pump and its K box covers the
population's doses converted with that syringe and weight (:class:`DoseScale`): the conversion to
ml/h happens once, at the schedule, and the command stays in the pump's ml/h.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Any

__all__ = [
    "DEFAULT_BINDING",
    "dose_scaled",
    "drug_agnostic",
    "REFERENCE_WEIGHT_KG",
    "DoseScale",
    "DrugBinding",
    "binding_of",
    "dose_ug_kg_min",
    "dose_ug_min",
    "rate_ml_h_for_ug_min",
]

#: longest drug name (the link hello's ``drug`` field is char[16])
MAX_DRUG_CHARS = 16
#: largest concentration accepted anywhere (µg/ml)
MAX_CONCENTRATION_UG_ML = 100000.0
#: the reference adult (kg) of the simulated patient models, whose ml/h count a 70 kg patient's
#: doses (docs/DRUGS.md): the weight a simulation converts doses with
REFERENCE_WEIGHT_KG = 70.0


@dataclass(frozen=True)
class DrugBinding:
    """The drug a design's gains are for and the syringe concentration their ml/h count.

    Attributes
    ----------
    name
        Drug name, lower case, 1 to 16 ASCII characters (``phenylephrine``).
    concentration_ug_ml
        Syringe concentration (µg/ml) of the ml/h in the design's gains, in (0, 100000].
    """

    name: str
    concentration_ug_ml: float

    def __post_init__(self) -> None:
        name = self.name
        if not (
            isinstance(name, str)
            and name
            and name.isascii()
            and name == name.strip().lower()
            and len(name) <= MAX_DRUG_CHARS
        ):
            raise ValueError(
                f"drug name {name!r}: allowed 1 to {MAX_DRUG_CHARS} lower-case ASCII characters"
            )
        c = self.concentration_ug_ml
        if isinstance(c, bool) or not isinstance(c, int | float):
            raise ValueError(f"drug concentration_ug_ml {c!r}: allowed a number")
        if not (math.isfinite(c) and 0.0 < c <= MAX_CONCENTRATION_UG_ML):
            raise ValueError(
                f"drug concentration_ug_ml {c!r}: allowed (0, {MAX_CONCENTRATION_UG_ML:g}] ug/ml"
            )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (``name``, ``concentration_ug_ml``): the artifact's ``design.drug``."""
        return {"name": self.name, "concentration_ug_ml": float(self.concentration_ug_ml)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> DrugBinding:
        """Inverse of :meth:`to_dict`; ``ValueError`` on missing or extra keys or a bad value."""
        if not isinstance(d, dict) or set(d) != {"name", "concentration_ug_ml"}:
            raise ValueError(f"drug {d!r}: allowed exactly the keys concentration_ug_ml, name")
        return cls(d["name"], d["concentration_ug_ml"])

    def describe(self) -> str:
        """``phenylephrine at 100 ug/ml``."""
        return f"{self.name} at {self.concentration_ug_ml:g} ug/ml"


#: The binding of every design made before designs named their drug: phenylephrine (the paper's
#: vasopressor) at 100 µg/ml (10 mg in 100 ml, the usual infusion dilution; the paper states none).
DEFAULT_BINDING = DrugBinding("phenylephrine", 100.0)


def binding_of(controller: Any) -> DrugBinding:
    """The drug binding a controller declares, else :data:`DEFAULT_BINDING`.

    Looked up on the instance, then on its module: ``DRUG`` and ``DRUG_CONCENTRATION_UG_ML`` as
    ``codegen`` emits them. The baselines (PI, Smith predictor) and modules generated before the
    binding existed declare none: their gains assume the shipped designs' syringe.

    Raises
    ------
    ValueError
        A declared binding that is not valid (:class:`DrugBinding`).
    """
    module = sys.modules.get(type(controller).__module__)
    for src in (controller, module):
        if src is not None and hasattr(src, "DRUG"):
            return DrugBinding(
                str(src.DRUG), float(getattr(src, "DRUG_CONCENTRATION_UG_ML", math.nan))
            )
    return DEFAULT_BINDING


def drug_agnostic(controller: Any) -> bool:
    """Whether a controller declares ``DRUG_AGNOSTIC = True`` (on the instance, its class or its
    module): it is bound to no drug and runs on whichever the clinician names (the PI and Smith
    baselines: fixed or scheduled gains in ml/h that every shipped drug's nominal patient shares,
    K ≈ 0.55 mmHg/(ml/h) of its usual syringe; docs/DRUGS.md). ``pressor run`` then checks the
    clinician's drug and syringe against the library and the device, not against a design."""
    module = sys.modules.get(type(controller).__module__)
    return any(getattr(src, "DRUG_AGNOSTIC", False) is True for src in (controller, module) if src)


def dose_scaled(controller: Any) -> bool:
    """Whether a controller's design is sized in doses (its module declares
    ``POPULATION_K_UG_KG_MIN``): it is bound to its drug but serves every syringe of it, the
    schedule converting the population to ml/h of the syringe in the pump (:class:`DoseScale`)."""
    module = sys.modules.get(type(controller).__module__)
    return any(
        getattr(src, "POPULATION_K_UG_KG_MIN", None) is not None
        for src in (controller, module)
        if src
    )


def dose_ug_min(rate_ml_h: float, concentration_ug_ml: float) -> float:
    """Dose rate (µg/min) of ``rate_ml_h`` (ml/h) of a ``concentration_ug_ml`` (µg/ml) syringe."""
    return rate_ml_h * concentration_ug_ml / 60.0


def dose_ug_kg_min(rate_ml_h: float, concentration_ug_ml: float, weight_kg: float) -> float:
    """Dose rate (µg/kg/min) of ``rate_ml_h`` (ml/h) at ``concentration_ug_ml`` (µg/ml) for a
    patient of ``weight_kg`` (kg)."""
    return rate_ml_h * concentration_ug_ml / (60.0 * weight_kg)


def rate_ml_h_for_ug_min(dose_ug_per_min: float, concentration_ug_ml: float) -> float:
    """The rate (ml/h) delivering ``dose_ug_per_min`` (µg/min) from a ``concentration_ug_ml``
    (µg/ml) syringe."""
    return dose_ug_per_min * 60.0 / concentration_ug_ml


@dataclass(frozen=True)
class DoseScale:
    """The conversion between ml/h of one syringe and doses per kg for one patient.

    Attributes
    ----------
    concentration_ug_ml
        The syringe in the pump (µg/ml), in (0, 100000].
    weight_kg
        The patient's weight (kg), > 0.
    """

    concentration_ug_ml: float
    weight_kg: float

    def __post_init__(self) -> None:
        c, w = self.concentration_ug_ml, self.weight_kg
        if not (
            isinstance(c, int | float) and math.isfinite(c) and 0 < c <= MAX_CONCENTRATION_UG_ML
        ):
            raise ValueError(
                f"concentration_ug_ml {c!r}: allowed (0, {MAX_CONCENTRATION_UG_ML:g}] ug/ml"
            )
        if not (isinstance(w, int | float) and math.isfinite(w) and w > 0):
            raise ValueError(f"weight_kg {w!r}: allowed a finite number > 0 kg")

    @property
    def dose_per_ml_h(self) -> float:
        """µg/kg/min delivered by 1 ml/h: ``c / (60 W)``."""
        return self.concentration_ug_ml / (60.0 * self.weight_kg)

    def ml_h(self, dose_ug_kg_min: float) -> float:
        """The rate (ml/h) delivering ``dose_ug_kg_min`` (µg/kg/min)."""
        return dose_ug_kg_min * 60.0 * self.weight_kg / self.concentration_ug_ml

    def dose(self, rate_ml_h: float) -> float:
        """The dose (µg/kg/min) ``rate_ml_h`` (ml/h) delivers."""
        return rate_ml_h * self.concentration_ug_ml / (60.0 * self.weight_kg)

    def k_ml_h(self, k_per_dose: float) -> float:
        """A sensitivity in mmHg per µg/kg/min as mmHg/(ml/h) of this syringe and patient."""
        return k_per_dose * self.concentration_ug_ml / (60.0 * self.weight_kg)

    def k_dose(self, k_per_ml_h: float) -> float:
        """A sensitivity in mmHg/(ml/h) of this syringe as mmHg per µg/kg/min."""
        return k_per_ml_h * 60.0 * self.weight_kg / self.concentration_ug_ml
