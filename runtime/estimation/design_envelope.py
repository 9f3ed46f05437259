"""What a generated log-K module declares that the cautious start needs: its box, its certified
rates of ln K, its patient population and its syringe (:class:`DesignEnvelope`, read by
:func:`envelope_of`; the source itself: :mod:`pressor.runtime.estimation.cautious`)."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Any

from pressor.contracts.drug import binding_of

__all__ = ["DesignEnvelope", "envelope_of"]


@dataclass(frozen=True)
class DesignEnvelope:
    """What a generated log-K module declares that the cautious source needs.

    Attributes
    ----------
    box
        ((K lo, hi) mmHg/(ml/h), (T lo, hi) s, (τ lo, hi) s) of the design.
    fall_per_s, rise_per_s
        The certified bounds on the fall and the rise of ln K (1/s).
    population
        (lo, hi) sensitivity of the design's patients (mmHg per µg/kg/min).
    concentration_ug_ml
        The syringe the design names (µg/ml).
    drug
        The drug the design is for (lower case, ``phenylephrine``).
    """

    box: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
    fall_per_s: float
    rise_per_s: float
    population: tuple[float, float]
    concentration_ug_ml: float
    drug: str = "phenylephrine"


def envelope_of(controller: Any) -> DesignEnvelope:
    """The :class:`DesignEnvelope` a generated module declares (on the instance or its module).

    Raises
    ------
    ValueError
        A controller that is not a log-K design with a patient population (``K_RATE_RELATIVE``,
        ``POPULATION_K_UG_KG_MIN``, ``GRID_LO``/``GRID_HI``, ``RATE_BOUNDS``), naming what is
        missing.
    """
    module = sys.modules.get(type(controller).__module__)

    def find(name: str) -> Any:
        for src in (controller, module):
            if src is not None and hasattr(src, name):
                return getattr(src, name)
        return None

    names = ("GRID_LO", "GRID_HI", "RATE_BOUNDS", "K_RATE_RELATIVE", "POPULATION_K_UG_KG_MIN")
    missing = [n for n in names if find(n) is None]
    if missing or not find("K_RATE_RELATIVE"):
        raise ValueError(
            f"--schedule cautious needs a design on a log-K scale with a patient population"
            f" ([rates] K_relative_per_s, [population]); the controller"
            f" {type(controller).__qualname__!r} declares no {', '.join(missing or names[3:4])}"
        )
    lo, hi = find("GRID_LO"), find("GRID_HI")
    box = tuple((float(a), float(b)) for a, b in zip(lo, hi, strict=True))
    fall = float(find("K_RATE_FALL_PER_S") or find("RATE_BOUNDS")[0])
    rise = float(find("K_RATE_UP_PER_S") or fall)
    pop = tuple(float(v) for v in find("POPULATION_K_UG_KG_MIN"))
    binding = binding_of(controller)
    return DesignEnvelope(
        box,  # type: ignore[arg-type]
        fall,
        rise,
        pop,  # type: ignore[arg-type]
        binding.concentration_ug_ml,
        binding.name,
    )
