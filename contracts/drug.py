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
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Any

__all__ = [
    "DEFAULT_BINDING",
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
