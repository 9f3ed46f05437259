"""The steep norepinephrine patients and the guarded cautious source (research/steep_patients.py)."""

from __future__ import annotations

import math

import pytest

from pressor.hil_sim.patients.patient_model import load_patient_model, model_drug
from pressor.hil_sim.patients.pkpd import PatientParams
from pressor.runtime.core.scheduling import ScheduleInput
from pressor.runtime.estimation.cautious import CautiousSchedule
from research.steep_patients import GuardedSchedule, SteepNorepinephrine
from tests.support.cautious_envelope import DOSE, ENVELOPE, TS, k_hat_on_a_first_order_patient

#: one compartment (Q = 0), no tolerance: its steady state is a hand computation (the test)
HAND = PatientParams(
    baseline_mmhg=55.0,
    delay_s=20.0,
    cl_l_min=2.5,
    v1_l=8.0,
    q_l_min=0.0,
    v2_l=150.0,
    effect_lag_s=40.0,
    emax_mmhg=50.0,
    ec50_ng_ml=32.0,
    hill=2.0,
    tolerance_tau_s=1200.0,
    tolerance_gain=0.0,
    hemorrhage_mmhg=10.0,
    hemorrhage_ramp_s=60.0,
    bolus_mmhg=8.0,
    bolus_rise_s=90.0,
    bolus_decay_s=600.0,
)


def test_each_ug_of_norepinephrine_counts_as_ten_of_phenylephrine_at_the_steady_state():
    # 15 ml/h of 16 ug/ml is 4 ug/min of norepinephrine, 40 of phenylephrine: 40/2.5 = 16 ng/ml;
    # (16/32)^2 = 0.25, so the rise is 50 * 0.25 / 1.25 = 10 mmHg
    patient = SteepNorepinephrine(HAND, 1.0)
    for _ in range(3600):  # an hour: V/CL = 3.2 min and a 40 s effect site have settled
        patient.step(15.0)
    assert patient.delta_map_mmhg == pytest.approx(10.0, abs=1e-6)
    assert patient.max_delta_map_mmhg(15.0) == pytest.approx(10.0, abs=1e-9)


@pytest.mark.parametrize(
    ("name", "drug", "ug_ml"),
    [
        ("SteepNorepinephrine", "norepinephrine", 16.0),
        ("SteepPhenylephrine", "phenylephrine", 100.0),
    ],
)
def test_the_steep_patients_load_as_a_model_of_their_drug_and_syringe(name, drug, ug_ml):
    spec = f"research.steep_patients:{name}"
    assert load_patient_model(spec).COHORT == "one-compartment"  # type: ignore[attr-defined]
    binding = model_drug(spec)
    assert binding is not None
    assert (binding.name, binding.concentration_ug_ml) == (drug, ug_ml)


def test_a_convexity_of_c_leaves_k_hat_c_times_where_no_response_leaves_it():
    # no response to 2 ml/h: K-hat settles where the margin (1 mmHg + 0.1 of the prediction)
    # hides the evidence's slowest patient (T 400 s, tau 45 s) after 3000 s: 1/(0.9 s) with
    # s = 2 (1 - exp(-2955/400)); the convexity divides s by c
    s = 2.0 * (1.0 - math.exp(-(3000.0 - 45.0) / 400.0))
    for c in (1.0, 2.5):
        source = GuardedSchedule(ENVELOPE, TS, DOSE, convexity=c)
        k = k_hat_on_a_first_order_patient(source, 0.0, 100.0, 10.0, 2.0, 3000.0)
        assert k[-1] == pytest.approx(c / (0.9 * s), rel=2e-3)


def test_holding_below_the_best_response_keeps_k_hat_through_a_drop_the_shipped_source_reads():
    # a patient of 1 mmHg/(ml/h), T 100 s, tau 10 s at 2 ml/h, then a 5 mmHg drop at 600 s
    def feed(source: CautiousSchedule) -> tuple[float, float]:
        at_drop = math.nan
        for i in range(int(700.0 / TS)):
            t = i * TS
            y = 50.0 + 2.0 * (1.0 - math.exp(-(t - 10.0) / 100.0)) if t > 10.0 else 50.0
            if t >= 600.0:
                at_drop = source.K if math.isnan(at_drop) else at_drop
                y -= 5.0
            source.update(ScheduleInput(y, 0, 2.0, math.nan, math.nan, math.nan, False))
        return at_drop, source.K

    shipped_at_drop, shipped_after = feed(CautiousSchedule(ENVELOPE, TS, DOSE))
    held_at_drop, held_after = feed(GuardedSchedule(ENVELOPE, TS, DOSE, hold_below_best=True))
    assert held_at_drop == shipped_at_drop  # the same source until the MAP fell
    assert held_after == held_at_drop
    assert shipped_after < 0.5 * shipped_at_drop


