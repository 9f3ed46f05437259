"""``pressor scenarios``: each shipped scenario with the file it lives in."""

from __future__ import annotations

from pathlib import Path

from pressor.hil_sim.cli import main
from pressor.hil_sim.scenarios.scenario import SCENARIO_DIR, load_scenario_file


def test_scenarios_shows_the_file_of_each_scenario(capsys):
    assert main("scenarios", []) == 0
    rows = [line.split(maxsplit=2) for line in capsys.readouterr().out.strip().splitlines()]
    assert {name for name, *_ in rows} >= {"paper-tracking", "paper-disturbance"}
    for name, file, _desc in rows:
        assert Path(file) == SCENARIO_DIR / f"{name}.toml"
        assert load_scenario_file(file).name == name
