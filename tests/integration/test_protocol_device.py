"""A device written from docs/PROTOCOL.md alone (tests/support/protocol_device.py and its
bedside, tests/support/protocol_device_bedside.py) drives the real ``pressor run`` over a real pty,
signed, in both link modes."""

from __future__ import annotations

import ast
import math
import os
import subprocess
import sys
import time
import tty
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import pytest

from tests.support.protocol_device import (
    DeviceConfig,
    DeviceLog,
    ProtocolDevice,
    read_key,
)
from tests.support.protocol_harness import wait_for_port_open, write_key

ROOT = Path(__file__).resolve().parents[2]
TS_S = 0.1  # the device's sample period = 1 / pressor run's default --rate (s)
TARGET_MMHG = 70.0
MAX_RATE_ML_H = 120.0  # the controllers' default maximum (docs/PROTOCOL.md, INFUSION_COMMAND)
#: the project's import namespace, and its folders' bare names (importable inside a checkout)
PROJECT_PACKAGES = {
    "pressor",
    "contracts",
    "baselines",
    "link",
    "synthesis",
    "codegen",
    "runtime",
    "hil_sim",
}


@dataclass
class Run:
    """One ``pressor run`` driven by the protocol device."""

    rc: int
    stdout: str
    stderr: str
    log: DeviceLog
    after_port_open_s: float  # from the runtime opening its port to its exit (s)


def drive(
    dialect: ModuleType, tmp_path: Path, cfg: DeviceConfig, key_file: Path, *run_args: str
) -> Run:
    """Start ``pressor run`` on a fresh pty and play ``cfg`` on the other side until both end."""
    master, slave = os.openpty()
    tty.setraw(slave)
    out, err = tmp_path / "run.out", tmp_path / "run.err"
    with out.open("w") as fout, err.open("w") as ferr:
        proc = subprocess.Popen(
            [sys.executable, "-m", "pressor", "run", "--port", os.ttyname(slave)]
            + ["--signing-key", str(key_file), *run_args],
            cwd=tmp_path,
            env=dict(os.environ, CI="1"),
            stdout=fout,
            stderr=ferr,
        )
    try:
        os.close(slave)
        wait_for_port_open(master, proc)
        opened = time.monotonic()
        device = ProtocolDevice(dialect, master, cfg, peer_gone=lambda: proc.poll() is not None)
        log = device.run()
        rc = proc.wait(timeout=30)
        elapsed_s = time.monotonic() - opened
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)
    return Run(rc, out.read_text(), err.read_text(), log, elapsed_s)


def assert_commands_auto_and_in_range(log: DeviceLog) -> None:
    """Every command is the controller's (AUTO: the supervisor never fell back) and in range."""
    assert log.commands
    modes = {mode for _, mode, _ in log.commands.values()}
    assert modes == {0}, f"command modes {modes}: the supervisor left AUTO"
    rates = [rate for rate, _, _ in log.commands.values()]
    assert all(math.isfinite(r) and 0.0 <= r <= MAX_RATE_ML_H for r in rates)


def assert_lockstep_reaches_target(run: Run, n_ticks: int) -> None:
    """A clean lockstep run: every tick answered, MAP within ±5 mmHg of target over the last 60 s."""
    assert run.rc == 0, run.stderr
    assert run.log.outcome == "finished"
    assert sorted(run.log.commands) == list(range(n_ticks))
    assert run.log.resends == 0 and run.log.refused_frames == 0
    assert_commands_auto_and_in_range(run.log)
    last_minute = run.log.true_map_mmhg[-round(60 / TS_S) :]
    assert max(abs(m - TARGET_MMHG) for m in last_minute) <= 5.0, last_minute[-1]
    assert 2 in run.log.runtime_states, "no FINISHED heartbeat from the runtime"


def imported_modules(tree: ast.Module) -> set[str]:
    """Every module an ``import`` or ``from ... import`` in ``tree`` names (a relative one: from tests.support)."""
    names = {
        alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.Import)
        for alias in node.names
    }
    return names | {
        "tests.support." * bool(node.level) + (node.module or "")
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom)
    }


def test_protocol_device_modules_import_only_the_standard_library_pymavlink_and_each_other() -> (
    None
):
    device_modules = {
        f"tests.support.{path.stem}"
        for path in (ROOT / "tests" / "support").glob("protocol_device*.py")
    }
    checked: set[str] = set()
    to_check = ["tests.support.protocol_device"]
    while to_check:
        module = to_check.pop()
        checked.add(module)
        source = (ROOT / (module.replace(".", "/") + ".py")).read_text()
        names = imported_modules(ast.parse(source))
        siblings = {name for name in names if name.split(".")[0] == "tests"}
        assert siblings <= device_modules, f"{module} imports test code {siblings}"
        to_check += sorted(siblings - checked)
        top = {name.split(".")[0] for name in names - siblings}
        assert top & PROJECT_PACKAGES == set(), f"{module} imports the project"
        assert top - {"pymavlink", "__future__"} <= sys.stdlib_module_names, (module, top)
        assert "pressor.link.dialect" not in source and "link/dialect" not in source, module
    assert checked == device_modules, "a protocol_device*.py module the device does not use"


