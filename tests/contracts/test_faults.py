"""Fault specifications: names, defaults, parsing, validation, scenario tables, ``pressor faults``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pressor.contracts.faults import (
    CATALOGUE,
    FAULT_KINDS,
    FaultSpecError,
    fault_report,
    parse_fault,
)
from pressor.hil_sim.devices.device import main as device_main
from pressor.hil_sim.scenarios.scenario import ScenarioError, load_scenario_file
from pressor.runtime.core.supervisor_config import Fault
from tests.support.sil_helpers import pressor

REQUIRED = (
    "link-flip link-drop link-stall link-disconnect link-garbage link-duplicate sensor-nan"
    " sensor-flatline sensor-flush sensor-damped sensor-disconnect sensor-range pump-occlusion"
    " pump-empty pump-ignore pump-mismatch sched-out-of-box sched-jump sched-missing"
).split()


def test_catalogue_has_exactly_the_required_fault_names():
    assert list(FAULT_KINDS) == REQUIRED


@pytest.mark.parametrize("kind", REQUIRED)
def test_kind_alone_parses_with_documented_defaults(kind):
    spec = parse_fault(kind)
    info = CATALOGUE[kind]
    assert spec.kind == kind
    assert spec.start_s == info.default_start_s
    assert spec.duration_s == info.default_duration_s > 0.0
    assert spec.args == {p.name: p.default for p in info.params}
    assert all(name in Fault.__members__ for name in info.detected_as)


def test_key_value_and_bare_number_arguments():
    a = parse_fault("link-flip:start_s=12.5,duration_s=3,rate=0.5,seed=7")
    assert (a.start_s, a.duration_s, a.seed, a.args["rate"]) == (12.5, 3.0, 7, 0.5)
    b = parse_fault("sensor-flush:60,2")
    assert (b.start_s, b.duration_s, b.args["level_mmhg"]) == (60.0, 2.0, 300.0)
    assert parse_fault(a.to_cli()) == a  # what sil passes to the device parses back the same
    assert b.ticks(0.1) == (600, 620)


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        ("link-fizz", ["'kind'", "link-fizz", "link-flip"]),
        ("link-flip:rate=2", ["'rate'", "2", "[0, 1]"]),
        ("link-flip:rate=abc", ["'rate'", "abc"]),
        ("sensor-nan:start_s=-1", ["'start_s'", "-1"]),
        ("sensor-nan:level_mmhg=3", ["'level_mmhg'", "unknown"]),
        ("link-garbage:bytes=1.5", ["'bytes'", "integer"]),
        ("sensor-nan:1,2,3", ["'args'", "two bare numbers"]),
        ("pump-mismatch:factor=nan", ["'factor'", "nan"]),
    ],
)
def test_bad_fault_spec_names_field_value_and_range(text, needles):
    with pytest.raises(FaultSpecError) as err:
        parse_fault(text)
    msg = str(err.value)
    assert "\n" not in msg and "--fault" in msg
    for n in needles:
        assert n in msg


def test_sil_with_a_bad_fault_exits_2_with_one_line_and_writes_nothing(tmp_path):
    proc = pressor(
        "sil", "--controller", "pi", "--fault", "sensor-flush:level_mmhg=900", cwd=tmp_path
    )
    assert proc.returncode == 2
    line = proc.stderr.strip()
    assert len(line.splitlines()) == 1 and "level_mmhg" in line and "900" in line
    assert "[-50, 400]" in line
    assert list(tmp_path.iterdir()) == []


def test_device_with_a_bad_fault_exits_2_naming_it(capsys):
    rc = device_main("device", ["--port", "loop://", "--fault", "pump-empty:duration_s=x"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "duration_s" in err and len(err.splitlines()) == 1


def test_faults_command_lists_every_kind_with_defaults_bound_and_safe_state(tmp_path):
    proc = pressor("faults", cwd=tmp_path)
    assert proc.returncode == 0
    out = proc.stdout
    for kind in REQUIRED:
        assert f"  {kind}\n" in out
    assert "rate=0.01" in out and "level_mmhg=300" in out and "duration_s=3" in out
    assert out.count("detect:") == len(REQUIRED) and out.count("safe:") == len(REQUIRED)
    for name in ("LINK_ERRORS", "PUMP_ALARM", "PUMP_MISMATCH", "LINK_LOSS"):
        assert name in out


BASE = """
name = "faulted"
duration_s = 100.0
[patient]
mode = "nonlinear"
[target]
step_mmhg = 10.0
"""


def test_scenario_faults_table_loads_and_a_bad_one_names_file_index_and_field(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text(
        BASE + '[[faults]]\nkind = "sensor-nan"\nstart_s = 10.0\nduration_s = 2.0\n'
        '[[faults]]\nkind = "link-flip"\nrate = 0.2\n'
    )
    sc = load_scenario_file(good)
    assert [f.kind for f in sc.faults] == ["sensor-nan", "link-flip"]
    assert sc.faults[0].start_s == 10.0 and sc.faults[1].args["rate"] == 0.2
    bad = tmp_path / "bad.toml"
    bad.write_text(BASE + '[[faults]]\nkind = "sensor-range"\nvalue_mmhg = 5000\n')
    with pytest.raises(ScenarioError) as err:
        load_scenario_file(bad)
    msg = str(err.value)
    assert str(bad) in msg and "faults[0]" in msg and "value_mmhg" in msg and "5000" in msg


def test_fault_report_scores_detection_safe_time_and_reentry_step():
    # a hand-written log: NaN fault at tick 10 for 3 ticks, HOLD 10-14, RECOVERING 15-16, AUTO 17
    n = 25
    state = np.ones(n, dtype=np.int64)
    state[10:15] = 2
    state[15:17] = 4
    faults = np.zeros(n, dtype=np.int64)
    faults[10:13] = int(Fault.MAP_NAN)
    cmd = np.full(n, 10.0)
    cmd[15], cmd[16], cmd[17] = 10.5, 11.0, 11.2
    traj = {"tick": np.arange(n), "state": state, "faults": faults, "command_ml_h": cmd}
    spec = parse_fault("sensor-nan:1.0,0.3")
    sched = parse_fault("sched-missing:1.0,0.3", 1)
    bits = {f.name: int(f) for f in Fault if f.name}
    rep = fault_report([spec, sched], traj, bits, 0.1, scheduled=False)
    r = rep[0]
    assert (r["start_tick"], r["detected_tick"], r["latency_ticks"]) == (10, 10, 0)
    assert r["within_bound"] is True and r["detected_as"] == ["MAP_NAN"]
    assert r["reentry_tick"] == 17 and math.isclose(r["safe_state_s"], 0.7)
    assert math.isclose(r["max_reentry_step_ml_h"], 0.5)
    assert rep[1]["applicable"] is False and rep[1]["detected_tick"] is None
