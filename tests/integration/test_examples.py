"""Every file in examples/ runs (small sizes): the scripts as a user runs them, the scenario TOML
and the custom controller through ``pressor trial``."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.sil_helpers import pressor

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
#: script -> small-size arguments (every example must be listed: see the last test)
SCRIPTS = {
    "custom_controller.py": ["--patients", "2", "--duration-s", "300"],
    "trial_to_pandas.py": ["--patients", "3", "--duration-s", "300", "--out", "cohort.png"],
    "gym_random_policy.py": ["--episodes", "2", "--duration-s", "120"],
    # one tick per action: the script checks the episode against pressor trial's and fails if not
    "gym_pi_policy.py": ["--episodes", "1", "--duration-s", "120", "--ticks-per-action", "1"],
}


@pytest.mark.parametrize("script", sorted(SCRIPTS))
def test_example_script_runs(script, tmp_path):
    proc = subprocess.run(
        [sys.executable, str(EXAMPLES / script), *SCRIPTS[script]],
        cwd=tmp_path,
        env=dict(os.environ, CI="1"),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    if script == "trial_to_pandas.py":
        assert (tmp_path / "cohort.png").stat().st_size > 1000
    if script == "gym_pi_policy.py":
        assert "commands identical to pressor trial's: True" in proc.stdout


def test_example_scenario_and_controller_run_in_pressor_trial(tmp_path):
    proc = pressor(
        "trial",
        "--controller",
        f"{EXAMPLES / 'custom_controller.py'}:ScheduledPI:lambda_s=60,pi",
        "--scenario",
        str(EXAMPLES / "scenario_early_hemorrhage.toml"),
        "--patients",
        "2",
        "--out",
        "out",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    assert "early-hemorrhage" in proc.stdout and (tmp_path / "out" / "comparison.json").is_file()


def test_every_example_is_run_here():
    on_disk = {p.name for p in EXAMPLES.iterdir() if p.suffix in (".py", ".toml")}
    assert on_disk == set(SCRIPTS) | {"scenario_early_hemorrhage.toml"}