def test_lockstep_signed_pi_with_scheduling_params_brings_map_to_target(
    dialect: ModuleType, tmp_path: Path
) -> None:
    key = write_key(tmp_path / "signing.key")
    cfg = DeviceConfig(n_ticks=4000, target_mmhg=TARGET_MMHG, key=read_key(key))
    run = drive(dialect, tmp_path, cfg, key, "--controller", "pi")
    assert_lockstep_reaches_target(run, cfg.n_ticks)
    assert run.log.runtime_hello.sample_period_s == TS_S


def test_lockstep_signed_lpv_estimated_without_scheduling_params_brings_map_to_target(
    dialect: ModuleType, tmp_path: Path
) -> None:
    key = write_key(tmp_path / "signing.key")
    cfg = DeviceConfig(
        n_ticks=3000, target_mmhg=TARGET_MMHG, send_scheduling=False, key=read_key(key)
    )
    run = drive(dialect, tmp_path, cfg, key, "--schedule", "estimated")
    assert_lockstep_reaches_target(run, cfg.n_ticks)


def test_realtime_signed_loop_keeps_up_in_auto_with_commands_in_range(
    dialect: ModuleType, tmp_path: Path
) -> None:
    key = write_key(tmp_path / "signing.key")
    cfg = DeviceConfig(realtime=True, n_ticks=100, send_scheduling=False, key=read_key(key))
    run = drive(dialect, tmp_path, cfg, key, "--realtime")
    assert run.rc == 0, run.stderr
    assert run.log.outcome == "finished"
    assert_commands_auto_and_in_range(run.log)  # no LINK_LOSS or STALE_SAMPLE fallback
    # one command per runtime period; which tick each answers depends on the two clocks' phase
    assert run.log.commands_received >= 0.8 * cfg.n_ticks
    assert len(run.log.commands) >= cfg.n_ticks // 2


#: each refusal the runtime makes: what the device announces, the reason it is told, the one line
REFUSALS = {
    "drug": (
        {"drug": "norepinephrine"},
        "DRUG",
        "device drug norepinephrine differs from the loaded design's phenylephrine",
    ),
    "concentration": (
        {"concentration_ug_ml": 40.0},
        "CONCENTRATION",
        "device concentration 40 ug/ml differs from the loaded design's 100 ug/ml",
    ),
    "pump-maximum": (
        {"pump_max_ml_h": 100.0},
        "PUMP_MAXIMUM",
        "device pump maximum 100 ml/h differs from the controller's 120 ml/h: the pump cannot"
        " deliver every rate the controller commands",
    ),
    "protocol-version": (
        {"protocol_version": 1},
        "PROTOCOL_VERSION",
        "device hello: peer protocol_version 1, expected 2",
    ),
    "role": (
        {"role": 1},
        "ROLE",
        "device hello: peer announced role 1 (runtime), expected 2 (device)",
    ),
    "system-id": (
        {"system_id": 42},
        "SYSTEM_ID",
        "device hello from MAVLink system id 42, expected 2 (the system id is the role:"
        " runtime 1, device 2)",
    ),
    "sample-period": (
        {"sample_period_s": 0.05},
        "SAMPLE_PERIOD",
        "device sample_period_s 0.05 s differs from --rate 10.0 Hz (period 0.1 s)",
    ),
    "link-mode": (
        {"realtime": True},
        "LINK_MODE",
        "device runs real time (hello link_mode 1) but this runtime runs lockstep: add --realtime",
    ),
    "sensor-noise": (
        {"noise_mmhg": 60.0},
        "SENSOR_NOISE",
        "device announces sensor_noise_mmhg 60.0: allowed [0, 50] mmHg",
    ),
}


@pytest.mark.parametrize("kind", list(REFUSALS))
def test_a_refused_device_is_told_the_reason_and_the_runtime_exits_2_with_the_same_line(
    dialect: ModuleType, tmp_path: Path, kind: str
) -> None:
    announce, reason, line = REFUSALS[kind]
    key = write_key(tmp_path / "signing.key")
    cfg = DeviceConfig(n_ticks=100, key=read_key(key), link_timeout_s=3.0, **announce)
    run = drive(dialect, tmp_path, cfg, key)
    assert run.rc == 2
    assert (run.stdout + run.stderr).strip().splitlines() == [f"pressor run: {line}"]
    assert run.log.refusal == (getattr(dialect, f"PRESSOR_REFUSAL_REASON_{reason}"), line)
    assert run.log.outcome == f"refused by the runtime: {line}" and not run.log.commands
    assert run.after_port_open_s < 5.0


