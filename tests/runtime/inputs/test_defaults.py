"""The runs' shared defaults: each drug's cautious design, and the warning for any run whose first
doses are sized for a typical patient instead (runtime/inputs/defaults.py)."""

from __future__ import annotations

import pytest

from pressor.runtime.inputs.controller_loader import load_controller
from pressor.runtime.inputs.defaults import DESIGN_FOR_DRUG, caution_warning, default_schedule


@pytest.mark.parametrize(
    ("spec", "schedule"),
    [
        ("lpv", "estimated"),
        ("pi", "estimated"),
        ("smith", "nominal"),
        ("lpv:cautious", "validated"),
    ],
)
def test_a_run_off_the_cautious_start_is_warned_naming_it_and_what_starts_safe(spec, schedule):
    line = caution_warning(spec, schedule)
    assert line is not None
    assert f"--controller {spec} on --schedule {schedule} does not start cautiously" in line
    assert "lpv:cautious" in line and "lpv:norepinephrine-cautious" in line
    assert "most sensitive patient" in line


@pytest.mark.parametrize("schedule", ["cautious", "oracle"])
def test_the_cautious_start_and_the_research_oracle_are_not_warned(schedule):
    assert caution_warning("lpv:cautious", schedule) is None


@pytest.mark.parametrize("drug", sorted(DESIGN_FOR_DRUG))
def test_each_drugs_default_design_defaults_to_the_cautious_start_and_is_not_warned(drug):
    spec = DESIGN_FOR_DRUG[drug]
    schedule = default_schedule(load_controller(spec, 0.1))
    assert schedule == "cautious"
    assert caution_warning(spec, schedule) is None


def test_a_design_off_a_log_k_scale_defaults_to_the_estimate_and_is_warned():
    schedule = default_schedule(load_controller("lpv", 0.1))
    assert schedule == "estimated"
    assert caution_warning("lpv", schedule) is not None