def test_the_dose_ceiling_holds_k_hat_where_a_hill_curve_from_no_response_would_reach_the_step():
    # no response to 2 ml/h for 3000 s: the evidence's slowest patient (T 400 s, tau 45 s) has
    # answered s = 2 (1 - exp(-2955/400)); a Hill curve of exponent 2 that stays under the 1 mmHg
    # margin there reaches 22 mmHg (the step and a tenth) at u_c = s (22/1)^(1/2), so K-hat stays
    # at 20/u_c, 4.26/s, where the shipped source lets it fall to the margin's 1/(0.9 s)
    # (with a margin of 0.25 mmHg in the ceiling: u_c = s (22/0.25)^(1/2), a higher ceiling)
    s = 2.0 * (1.0 - math.exp(-(3000.0 - 45.0) / 400.0))
    source = GuardedSchedule(ENVELOPE, TS, DOSE, hill=2.0)
    k = k_hat_on_a_first_order_patient(source, 0.0, 100.0, 10.0, 2.0, 3000.0)
    assert k[-1] == pytest.approx(20.0 / (s * math.sqrt(22.0)), rel=2e-3)
    quiet = GuardedSchedule(ENVELOPE, TS, DOSE, hill=2.0, ceiling_margin=0.25)
    k = k_hat_on_a_first_order_patient(quiet, 0.0, 100.0, 10.0, 2.0, 3000.0)
    assert k[-1] == pytest.approx(20.0 / (s * math.sqrt(22.0 / 0.25)), rel=2e-3)
    shipped = k_hat_on_a_first_order_patient(
        CautiousSchedule(ENVELOPE, TS, DOSE), 0.0, 100.0, 10.0, 2.0, 3000.0
    )
    assert shipped[-1] == pytest.approx(1.0 / (0.9 * s), rel=2e-3)


@pytest.mark.parametrize("convexity", [0.5, math.nan])
def test_a_convexity_below_one_is_refused_naming_it(convexity):
    with pytest.raises(ValueError, match="convexity=.* must be finite and >= 1"):
        GuardedSchedule(ENVELOPE, TS, DOSE, convexity=convexity)


@pytest.mark.parametrize("hill", [0.5, math.inf])
def test_a_hill_exponent_below_one_is_refused_naming_it(hill):
    with pytest.raises(ValueError, match="hill=.* must be finite and >= 1"):
        GuardedSchedule(ENVELOPE, TS, DOSE, hill=hill)


def test_a_negative_ceiling_margin_is_refused_naming_it():
    with pytest.raises(ValueError, match="ceiling_margin=-1.0 mmHg must be finite and >= 0"):
        GuardedSchedule(ENVELOPE, TS, DOSE, hill=2.0, ceiling_margin=-1.0)


@pytest.fixture
def dose_cap(monkeypatch):
    """:func:`research.steep_patients.install_dose_cap` for one test: the norepinephrine
    module's controller class, the trial's compiled twin and ``envelope_of`` restored after it."""
    from pressor.hil_sim.trials import trial
    from pressor.runtime.estimation import design_envelope
    from pressor.runtime.inputs.controller_loader import LPV_DESIGNS, load_generated_module
    from research.steep_patients import CAPPED_DESIGNS, install_dose_cap

    classes = [load_generated_module(LPV_DESIGNS[n]).Controller for n in CAPPED_DESIGNS]
    for target, name in [(c, "_step_float") for c in classes] + [
        (trial, "native_twin"),
        (design_envelope, "envelope_of"),
    ]:
        monkeypatch.setattr(target, name, getattr(target, name))
    norepinephrine = classes[CAPPED_DESIGNS.index("norepinephrine-cautious")]
    shipped = norepinephrine._step_float
    install_dose_cap()
    yield norepinephrine, shipped
    for c in classes:
        del c._dose_cap


def _commands(ctl, seconds: float = 600.0) -> list[float]:
    """Commands (ml/h) of ``ctl`` on K 1 mmHg/(ml/h), T 250 s, τ 55 s towards a target 20 mmHg
    above a MAP that never moves (the feedback winds up against whatever bounds the dose)."""
    return [ctl.step(60.0, 80.0, 1.0, 250.0, 55.0) for _ in range(int(seconds / TS))]


def test_the_research_dose_cap_bounds_every_command_and_changes_nothing_at_the_pump_maximum(
    dose_cap,
):
    cls, shipped = dose_cap
    free, same, capped = cls(), cls(), cls()
    same_commands = _commands(same)
    assert same_commands == [shipped(free, 60.0, 80.0, 1.0, 250.0, 55.0) for _ in same_commands]
    assert max(same_commands) > 30.0  # the law asks for more than the cap below
    capped._dose_cap = 7.5
    assert max(_commands(capped)) == pytest.approx(7.5)