@pytest.mark.parametrize(
    ("device_key", "wall_clock", "cause"),
    [
        ("other", True, "signs with another key"),
        (None, True, "unsigned"),
        ("same", False, "more than a minute old"),
    ],
    ids=["wrong-key", "unsigned", "stamps-from-zero"],
)
def test_signing_mismatch_is_refused_with_one_line_within_2_s(
    dialect: ModuleType, tmp_path: Path, device_key: str | None, wall_clock: bool, cause: str
) -> None:
    key = write_key(tmp_path / "signing.key")
    device_keys = {"other": read_key(write_key(tmp_path / "other.key")), "same": read_key(key)}
    cfg = DeviceConfig(n_ticks=100, key=device_keys.get(device_key), wall_clock_signing=wall_clock)
    run = drive(dialect, tmp_path, cfg, key)
    assert run.rc == 1
    assert run.after_port_open_s < 2.0
    assert run.log.runtime_hello is None and not run.log.commands
    lines = (run.stdout + run.stderr).strip().splitlines()
    assert len(lines) == 1 and "signing mismatch" in lines[0] and cause in lines[0], lines


def quantized_1hz(**kwargs: object) -> DeviceConfig:
    """A monitor showing integer mmHg once a second, honestly announcing 1 mmHg of noise."""
    return DeviceConfig(
        target_mmhg=TARGET_MMHG,
        send_scheduling=False,
        noise_mmhg=1.0,
        quantum_mmhg=1.0,
        monitor_period_s=1.0,
        **kwargs,
    )


def test_lockstep_1hz_quantized_monitor_holds_samples_and_reaches_target(
    dialect: ModuleType, tmp_path: Path
) -> None:
    key = write_key(tmp_path / "signing.key")
    cfg = quantized_1hz(n_ticks=9000, key=read_key(key))  # the cautious start: ~8 min
    run = drive(dialect, tmp_path, cfg, key)
    held = dialect.PRESSOR_MAP_QUALITY_HELD
    for tick, value, quality in run.log.samples:  # the device keeps to the rule it is written to
        assert quality == (0 if tick % 10 == 0 else held)
        assert value == round(value) and value == run.log.samples[tick - tick % 10][1]
    assert_lockstep_reaches_target(run, cfg.n_ticks)


@pytest.mark.slow
def test_realtime_1hz_quantized_monitor_sends_samples_on_updates_and_stays_in_auto(
    dialect: ModuleType, tmp_path: Path
) -> None:
    key = write_key(tmp_path / "signing.key")
    cfg = quantized_1hz(realtime=True, n_ticks=250, key=read_key(key))
    run = drive(dialect, tmp_path, cfg, key, "--realtime")
    assert [tick for tick, _, _ in run.log.samples] == list(range(0, cfg.n_ticks, 10))
    assert run.rc == 0, run.stderr
    assert run.log.outcome == "finished"
    assert_commands_auto_and_in_range(run.log)  # no STALE_SAMPLE between monitor updates
    assert run.log.commands_received >= cfg.n_ticks // 2  # commands keep flowing


def test_the_norepinephrine_design_runs_against_a_norepinephrine_device(
    dialect: ModuleType, tmp_path: Path
) -> None:
    """The drug binding admits the matching pair: a device announcing norepinephrine at 16 µg/ml
    (the design's syringe) runs under ``--controller lpv:norepinephrine`` (the library doses it
    per kg: ``--weight-kg`` is required) and reaches its target
    on a patient inside that design's box (K 0.1-3.2 mmHg/(ml/h), T 150-750 s, τ 20-55 s)."""
    key = write_key(tmp_path / "signing.key")
    cfg = DeviceConfig(
        n_ticks=9000,
        target_mmhg=TARGET_MMHG,
        patient=(0.8, 300.0, 30.0, 55.0),
        drug="norepinephrine",
        concentration_ug_ml=16.0,
        key=read_key(key),
    )
    args = ("--controller", "lpv:norepinephrine", "--schedule", "oracle", "--weight-kg", "70")
    run = drive(dialect, tmp_path, cfg, key, *args)
    assert_lockstep_reaches_target(run, cfg.n_ticks)
    # the summary a person reads: the drug, its syringe, the weight and the dose per kg
    assert "drug: norepinephrine 16 µg/ml; patient weight 70 kg" in run.stdout
    infusion = next(x for x in run.stdout.splitlines() if x.startswith("infusion: "))
    assert "ml/h = " in infusion and "µg/kg/min" in infusion
