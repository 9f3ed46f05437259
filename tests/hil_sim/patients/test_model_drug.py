"""Each patient model's drug lives in the registry, and a design meets only its drug."""

from __future__ import annotations

import pytest

from benchmarks.sweep_plan import MODEL_CONCENTRATION_UG_ML, MODEL_DRUG
from pressor.contracts.drug import DrugBinding
from pressor.hil_sim.patients.norepinephrine import CONCENTRATION_UG_ML
from pressor.hil_sim.patients.patient_model import (
    PATIENT_MODEL_DRUGS,
    PATIENT_MODELS,
    PatientModelError,
    model_drug,
)
from pressor.hil_sim.patients.syringe import check_drug
from pressor.runtime.inputs.controller_loader import load_controller


def test_every_registry_model_names_its_drug_as_the_sweep_and_the_model_count_it():
    assert set(PATIENT_MODEL_DRUGS) == set(PATIENT_MODELS)
    for name, binding in PATIENT_MODEL_DRUGS.items():
        assert binding.name == MODEL_DRUG[name], name
        assert binding.concentration_ug_ml == MODEL_CONCENTRATION_UG_ML[binding.name], name
    assert PATIENT_MODEL_DRUGS["norepinephrine"].concentration_ug_ml == CONCENTRATION_UG_ML


def test_a_scaled_model_is_a_patient_of_its_base_model_s_drug():
    assert model_drug("norepinephrine@sensitivity=2") == DrugBinding("norepinephrine", 16.0)


def test_a_plugin_model_names_its_drug_with_class_attributes_or_none():
    assert model_drug("tests.support.patient_plugin:FirstOrderPatient") is None


@pytest.mark.parametrize(
    ("spec", "model", "design_drug"),
    [
        ("lpv", "norepinephrine", "phenylephrine"),
        ("lpv:wide-delay", "norepinephrine", "phenylephrine"),
        ("lpv:norepinephrine", "paper", "norepinephrine"),
        ("lpv:norepinephrine", "pkpd", "norepinephrine"),
    ],
)
def test_check_drug_refuses_a_design_on_another_drug_s_model(spec, model, design_drug):
    controller = load_controller(spec, sample_period_s=0.1)
    theirs = PATIENT_MODEL_DRUGS[model].name
    with pytest.raises(PatientModelError, match=f"a {design_drug} design .* a {theirs} patient"):
        check_drug(controller, spec, model)


def test_check_drug_lets_a_design_meet_its_own_drug():
    controller = load_controller("lpv:norepinephrine", sample_period_s=0.1)
    assert check_drug(controller, "lpv:norepinephrine", "norepinephrine").name == "norepinephrine"


@pytest.mark.parametrize("spec", ["pi", "smith", "smith:45"])
@pytest.mark.parametrize("model", list(PATIENT_MODELS))
def test_the_drug_agnostic_baselines_take_the_model_s_drug(spec, model):
    controller = load_controller(spec, sample_period_s=0.1)
    assert check_drug(controller, spec, model) == PATIENT_MODEL_DRUGS[model]
