"""The default controller on first-order patients at its design box's slow corner.

The sweep judges the cautious start on the drug's patient models (docs/notes/cautious-start.md).
Its construction bounds the *first commands* for the most sensitive patient of the certified
range; this probe asks what the closed loop then does on the range's plain first-order-plus-delay
patients, where the models may not go: the population's top sensitivity (and fractions of it) at
each lag up to the box's longest, with the box's longest delay, on a +20 mmHg step without
disturbances (monitor noise 0.1 mmHg), through the drug's default (its log-K design on the
cautious schedule). Measured in docs/notes/cautious-start.md, "The box's slow corner".

Usage::

    python -m research.box_corners --drug norepinephrine
    python -m research.box_corners --drug phenylephrine --lags 100,200,300,400
    python -m research.box_corners --drug norepinephrine \\
        --caution 'norepinephrine:{"T_s": 750}'

Printed per lag: step overshoot (% of the step) and time to ±5 mmHg (min) at each fraction of the
top sensitivity.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import ClassVar

from pressor.contracts.drug import REFERENCE_WEIGHT_KG, DoseScale
from pressor.hil_sim.patients.patient import FrozenParams, Patient
from research import cautious_levels

#: drug -> (generated module of its default design, syringe µg/ml)
DESIGNS: dict[str, tuple[str, float]] = {
    "phenylephrine": ("lpv_cautious", 100.0),
    "norepinephrine": ("lpv_norepinephrine_cautious", 16.0),
}
#: the probe's scenario: a +20 mmHg step at t = 0, noise 0.1 mmHg, no disturbance, 1 h
SCENARIO = Path(__file__).with_name("box_corner_step.toml")
BASELINE_MMHG = 55.0


def corner(drug: str) -> tuple[float, float, float]:
    """(top K in mmHg/(ml/h) at the design's syringe and the reference adult, the box's longest
    T in s, its longest τ in s) of ``drug``'s default design."""
    import importlib

    name, conc = DESIGNS[drug]
    module = importlib.import_module(f"pressor.runtime.generated.{name}")
    top = DoseScale(conc, REFERENCE_WEIGHT_KG).k_ml_h(module.POPULATION_K_UG_KG_MIN[1])
    return float(top), float(module.GRID_HI[1]), float(module.GRID_HI[2])


class _FirstOrder(Patient):
    """The project's frozen first-order patient (:class:`pressor.hil_sim.patients.patient.Patient`
    on :class:`~pressor.hil_sim.patients.patient.FrozenParams`: K·e^(−τs)/(Ts+1), MAP from
    :data:`BASELINE_MMHG`) as a patient model of a drug. ``patient_seed`` = T in s × 1000 + K in %
    of the drug's top (1-999); 0 parts mean the box's longest T and the top."""

    DRUG: ClassVar[str]
    DRUG_CONCENTRATION_UG_ML: ClassVar[float]
    coefficient_units: ClassVar[Mapping[str, str]] = {
        "K": "mmHg/(ml/h)",
        "T_s": "s",
        "tau_s": "s",
        "baseline_mmhg": "mmHg",
    }

    @classmethod
    def from_seed(cls, patient_seed: int, step_s: float) -> _FirstOrder:
        top, t_hi, tau_hi = corner(cls.DRUG)
        T_s = patient_seed // 1000 or t_hi
        pct = patient_seed % 1000 or 100
        return cls(FrozenParams(top * pct / 100.0, float(T_s), tau_hi, BASELINE_MMHG), step_s)


class PhenylephrineCorner(_FirstOrder):
    """A first-order phenylephrine patient (100 µg/ml) of the default design's box."""

    DRUG = "phenylephrine"
    DRUG_CONCENTRATION_UG_ML = 100.0


class NorepinephrineCorner(_FirstOrder):
    """A first-order norepinephrine patient (16 µg/ml) of the default design's box."""

    DRUG = "norepinephrine"
    DRUG_CONCENTRATION_UG_ML = 16.0


MODELS = {"phenylephrine": PhenylephrineCorner, "norepinephrine": NorepinephrineCorner}


def probe(drug: str, T_s: float, pct: int) -> tuple[float, float | None]:
    """(step overshoot %, time to ±5 mmHg in min or None) of the default on the first-order
    patient of ``drug`` with lag ``T_s`` (s) and sensitivity ``pct`` % of the top."""
    from pressor.api import simulate

    model = f"{__name__}:{MODELS[drug].__name__}"
    run = simulate(None, SCENARIO, int(T_s) * 1000 + pct, patient_model=model)
    t = run.record["time_to_band_s"]
    return run.record["step_overshoot_pct"], None if t is None else t / 60.0


def main(argv: list[str] | None = None) -> int:
    """Print the probe's table (module docstring)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--drug", choices=sorted(DESIGNS), default="norepinephrine")
    p.add_argument(
        "--lags", default=None, help="T in s, comma-separated (default: 4 up to the box's)"
    )
    p.add_argument("--percents", default="100,50,20,10", help="K in %% of the population's top")
    p.add_argument(
        "--caution", default=None, metavar="DRUG:JSON", help="as research.cautious_levels"
    )
    a = p.parse_args(argv)
    if a.caution:
        cautious_levels.replace_caution(a.caution)
    top, t_hi, tau_hi = corner(a.drug)
    lags = (
        [float(x) for x in a.lags.split(",")]
        if a.lags
        else [t_hi * f for f in (1, 0.75, 0.5, 0.25)]
    )
    pcts = [int(x) for x in a.percents.split(",")]
    print(f"{a.drug}: top K {top:.2f} mmHg/(ml/h), tau {tau_hi:g} s; overshoot % / to ±5 min")
    print("| T (s) | " + " | ".join(f"K {q} % of top" for q in pcts) + " |")
    print("| ---: |" + " ---: |" * len(pcts))
    for T in lags:
        cells = []
        for q in pcts:
            ov, tb = probe(a.drug, T, q)
            cells.append(f"{ov:.1f} / {'-' if tb is None else f'{tb:.1f}'}")
        print(f"| {T:g} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
