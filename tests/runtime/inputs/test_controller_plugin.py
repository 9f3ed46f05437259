"""Plugin controllers (pressor.runtime.inputs.controller_plugin): loading, the protocol check's messages,
entry points, supervision in-process (clamp, alarm, a raising controller) and byte-identical
trials."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pressor import api
from pressor.runtime.core.closed_loop import ControllerError
from pressor.runtime.core.supervisor_config import Fault, State
from pressor.runtime.inputs.controller_loader import (
    ControllerSpecError,
    controller_name,
    load_controller,
)
from pressor.runtime.inputs.controller_plugin import refresh_entry_points, split_controller_list

SUPPORT = Path(__file__).resolve().parents[2] / "support"
PLUGINS = str(SUPPORT / "controller_plugins.py")
SHORT = """
name = "short-step"
description = "2 min step for plugin tests"
duration_s = 120.0
[patient]
mode = "nonlinear"
[target]
step_mmhg = 20.0
[sensor]
noise_std_mmhg = 0.1
"""


@pytest.fixture()
def short(tmp_path: Path) -> Path:
    path = tmp_path / "short.toml"
    path.write_text(SHORT)
    return path


def test_a_plugin_loads_by_module_by_file_with_arguments_and_the_loop_period():
    c = load_controller("tests.support.controller_plugins:PlainPI:kp=0.8,ki=0.02", 0.05)
    assert (type(c).__name__, c.kp, c.ki, c.sample_period_s) == ("PlainPI", 0.8, 0.02, 0.05)
    c = load_controller(f"{PLUGINS}:PlainPI:0.1,kp=2", 0.1)  # positional period, then keyword
    assert (c.sample_period_s, c.kp) == (0.1, 2)
    assert controller_name(f"{PLUGINS}:PlainPI:kp=2") == "PlainPI"
    assert controller_name("smith:45") == "smith:45"


@pytest.mark.parametrize(
    ("cls", "needles"),
    [
        ("Missing", ["has no class 'Missing'", "controller_plugins"]),
        ("NoStatus", ["class 'NoStatus'", "does not satisfy", "reset()", "status with saturated"]),
        ("FixedPeriod", ["class 'FixedPeriod'", "sample_period_s = 1 s", "runs at 0.1 s"]),
        ("TwoArgStep", ["class 'TwoArgStep'", "step() must take (map_mmhg, target_mmhg, K, T"]),
        ("HugeMax", ["max_rate_ml_h = 1e+09 ml/h outside (0, 10000] ml/h"]),
        ("PlainPI:bogus=1", ["class 'PlainPI'", "constructor failed", "bogus"]),
    ],
)
def test_a_bad_plugin_is_refused_naming_module_class_and_what_is_missing(cls, needles):
    with pytest.raises(ControllerSpecError) as info:
        load_controller(f"tests.support.controller_plugins:{cls}", 0.1)
    for needle in needles:
        assert needle in str(info.value)
    assert "tests.support.controller_plugins" in str(info.value)


def test_an_unimportable_module_or_missing_file_is_named():
    with pytest.raises(ControllerSpecError, match="cannot import module 'no_such_mod'"):
        load_controller("no_such_mod:X", 0.1)
    with pytest.raises(ControllerSpecError, match="not found"):
        load_controller("/no/such/file.py:X", 0.1)
    with pytest.raises(ControllerSpecError, match="MODULE:CLASS"):
        load_controller("bad-name:X", 0.1)


def test_generated_modules_keep_their_integrity_check(tmp_path):
    fake = tmp_path / "fake.py"
    fake.write_text((SUPPORT / "controller_plugins.py").read_text())
    with pytest.raises(ControllerSpecError, match="MODULE_SHA256"):
        load_controller(str(fake), 0.1)  # a bare FILE.py is a generated module
    assert type(load_controller(f"{fake}:PlainPI", 0.1)).__name__ == "PlainPI"


def test_an_installed_entry_point_names_a_controller(tmp_path, monkeypatch):
    dist = tmp_path / "myctl-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: myctl\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(
        "[pressor.controllers]\nmy-pi = tests.support.controller_plugins:PlainPI\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    refresh_entry_points()
    try:
        assert load_controller("my-pi:kp=3", 0.1).kp == 3
        assert split_controller_list("lpv,my-pi:kp=1,ki=0.5,pi") == [
            "lpv",
            "my-pi:kp=1,ki=0.5",
            "pi",
        ]
    finally:
        monkeypatch.undo()
        refresh_entry_points()


def test_a_controller_list_keeps_a_plugins_arguments_together():
    specs = split_controller_list(f"lpv,{PLUGINS}:PlainPI:kp=1,ki=0.1,smith:45,pi")
    assert specs == ["lpv", f"{PLUGINS}:PlainPI:kp=1,ki=0.1", "smith:45", "pi"]


def test_a_runaway_plugin_is_clamped_and_alarmed(short):
    run = api.simulate(f"{PLUGINS}:Runaway", short, patient_seed=3, duration_s=30.0)
    tr = run.trajectory
    assert np.all(tr.command_ml_h <= 120.0) and tr.command_ml_h.max() == 120.0
    auto = tr.state == int(State.AUTO)
    assert auto.sum() > 200  # the supervisor kept the loop running, clamping every tick
    assert np.all(tr.faults[auto] & int(Fault.COMMAND_CLAMPED))
    assert run.alarm[auto].all()
    frame = run.to_pandas()
    assert frame["alarm"].sum() == run.alarm.sum() and set(frame["state"]) >= {"AUTO"}


def test_a_raising_plugin_is_a_clean_error_in_process_and_across_workers(short, capsys):
    from pressor.hil_sim.cli import main

    with pytest.raises(ControllerError, match=r"'Raises'.*tick 19.*ZeroDivisionError"):
        api.trial(f"{PLUGINS}:Raises", short, n_patients=2)
    spec = f"{PLUGINS}:Raises:at=5"
    argv = ["--controller", spec, "--patients", "3", "--jobs", "2", "--scenario", str(short)]
    assert main("trial", [*argv, "--out", str(short.parent / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert "patient seed" in err[-1] and "ZeroDivisionError('plugin bug')" in err[-1]
    assert "controller_plugins.py" in err[-1]


def test_plugin_trials_are_byte_identical_in_process_across_workers_and_the_command(
    short, tmp_path
):
    from pressor.hil_sim.cli import main

    spec = f"{PLUGINS}:PlainPI:kp=0.6"
    one = api.trial(spec, short, n_patients=4, seed=2).write(tmp_path / "api1")
    two = api.trial(spec, short, n_patients=4, seed=2, jobs=2).write(tmp_path / "api2")
    argv = ["--controller", spec, "--patients", "4", "--seed", "2", "--scenario", str(short)]
    assert main("trial", [*argv, "--jobs", "2", "--out", str(tmp_path / "cli")]) == 0
    for name in ("patients.json", "patients.csv", "summary.json"):
        ref = (one / name).read_bytes()
        assert (two / name).read_bytes() == ref
        assert (tmp_path / "cli" / name).read_bytes() == ref
    assert json.loads((one / "summary.json").read_text())["controller"] == spec


def test_api_accepts_a_class_and_to_pandas_holds_records_and_trajectories(short):
    from tests.support.controller_plugins import PlainPI

    result = api.trial(PlainPI, short, n_patients=2, controller_args={"kp": 0.6}, trajectories=True)
    assert result.controller == "tests.support.controller_plugins:PlainPI:kp=0.6"
    frame = result.to_pandas()
    assert list(frame["patient_seed"]) == [r["patient_seed"] for r in result.records]
    assert "iae_mmhg_s" in frame.columns
    long = result.to_pandas(trajectories=True)
    assert len(long) == 2 * result.trajectories["t_s"].size
    with pytest.raises(ValueError, match="n_patients = 0"):
        api.trial("pi", short, n_patients=0)
