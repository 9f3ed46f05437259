"""The front door's SIL orchestration (pressor.sil): configuration from the simulator's scenario
API and the device process's command line. End-to-end runs are in tests/integration/test_sil.py."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from pressor.hil_sim.scenarios.scenario import SCENARIO_DIR, load_scenario
from pressor.plumbing.usage import UsageError
from pressor.sil import device_command, sil_config


def test_scenario_events_and_faults_come_from_the_simulators_scenario(tmp_path: Path):
    scenario = tmp_path / "s.toml"
    text = (SCENARIO_DIR / "paper-disturbance.toml").read_text()
    text += '\n[[faults]]\nkind = "sensor-flush"\nstart_s = 600.0\n'
    scenario.write_text(text)
    cfg = sil_config(
        ["--controller", "pi", "--scenario", str(scenario), "--fault", "pump-empty:100"]
    )
    assert cfg.events == (("hemorrhage", 1200.0), ("bolus", 2100.0))
    assert [(f.kind, f.start_s) for f in cfg.run.fault_specs] == [
        ("pump-empty", 100.0),  # the command line's first, then the scenario's
        ("sensor-flush", 600.0),
    ]
    assert cfg.run.faults == ("pump-empty:100",)  # only these are passed on to the device
    assert load_scenario(str(scenario)).faults == cfg.run.fault_specs[1:]
    assert cfg.run.rrd == Path("pressor_sil_pi_s_seed1.rrd")  # a scenario file: its stem


def test_sil_runs_the_scenarios_duration_unless_duration_is_given():
    assert load_scenario("paper-disturbance").duration_s == 3600.0
    assert sil_config(["--scenario", "paper-disturbance"]).duration_s == 3600.0
    assert sil_config(["--scenario", "paper-disturbance", "--duration", "60"]).duration_s == 60.0
    cfg = sil_config(["--scenario", "paper-disturbance"])
    cmd = device_command(cfg, "/dev/null", None, None)
    assert (
        cmd[cmd.index("--duration") + 1] == "3600.0"
    )  # the bolus at 2100 s happens in sil as in trial


def test_default_recording_name_names_controller_scenario_and_seed():
    cfg = sil_config(["--controller", "pi", "--patient-seed", "7"])
    assert cfg.run.rrd == Path("pressor_sil_pi_paper-disturbance_seed7.rrd")
    assert (cfg.scenario, cfg.duration_s, cfg.link, cfg.signed) == (
        "paper-disturbance",
        load_scenario("paper-disturbance").duration_s,
        "pty",
        True,
    )


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--scenario", "no-such"], "'no-such' must be one of"),
        (["--link", "/dev/ttyS9"], "--link /dev/ttyS9"),
        (["--patient-seed", "-1"], "--patient-seed = -1: must be an integer in [0, 4294967295]"),
        (["--duration", "0"], "--duration = 0.0: must be a finite number in (0, 604800]"),
        (["--patient-model", "nope"], "--patient-model 'nope': unknown model; one of paper,"),
        (
            ["--patient-model", "pressor.hil_sim.devices.pump:Pump"],
            "class 'Pump' of module 'pressor.hil_sim.devices.pump'",
        ),
        (["--scenario", "nominal-step", "--patient-model", "pkpd"], "fixes a frozen first-order"),
    ],
)
def test_bad_sil_input_is_a_usage_error_before_any_device_starts(argv, needle):
    with pytest.raises(UsageError) as info:
        sil_config(["--controller", "pi", *argv])
    assert needle in str(info.value)


def test_device_command_carries_scenario_seed_duration_rate_faults_cpu_and_key(tmp_path):
    cfg = sil_config(
        ["--controller", "pi", "--patient-seed", "3", "--duration", "60", "--fault", "link-drop:10"]
    )
    key = tmp_path / "k"
    cmd = device_command(cfg, "/dev/pts/9", 1, key)
    assert cmd[:4] == [sys.executable, "-m", "pressor", "device"]
    args = cmd[4:]
    pairs = dict(zip(args[::2], args[1::2], strict=False))
    assert pairs["--port"] == "/dev/pts/9" and pairs["--scenario"] == "paper-disturbance"
    assert pairs["--patient-seed"] == "3" and pairs["--duration"] == "60.0"
    assert pairs["--rate"] == "10.0" and pairs["--cpu"] == "1"
    assert args[args.index("--fault") + 1] == "link-drop:10"
    assert args[args.index("--retransmit") + 1] == "0.05"  # link faults: fast resend
    assert args[-2:] == ["--signing-key", str(key)]
    plain = device_command(sil_config(["--controller", "pi"]), "/dev/pts/9", None, None)
    assert not {"--cpu", "--retransmit", "--signing-key", "--fault"} & set(plain)
    assert plain[-1] == "--no-signing"  # an unsigned sil run: the device must not sign either


def test_the_device_plays_the_patient_model_sil_names_and_only_a_named_one_is_passed():
    cfg = sil_config(["--controller", "pi", "--patient-model", "phenylephrine-2c"])
    assert cfg.patient_model == "phenylephrine-2c"
    cmd = device_command(cfg, "/dev/pts/9", None, None)
    assert cmd[-2:] == ["--patient-model", "phenylephrine-2c"]
    default = sil_config(["--controller", "pi"])
    assert default.patient_model == "paper"
    assert "--patient-model" not in device_command(default, "/dev/pts/9", None, None)


def test_relative_scenario_path_reaches_the_device_as_an_absolute_path(tmp_path, monkeypatch):
    (tmp_path / "sc").mkdir()
    (tmp_path / "sc" / "mine.toml").write_text((SCENARIO_DIR / "paper-tracking.toml").read_text())
    monkeypatch.chdir(tmp_path)
    cfg = sil_config(["--controller", "pi", "--scenario", "sc/mine.toml"])
    assert cfg.scenario == str(tmp_path / "sc" / "mine.toml")
    assert cfg.run.rrd == Path("pressor_sil_pi_mine_seed1.rrd")
    cmd = device_command(cfg, "/dev/null", None, None)
    assert cmd[cmd.index("--scenario") + 1] == str(tmp_path / "sc" / "mine.toml")
    with pytest.raises(UsageError, match="nope.toml"):
        sil_config(["--controller", "pi", "--scenario", "sc/nope.toml"])
