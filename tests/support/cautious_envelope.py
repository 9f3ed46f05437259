"""A small design envelope for the cautious source's research variants' tests, and a
first-order patient to feed them.

A box of T 100-400 s and τ 10-45 s whose population's top is 10 mmHg/(ml/h) at a 100 µg/ml
syringe and 70 kg, certified falls of ln K of 0.04/s, and a drug with no caution of its own (the
box's geometric-mean T, no effect site, start at the top).
"""

from __future__ import annotations

import math

import numpy as np

from pressor.contracts.drug import DoseScale
from pressor.runtime.core.scheduling import ScheduleInput
from pressor.runtime.estimation.cautious import CautiousSchedule
from pressor.runtime.estimation.design_envelope import DesignEnvelope

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


def k_hat_on_a_first_order_patient(
    source: CautiousSchedule,
    K: float,
    T_s: float,
    tau_s: float,
    rate_ml_h: float,
    until_s: float,
    device: tuple[float, float] | None = None,
) -> np.ndarray:
    """K̂ at each tick of ``source`` fed a first-order patient (K mmHg/(ml/h), T and τ in s; its
    closed-form step response from 50 mmHg) infused at ``rate_ml_h`` from t = 0 for ``until_s``
    s; ``device``: the (T, τ) the device sends (valid), or none."""
    dev_T, dev_tau = device if device is not None else (math.nan, math.nan)
    out = []
    for i in range(int(round(until_s / TS))):
        t = i * TS
        rise = K * rate_ml_h * (1.0 - math.exp(-(t - tau_s) / T_s)) if t > tau_s else 0.0
        inputs = ScheduleInput(
            50.0 + rise, 0, rate_ml_h, math.nan, dev_T, dev_tau, device is not None
        )
        out.append(source.update(inputs).K)
    return np.array(out)
