"""The ``norepinephrine`` patient model against values computed by hand (closed forms, not the code
under test): steady state with endogenous production and counter-regulation, the step response of
the one compartment and its effect site, the apparent schedule, the seeded draws."""

from __future__ import annotations

import math
from dataclasses import asdict, replace

import pytest

from pressor.hil_sim.patients.norepinephrine import (
    CONCENTRATION_UG_ML,
    RANGES,
    Norepinephrine1C,
    NorepinephrineParams,
    draw_params,
)
from pressor.hil_sim.patients.patient_model import PatientModel, load_patient_model

#: a typical patient: SAPS II 40 (CL = 3·0.3^0.5 l/min), V 8.8 l, EC50 2.5 ng/ml
TYPICAL = NorepinephrineParams(
    baseline_mmhg=50.0,
    line_delay_s=10.0,
    effect_lag_s=25.0,
    saps2=40.0,
    v_l=8.8,
    endogenous_ug_min=0.5,
    effect_tau_s=20.0,
    ec50_ng_ml=2.5,
    hill=1.5,
    net_emax_mmhg=30.0,
    k_out_per_min=0.072,
    feedback_exponent=0.66,
)


def hill(x: float, emax: float, ec50: float, n: float) -> float:
    return emax * x**n / (ec50**n + x**n)


def test_clearance_follows_beloeil_at_saps_20_40_60_and_the_model_is_registered() -> None:
    assert replace(TYPICAL, saps2=20.0).clearance_l_min == pytest.approx(3.0)
    assert replace(TYPICAL, saps2=60.0).clearance_l_min == pytest.approx(0.9)
    assert TYPICAL.clearance_l_min == pytest.approx(math.sqrt(3.0 * 0.9))
    # half-lives ln2·V/CL: 2.0 and 6.8 min, Beloeil's
    assert math.log(2) * 8.8 / 3.0 == pytest.approx(2.0, abs=0.05)
    assert math.log(2) * 8.8 / 0.9 == pytest.approx(6.8, abs=0.05)
    assert load_patient_model("norepinephrine") is Norepinephrine1C
    assert isinstance(Norepinephrine1C.from_seed(3, 0.1), PatientModel)


def test_steady_state_is_the_hand_computed_hill_value_less_the_counter_regulated_fraction() -> None:
    # 30 ml/h of 16 ug/ml = 8 ug/min; CL = sqrt(2.7) l/min; Css = (8 + 0.5)/CL ng/ml;
    # g = 0.66/1.66, Emax = 30·1.66 = 49.8; ΔMAP = (1 - g)·(H(Css) - H(C_endo)).
    cl = math.sqrt(2.7)
    c_endo, css = 0.5 / cl, 8.5 / cl
    emax = 30.0 * 1.66
    hand = (hill(css, emax, 2.5, 1.5) - hill(c_endo, emax, 2.5, 1.5)) / 1.66
    patient = Norepinephrine1C(TYPICAL, 1.0)
    assert patient.map_mmhg == 50.0 and patient.plasma_ng_ml == pytest.approx(c_endo)
    assert patient.max_delta_map_mmhg(30.0) == pytest.approx(hand, rel=1e-12)
    for _ in range(3 * 3600):  # 3 h: > 20 counter-regulation time constants (8.4 min)
        patient.step(30.0)
    assert patient.plasma_ng_ml == pytest.approx(css, rel=1e-9)
    assert patient.delta_map_mmhg == pytest.approx(hand, abs=1e-6)
    assert patient.counter_mmhg == pytest.approx(hand * 0.66, abs=1e-6)


def test_step_response_follows_the_one_compartment_and_effect_site_closed_form() -> None:
    params = replace(TYPICAL, feedback_exponent=0.0, endogenous_ug_min=0.0)  # no feedback
    patient = Norepinephrine1C(params, 0.1)
    cl = math.sqrt(2.7)
    k, ke0 = cl / 8.8 / 60.0, 1.0 / 20.0  # 1/s
    u = 30.0 * 16.0 / 3600.0  # ug/s
    seen = {}
    for j in range(1, 12001):  # 20 min
        patient.step(30.0)
        seen[j] = (patient.plasma_ng_ml, patient.delta_map_mmhg)
    assert seen[350] == (0.0, 0.0)  # the 35 s delay (line 10 s + effect lag 25 s)
    for j in (400, 1200, 6000, 12000):
        t = j * 0.1 - 35.0
        c = u / (k * 8.8) * (1.0 - math.exp(-k * t))
        ce = u / (k * 8.8) * (1.0 - (ke0 * math.exp(-k * t) - k * math.exp(-ke0 * t)) / (ke0 - k))
        assert seen[j][0] == pytest.approx(c, rel=1e-9)
        assert seen[j][1] == pytest.approx(hill(ce, 30.0, 2.5, 1.5), rel=1e-9)
    # apparent schedule: T = 60·V/CL + 1/ke0, τ = line + lag, K the settled rise of one more ml/h
    assert patient.T_s == pytest.approx(60.0 * 8.8 / cl + 20.0)
    assert patient.tau_s == 35.0
    dc = CONCENTRATION_UG_ML / (60.0 * cl)
    assert patient.K == pytest.approx(hill(ce + dc, 30.0, 2.5, 1.5) - hill(ce, 30.0, 2.5, 1.5))


def test_draws_are_seeded_and_inside_the_documented_ranges() -> None:
    assert draw_params(11) == draw_params(11) != draw_params(12)
    for seed in range(30):
        for name, value in asdict(draw_params(seed)).items():
            lo, hi = RANGES[name]
            assert lo <= value <= hi, (name, value)
    with pytest.raises(ValueError, match="hill=-1.0 outside"):
        replace(TYPICAL, hill=-1.0)
    with pytest.raises(ValueError, match="step_s=20.0 outside"):
        Norepinephrine1C(TYPICAL, 20.0)
