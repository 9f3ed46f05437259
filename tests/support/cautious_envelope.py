"""A small design envelope for the cautious source's research variants' tests.

A box of T 100-400 s and τ 10-45 s whose population's top is 10 mmHg/(ml/h) at a 100 µg/ml
syringe and 70 kg, certified falls of ln K of 0.04/s, and a drug with no caution of its own (the
box's geometric-mean T, no effect site, start at the top).
"""

from __future__ import annotations

from pressor.contracts.drug import DoseScale
from pressor.runtime.estimation.cautious import DesignEnvelope

TS = 0.1  # s
DOSE = DoseScale(100.0, 70.0)
ENVELOPE = DesignEnvelope(
    box=((0.01, 50.0), (100.0, 400.0), (10.0, 45.0)),
    fall_per_s=0.04,
    rise_per_s=0.0015,
    population=(DOSE.k_dose(0.05), DOSE.k_dose(10.0)),
    concentration_ug_ml=100.0,
    drug="a drug without a caution",
)
