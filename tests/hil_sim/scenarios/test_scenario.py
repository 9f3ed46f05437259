"""Scenario files: the shipped ones load; bad ones fail with one line naming file, field, value, range."""

from __future__ import annotations

from pathlib import Path

import pytest

from pressor.hil_sim.scenarios.disturbance import Bolus, Hemorrhage
from pressor.hil_sim.scenarios.scenario import (
    ScenarioError,
    load_scenario,
    load_scenario_file,
    scenario_names,
)

GOOD = """
name = "t"
duration_s = 600.0
[patient]
mode = "nonlinear"
[target]
step_mmhg = 20.0
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(text)
    return path


def test_shipped_scenarios_load_with_their_documented_content():
    assert {"nominal-step", "paper-tracking", "paper-disturbance"} <= set(scenario_names())
    nominal = load_scenario("nominal-step")
    assert nominal.frozen is not None
    assert (nominal.frozen.K, nominal.frozen.T_s, nominal.frozen.tau_s) == (0.55, 150.0, 40.0)
    assert nominal.step_mmhg == 20.0 and not nominal.noisy
    tracking = load_scenario("paper-tracking")
    assert tracking.patient_mode == "nonlinear" and not tracking.disturbances and not tracking.noisy
    dist = load_scenario("paper-disturbance")
    assert dist.noisy
    kinds = {type(d) for d in dist.disturbances}
    assert kinds == {Hemorrhage, Bolus}


def test_minimal_file_gets_defaults(tmp_path):
    s = load_scenario_file(_write(tmp_path, GOOD))
    assert s.pump.max_rate_ml_h == 120.0 and s.sensor.period_s == 0.1 and s.internal_step_s == 0.1


@pytest.mark.parametrize(
    ("edit", "field", "fragment"),
    [
        (
            ("duration_s = 600.0", "duration_s = -5.0"),
            "duration_s",
            "= -5.0: must be a finite number in [1, 604800] s",
        ),
        (('mode = "nonlinear"', 'mode = "zombie"'), "patient.mode", "must be one of"),
        (
            ("step_mmhg = 20.0", 'step_mmhg = "20"'),
            "target.step_mmhg",
            "= '20': must be a finite number",
        ),
        (
            ("step_mmhg = 20.0", "step_mmhg = 20.0\nstep_time_s = 900.0"),
            "target.step_time_s",
            "= 900.0: must be a finite number in [0, ",
        ),
        (
            ("[target]", "[pump]\nmax_rate_ml_h = 0.0\n[target]"),
            "pump.max_rate_ml_h",
            "= 0.0: must be a finite number in (0, 10000] ml/h",
        ),
        (
            ("[target]", "[sensor]\nnoise_std_mmhg = 500\n[target]"),
            "sensor.noise_std_mmhg",
            "= 500: must be a finite number in [0, ",
        ),
        (("[target]", "[pump]\nspeed = 3\n[target]"), "pump.speed", "unknown field"),
        (('mode = "nonlinear"', 'mode = "frozen"\nK = 0.5'), "patient.T_s", "required"),
    ],
)
def test_bad_field_error_names_file_field_value_and_range(tmp_path, edit, field, fragment):
    path = _write(tmp_path, GOOD.replace(*edit))
    with pytest.raises(ScenarioError) as info:
        load_scenario_file(path)
    msg = str(info.value)
    assert msg.startswith(str(path)) and f"field '{field}'" in msg and fragment in msg
    assert "\n" not in msg


def test_bad_disturbance_and_artifact_entries_are_named_by_index(tmp_path):
    text = (
        GOOD
        + '[[disturbances]]\nkind = "hemorrhage"\nstart_s = 1.0\nramp_s = 1.0\ndepth_mmhg = 500.0\n'
    )
    with pytest.raises(
        ScenarioError,
        match=r"field 'disturbances\[0\]\.depth_mmhg' = 500.0: must be a finite number in \[0, ",
    ):
        load_scenario_file(_write(tmp_path, text))
    text = GOOD + '[[sensor.artifacts]]\nkind = "sparkle"\nstart_s = 1.0\nduration_s = 1.0\n'
    with pytest.raises(ScenarioError, match=r"sensor\.artifacts\[0\]\.kind' = 'sparkle'"):
        load_scenario_file(_write(tmp_path, text))


def test_invalid_toml_and_missing_file_and_unknown_name(tmp_path):
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario_file(_write(tmp_path, "name = "))
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario_file(tmp_path / "missing.toml")
    with pytest.raises(ScenarioError, match="must be one of"):
        load_scenario("not-a-scenario")


def test_the_example_in_docs_scenarios_is_a_valid_scenario():
    import re
    import tomllib

    from pressor.hil_sim.scenarios.scenario import parse_scenario

    doc = (Path(__file__).resolve().parents[3] / "docs" / "SCENARIOS.md").read_text()
    example = re.search(r"```toml\n(.*?)```", doc, re.S)
    assert example is not None
    sc = parse_scenario(tomllib.loads(example.group(1)), "docs/SCENARIOS.md")
    assert sc.sensor.period_s == 1.0 and sc.sensor.quantum_mmhg == 1.0
    assert [d.kind for d in sc.disturbances] == ["hemorrhage"]
    assert [f.kind for f in sc.faults] == ["sensor-flush"]
