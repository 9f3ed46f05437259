"""The researcher's surface: a paired comparison from Python, and errors in the API's terms."""

from __future__ import annotations

from pathlib import Path

import pytest

from pressor import api
from pressor.hil_sim.cli import main as cli_main
from pressor.runtime.inputs.controller_loader import ControllerSpecError


def test_compare_writes_the_same_comparison_and_records_as_pressor_trial(
    tmp_path: Path, short_scenario: Path
):
    result = api.compare("pi,smith", short_scenario, n_patients=3, seed=1)
    assert result.controllers == ("pi", "smith")
    assert set(result.trials) == {"pi", "smith"}
    assert all(isinstance(t, api.TrialResult) for t in result.trials.values())
    assert list(result.comparison) == ["pi vs smith"]
    written = result.write(tmp_path / "api")

    cli_out = tmp_path / "cli"
    argv = ["--controller", "pi,smith", "--patients", "3", "--seed", "1"]
    assert cli_main("trial", argv + ["--scenario", str(short_scenario), "--out", str(cli_out)]) == 0
    for rel in ("comparison.json", "pi/patients.json", "smith/summary.json", "pi/patients.csv"):
        assert (written / rel).read_bytes() == (cli_out / rel).read_bytes(), rel


def test_compare_accepts_a_list_and_pairs_the_first_controller_with_each_other(short_scenario):
    result = api.compare(["smith", "pi"], short_scenario, n_patients=1, seed=2)
    assert list(result.comparison) == ["smith vs pi"]
    assert (
        result.trials["pi"].records[0]["patient_seed"]
        == (result.trials["smith"].records[0]["patient_seed"])
    )


@pytest.mark.parametrize("controllers", [["pi"], ["pi", "pi"], "pi"])
def test_compare_refuses_fewer_than_two_distinct_controllers(controllers, short_scenario):
    with pytest.raises(ValueError, match="two or more controllers, each once"):
        api.compare(controllers, short_scenario, n_patients=1)


def test_compare_checks_every_controller_before_running_any(short_scenario):
    with pytest.raises(ControllerSpecError, match="^controller 'nosuch'"):
        api.compare(["pi", "nosuch"], short_scenario, n_patients=1)


def test_trial_with_a_controller_list_points_to_compare(short_scenario):
    with pytest.raises(ValueError, match=r"names several controllers: compare\(\[\.\.\.\]\)"):
        api.trial("lpv,pi", short_scenario, n_patients=1)


@pytest.mark.parametrize(
    ("kwargs", "argument"),
    [
        ({"controller": "nosuch"}, "controller"),
        ({"scenario": "nosuch"}, "scenario"),
        ({"patient_model": "nosuch"}, "patient_model"),
    ],
)
def test_api_errors_name_the_api_argument_not_a_command_line_flag(kwargs, argument):
    with pytest.raises(ValueError) as info:
        api.trial(**{"n_patients": 1, **kwargs})
    text = str(info.value)
    assert "--" not in text.split(":")[0] and argument in text, text
    with pytest.raises(type(info.value)):  # the same type as before: callers catching it still do
        api.simulate(**{k: v for k, v in kwargs.items()})
