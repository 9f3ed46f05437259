"""The shipped wide-delay design (its module's currency: test_shipped_lpv_designs.py): its
artifact is the "smith-pe" family on a 200 s delay box, ``--controller lpv:wide-delay`` loads it
bound to the default syringe, and on a device-sent fit whose delay lies beyond the default
design's box it holds an out-of-class patient's step where the default design overshoots."""

from __future__ import annotations

from pathlib import Path

import pytest

from pressor.codegen import pipeline as pl
from pressor.contracts.drug import DEFAULT_BINDING, binding_of
from pressor.hil_sim.patients.pkpd import IndependentPatient, draw_patient
from pressor.runtime.inputs.controller_loader import (
    LPV_DESIGNS,
    ControllerSpecError,
    controller_name,
    load_controller,
)
from pressor.synthesis.artifact import load_artifact
from research.schedule_sources import run_one
from research.step_fit import CONCENTRATION_UG_ML, STEP_S, step_response_fit

ARTIFACT = Path(pl.REPO_ROOT) / "synthesis" / "data" / "wide_delay_design.npz"
COMMITTED = LPV_DESIGNS["wide-delay"]


def test_its_artifact_is_the_smith_pe_family_on_a_200_s_delay_box() -> None:
    artifact = load_artifact(ARTIFACT)
    assert artifact.metadata["controller"] == {"loop_gain": 3.0, "structure": "smith-pe"}
    assert artifact.metadata["box"][2] == [10.0, 200.0]  # the default design stops at 45 s


def test_lpv_wide_delay_loads_with_the_default_syringe_and_a_bad_name_lists_the_designs() -> None:
    c = load_controller("lpv:wide-delay", artifact_sha256=pl.load_design(ARTIFACT).sha256)
    assert binding_of(c) == DEFAULT_BINDING
    assert controller_name("lpv:wide-delay") == "lpv:wide-delay"
    with pytest.raises(ControllerSpecError, match="lpv:wide-delay"):
        load_controller("lpv:wide")


def test_on_a_fit_with_a_long_delay_the_wide_design_does_not_overshoot_where_the_default_does():
    # one-compartment patient 3 of seed 2026: its 10 min step fit is K 0.93, T 290 s, tau 108 s
    params = draw_patient(2026, 3, "one-compartment")
    target = params.baseline_mmhg + 15.0
    fit = step_response_fit(params, target)
    assert fit[2] > 45.0  # beyond the default design's delay box

    def run(spec: str) -> dict:
        patient = IndependentPatient(params, STEP_S, CONCENTRATION_UG_ML, disturbances=False)
        return run_one(patient, spec, "stepfit", target, 1200.0, 1, [], fit)

    wide, default = run("lpv:wide-delay"), run("lpv")
    assert default["os"] > 20.0
    assert wide["os"] < 2.0
    assert wide["iae"] < default["iae"]
    assert wide["HOLD/FAILSAFE"] == 0 and wide["SCHED_RATE"] == 0
