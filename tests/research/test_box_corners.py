"""First-order patients of a design box (research/box_corners.py)."""

from __future__ import annotations

import math

import pytest

from pressor.hil_sim.patients.patient_model import load_patient_model, model_drug
from research.box_corners import NorepinephrineCorner, PhenylephrineCorner, corner


def test_the_patient_is_the_closed_form_first_order_step_behind_its_delay():
    h = 0.1
    top, t_hi, tau_hi = corner("phenylephrine")
    p = PhenylephrineCorner.from_seed(200 * 1000 + 50, h)  # T 200 s, K half the top
    assert (p.K, p.T_s, p.tau_s) == (pytest.approx(top / 2), 200.0, tau_hi)
    rate = 3.0
    for n in range(1, 3001):
        p.step(rate)
        d = round(tau_hi / h)  # whole steps of delay
        expected = 0.0 if n <= d else p.K * rate * (1.0 - math.exp(-(n - d) * h / 200.0))
        assert p.delta_map_mmhg == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert p.map_mmhg == pytest.approx(55.0 + p.delta_map_mmhg)


def test_seed_zero_is_the_most_sensitive_patient_at_the_boxs_longest_lag():
    top, t_hi, tau_hi = corner("norepinephrine")
    p = NorepinephrineCorner.from_seed(0, 0.1)
    assert (p.K, p.T_s, p.tau_s) == (pytest.approx(top), t_hi, tau_hi)
    # the norepinephrine population's top at 16 µg/ml and 70 kg: 20000 mmHg per µg/kg/min
    # × 16/(70 × 60) µg/kg/min per ml/h
    assert top == pytest.approx(20000.0 * 16.0 / (70.0 * 60.0))


@pytest.mark.parametrize(
    ("cls", "drug"),
    [("NorepinephrineCorner", "norepinephrine"), ("PhenylephrineCorner", "phenylephrine")],
)
def test_the_corner_patients_are_patient_models_of_their_drug(cls, drug):
    spec = f"research.box_corners:{cls}"
    assert load_patient_model(spec).DRUG == drug
    assert model_drug(spec).name == drug
