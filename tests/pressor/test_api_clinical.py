"""The API in clinical units and in its own terms: a design meets only its drug, doses in
µg/kg/min, an absolute target, errors naming the API's arguments (issue 40, items 1 and 5)."""

from __future__ import annotations

import numpy as np
import pytest

from pressor import api
from pressor.hil_sim.patients.patient_model import PatientModelError
from pressor.plumbing.parallel import BackendError
from pressor.runtime.core.closed_loop import ControllerError

RAISES = "tests.support.controller_plugins:Raises"


@pytest.mark.parametrize(
    "call",
    [
        lambda sc: api.trial("lpv", sc, n_patients=1, patient_model="norepinephrine"),
        lambda sc: api.simulate("lpv", sc, patient_model="norepinephrine"),
        lambda sc: api.compare(["pi", "lpv"], sc, n_patients=1, patient_model="norepinephrine"),
        lambda sc: api.simulate("lpv:norepinephrine", sc),
    ],
)
def test_a_design_is_refused_on_another_drugs_patients_naming_both_drugs(call, short_scenario):
    with pytest.raises(PatientModelError) as info:
        call(short_scenario)
    text = str(info.value)
    assert "phenylephrine" in text and "norepinephrine" in text
    assert "--" not in text and "patient_model" in text and text.startswith("controller ")


def test_the_drug_agnostic_baselines_run_on_the_patient_model_s_drug(short_scenario):
    for controller in ("pi", "smith"):
        run = api.simulate(controller, short_scenario, patient_model="norepinephrine")
        inf = run.record["infusion"]
        assert (inf["drug"], inf["concentration_ug_ml"]) == ("norepinephrine", 16.0)


def test_the_record_gives_mean_and_peak_dose_in_ug_kg_min_at_the_weight(short_scenario):
    run = api.simulate("pi", short_scenario, weight_kg=50.0)
    inf, rec = run.record["infusion"], run.record
    assert (inf["drug"], inf["concentration_ug_ml"], inf["weight_kg"]) == (
        "phenylephrine",
        100.0,
        50.0,
    )
    assert inf["peak_dose_ug_kg_min"] == pytest.approx(rec["max_rate_ml_h"] * 100.0 / (60 * 50))
    assert inf["mean_dose_ug_kg_min"] == pytest.approx(
        rec["drug_total_ml"] * 3600.0 / 300.0 * 100.0 / (60 * 50)
    )
    reference = api.simulate("pi", short_scenario).record["infusion"]
    assert (reference["weight_kg"], reference["weight_given"]) == (70.0, False)
    assert inf["weight_given"] is True


def test_a_trial_records_the_drug_and_weight_with_every_patient(short_scenario):
    result = api.trial("pi", short_scenario, n_patients=2, weight_kg=90.0)
    assert all(r["infusion"]["weight_kg"] == 90.0 for r in result.records)
    assert result.summary["infusion"]["weight_kg"] == 90.0
    frame_columns = result.records[0]["infusion"].keys()
    assert {"mean_dose_ug_kg_min", "peak_dose_ug_kg_min", "mean_rate_ml_h"} <= set(frame_columns)


def test_an_absolute_target_replaces_the_scenario_s_step(short_scenario):
    run = api.simulate("pi", short_scenario, target_mmhg=90.0)
    baseline = run.record["coefficients"]["baseline_mmhg"]
    target = run.trajectory.target_mmhg
    assert np.all(target == np.float32(90.0))  # the short scenario steps at t = 0
    relative = api.simulate("pi", short_scenario).trajectory.target_mmhg
    assert relative[0] == np.float32(baseline + 20.0)


def test_a_drug_or_syringe_other_than_the_run_s_is_refused(short_scenario):
    with pytest.raises(PatientModelError, match=r"^drug norepinephrine: the loaded design"):
        api.simulate("lpv", short_scenario, drug="norepinephrine")
    with pytest.raises(PatientModelError, match=r"^concentration_ug_ml 200: patient_model paper"):
        api.simulate("pi", short_scenario, concentration_ug_ml=200.0)
    run = api.simulate("pi", short_scenario, drug="Phenylephrine", concentration_ug_ml=100.0)
    assert run.record["infusion"]["drug"] == "phenylephrine"


@pytest.mark.parametrize(
    ("kwargs", "start"),
    [
        ({"rate_hz": 3.0}, "rate_hz = 3.0: its period"),
        ({"target_mmhg": 200.0}, "target_mmhg = 200.0: must be a finite number in [50, 120] mmHg"),
        ({"weight_kg": 7.0}, "weight_kg = 7.0: must be a finite number in [30, 250] kg"),
        ({"concentration_ug_ml": 0.0}, "concentration_ug_ml = 0.0: must be a finite number in (0,"),
        ({"drug": ""}, "drug '': allowed 1 to 16 ASCII characters"),
        ({"duration_s": 0.0}, "duration_s = 0.0: must be a finite number in [1, 604800] s"),
        ({"sensitivity": 100.0}, "sensitivity = 100.0: must be a finite number in [0.05, 20]"),
    ],
)
def test_api_errors_name_the_api_argument_value_and_range(kwargs, start, short_scenario):
    for call in (api.simulate, lambda *a, **k: api.trial(*a, n_patients=1, **k)):
        with pytest.raises(ValueError) as info:
            call("pi", short_scenario, **kwargs)
        assert str(info.value).startswith(start), str(info.value)


@pytest.mark.parametrize(
    ("call", "start"),
    [
        (lambda sc: api.simulate(123, sc), "controller = 123: allowed a controller spec (str"),
        (lambda sc: api.trial(1.5, sc, n_patients=1), "controller = 1.5: allowed a controller"),
        (lambda sc: api.compare([1, 2], sc, n_patients=1), "controller = 1: allowed a controller"),
        (lambda sc: api.simulate("pi", sc, patient_seed="x"), "patient_seed = 'x': must be an"),
        (lambda sc: api.simulate("pi", sc, patient_model=3), "patient_model = 3: allowed a model"),
    ],
)
def test_a_value_of_the_wrong_type_is_a_value_error_naming_the_argument(
    call, start, short_scenario
):
    with pytest.raises(ValueError) as info:
        call(short_scenario)
    assert str(info.value).startswith(start), str(info.value)


def test_an_unusable_scheduler_is_named_as_the_api_argument(short_scenario):
    with pytest.raises(BackendError, match=r"^scheduler 'bogus://x': not a Dask scheduler address"):
        api.trial("pi", short_scenario, n_patients=1, scheduler="bogus://x")


def test_a_controller_that_raises_is_named_as_the_api_argument(short_scenario):
    for call in (
        lambda: api.simulate(RAISES, short_scenario),
        lambda: api.trial(RAISES, short_scenario, n_patients=1),
    ):
        with pytest.raises(ControllerError) as info:
            call()
        text = str(info.value)
        assert text.startswith(f"controller {RAISES!r}, patient seed"), text
        assert "--" not in text
