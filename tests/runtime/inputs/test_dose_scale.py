"""Doses in the law (pressor.contracts.drug.DoseScale): the conversions round-trip for every syringe of the
shipped drug library and every adult weight, and a dose design's population fits its module's box
whatever the syringe and weight."""

from __future__ import annotations

import math

import pytest

from pressor.contracts.drug import REFERENCE_WEIGHT_KG, DoseScale, dose_ug_kg_min
from pressor.runtime.inputs.config import load_controller
from pressor.runtime.inputs.drug_library import WEIGHT_MAX_KG, WEIGHT_MIN_KG, load_library

WEIGHTS = (WEIGHT_MIN_KG, 55.5, REFERENCE_WEIGHT_KG, 123.4, WEIGHT_MAX_KG)
SYRINGES = [
    (name, c) for name, entry in sorted(load_library().items()) for c in entry.concentrations_ug_ml
]


@pytest.mark.parametrize(("drug", "conc"), SYRINGES)
@pytest.mark.parametrize("weight", WEIGHTS)
def test_rates_doses_and_sensitivities_round_trip(drug, conc, weight):
    scale = DoseScale(conc, weight)
    for rate in (0.0, 0.1, 1.0, 37.5, 120.0):
        dose = scale.dose(rate)
        assert dose == pytest.approx(dose_ug_kg_min(rate, conc, weight), rel=1e-15)
        assert scale.ml_h(dose) == pytest.approx(rate, rel=1e-14, abs=1e-15)
    for k in (1e-3, 0.55, 10.0, 2e4):
        assert scale.k_ml_h(scale.k_dose(k)) == pytest.approx(k, rel=1e-14)
        # the same patient: K ml/h x rate = K dose x dose (mmHg)
        assert scale.k_dose(k) * scale.dose(12.0) == pytest.approx(k * 12.0, rel=1e-14)


def test_the_literature_conversions():
    # 1 ml/h of phenylephrine 100 ug/ml at 70 kg = 0.0238 ug/kg/min; norepinephrine 16 ug/ml at
    # 70 kg = 0.0038 ug/kg/min (docs/DRUGS.md)
    assert DoseScale(100.0, 70.0).dose_per_ml_h == pytest.approx(0.0238, rel=2e-3)
    assert DoseScale(16.0, 70.0).dose_per_ml_h == pytest.approx(0.0038, rel=3e-3)


@pytest.mark.parametrize(
    ("conc", "weight"), [(0.0, 70.0), (-1.0, 70.0), (100.0, 0.0), (100.0, math.nan)]
)
def test_a_bad_syringe_or_weight_is_refused(conc, weight):
    with pytest.raises(ValueError, match="concentration_ug_ml|weight_kg"):
        DoseScale(conc, weight)


@pytest.mark.parametrize("spec", ["lpv:cautious", "lpv:norepinephrine-cautious"])
def test_the_population_fits_the_module_box_at_every_library_syringe_and_weight(spec):
    mod = type(load_controller(spec, 0.1)).__module__
    import sys

    module = sys.modules[mod]
    lo, hi = module.POPULATION_K_UG_KG_MIN
    k_lo, k_hi = module.GRID_LO[0], module.GRID_HI[0]
    for conc in load_library()[module.DRUG].concentrations_ug_ml:
        for weight in (WEIGHT_MIN_KG, WEIGHT_MAX_KG):
            scale = DoseScale(conc, weight)
            assert k_lo <= scale.k_ml_h(lo) and scale.k_ml_h(hi) <= k_hi, (conc, weight)
    assert hi / lo >= 100.0 and k_hi / k_lo >= 100.0
