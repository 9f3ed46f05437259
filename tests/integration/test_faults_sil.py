"""``pressor sil --fault ...`` end to end over a pty: every fault class detected within its bound,
safe state entered with an alarm, bumpless re-entry, commands always in range, and all of it in
the recording."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pressor.link import DROP_CAUSES
from pressor.runtime.core.supervisor_config import Fault, State, SupervisorConfig
from tests.support.sil_helpers import rrd_columns

REENTRY_STEP = SupervisorConfig().reentry_step_ml_h
LINK_SENSOR = [
    "link-flip:40,5",
    "link-drop:80,5",
    "link-stall:120",
    "link-disconnect:160",
    "link-garbage:200,3",
    "link-duplicate:240,5",
    "sensor-nan:280",
    "sensor-flatline:320",
    "sensor-flush:360",
    "sensor-damped:400,20",
    "sensor-disconnect:440",
    "sensor-range:480",
]
PUMP_SCHED = [
    # At the start, where the command moves from 0 to the feedforward's share: with the shipped
    # prefilter the command then sits at a constant 108 ml/h for ~90 s on this patient, and a pump
    # stuck at the commanded rate is neither detectable nor harmful.
    "pump-ignore:0,10",
    "pump-occlusion:60,10",
    "pump-empty:100,10",
    "pump-mismatch:140,10",
    "sched-out-of-box:180,5",
    "sched-jump:200,5",
    "sched-missing:220,5",
]


def sil(tmp: Path, tag: str, controller: str, faults: list[str], duration: int):
    args = ["sil", "--controller", controller, "--patient-seed", "3", "--duration", str(duration)]
    args += ["--schedule", "oracle", "--scenario", "paper-tracking"]  # the device's schedule faults
    for f in faults:
        args += ["--fault", f]
    rrd, summary = tmp / f"{tag}.rrd", tmp / f"{tag}.json"
    args += ["--rrd", str(rrd), "--summary", str(summary)]
    proc = subprocess.run(
        [sys.executable, "-m", "pressor", *args],
        cwd=tmp,
        env=dict(os.environ, CI="1"),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc, rrd, json.loads(summary.read_text())


@pytest.fixture(scope="module")
def link_sensor_run(tmp_path_factory):
    return sil(tmp_path_factory.mktemp("faults"), "ls", "pi", LINK_SENSOR, 520)


@pytest.fixture(scope="module")
def pump_sched_run(tmp_path_factory):
    return sil(tmp_path_factory.mktemp("faults"), "ps", "lpv", PUMP_SCHED, 260)


def _check_run(run, kinds):
    proc, rrd, s = run
    assert s["commands_out_of_range"] == 0 and s["metrics"]["commands_out_of_range"] == 0
    assert [f["kind"] for f in s["faults"]] == kinds
    cols = rrd_columns(rrd)
    cmd = cols["/pump/command_ml_h"]
    assert all(0.0 <= v <= 120.0 for v in cmd.values())
    assert sorted(cmd) == list(range(s["ticks"]))  # every tick, silent ones included
    for f in s["faults"]:
        assert f["applicable"], f
        assert f["detected_tick"] is not None, f
        assert f["within_bound"] in (True, None), f
        assert f["latency_ticks"] <= (f["bound_ticks"] or 250), f  # pump-ignore: 25 s at most
        d = f["detected_tick"]
        assert cols["/safety/alarm"][d] == 1.0, f  # alarm raised at detection, in the recording
        bits = int(cols["/safety/faults"][d])
        assert {Fault[n] for n in f["detected_as"]} <= {b for b in Fault if b & bits}, f
        if f["safe_state_s"] > 0.0:
            # left AUTO for the documented safe state, came back bumplessly
            assert cols["/safety/state"][d] in (State.HOLD, State.FAILSAFE), f
            assert f["reentry_tick"] is not None, f
            assert f["max_reentry_step_ml_h"] <= REENTRY_STEP + 1e-9, f
    assert "fault " in proc.stdout and "commands out of [0, max]: 0" in proc.stdout
    return s


def test_link_and_sensor_faults_detected_within_one_watchdog_period(link_sensor_run):
    s = _check_run(link_sensor_run, [f.split(":")[0] for f in LINK_SENSOR])
    by = {f["kind"]: f for f in s["faults"]}
    for f in s["faults"]:
        assert f["bound_ticks"] <= 10 and f["within_bound"] is True, f  # <= 1 s at 10 Hz
    for kind in ("link-flip", "link-drop", "link-garbage", "link-duplicate"):
        assert by[kind]["safe_state_s"] == 0.0  # advisory: bad frames discarded, control goes on
    for kind in ("link-stall", "link-disconnect"):  # silence: link loss before a 3 s stale sample
        assert by[kind]["detected_as"][0] == "LINK_LOSS" and by[kind]["latency_ticks"] == 9
    stall = by["link-disconnect"]
    # disconnect 8 s > pump watchdog 5 s: FAILSAFE from detection (0.9 s in) until the inputs have
    # been good for recover_after_s; re-entry from the runtime's own held command (the pump's
    # watchdog status never re-bases it)
    assert stall["safe_state_s"] >= 8.0 - 0.9 + SupervisorConfig().recover_after_s
    for kind in ("sensor-nan", "sensor-flush", "sensor-range", "sensor-disconnect"):
        assert by[kind]["latency_ticks"] == 0
    assert s["supervisor"]["detections"]["LINK_LOSS"] >= 2


def test_the_summary_counts_what_the_runtime_dropped_by_cause(link_sensor_run):
    proc, _, s = link_sensor_run
    dropped = s["link_dropped"]
    assert list(dropped) == sorted(DROP_CAUSES)  # every cause, zero or not
    assert dropped["bad_crc"] > 0  # link-flip
    assert dropped["refused_bad_signature"] > 0  # link-duplicate: a signed frame twice is a replay
    assert dropped["duplicates"] > 0  # ticks the device resent
    # link-drop / link-duplicate: ticks resent because a frame of their first copy was lost
    assert dropped["incomplete_sched"] + dropped["incomplete_target"] > 0
    assert dropped["incomplete_status"] > 0
    # a signed peer, lockstep: nothing unsigned, nothing superseded, no tick older than the last
    assert dropped["refused_unsigned"] == dropped["stale"] == dropped["old_ticks"] == 0
    line = next(x for x in proc.stdout.splitlines() if x.startswith("link dropped: "))
    assert f"duplicates {dropped['duplicates']}" in line and "stale" not in line


def test_silent_ticks_of_a_stall_are_recorded_on_the_virtual_clock(link_sensor_run):
    _, rrd, s = link_sensor_run
    cols = rrd_columns(rrd)
    stall = next(f for f in s["faults"] if f["kind"] == "link-stall")
    k0 = stall["start_tick"]
    states = [cols["/safety/state"][k] for k in range(k0 - 1, k0 + 12)]
    assert states[0] == State.AUTO
    assert set(states[1:10]) == {State.AUTO}  # the held sample is within the 3 s age limit
    assert states[10] == State.FAILSAFE  # LINK_LOSS after 1 s
    assert all(np.isnan(cols["/patient/map_mmhg"][k]) for k in range(k0, k0 + 30))


def test_pump_and_sched_faults_with_the_scheduled_controller(pump_sched_run):
    s = _check_run(pump_sched_run, [f.split(":")[0] for f in PUMP_SCHED])
    by = {f["kind"]: f for f in s["faults"]}
    assert by["pump-occlusion"]["latency_ticks"] == 1 and by["pump-empty"]["latency_ticks"] == 1
    assert by["pump-mismatch"]["within_bound"] is True
    assert by["sched-missing"]["safe_state_s"] > 0.0  # hard fault: HOLD
    assert by["sched-out-of-box"]["safe_state_s"] == 0.0  # advisory: the controller clamps


def test_faulted_sil_run_repeats_its_trajectory_and_fault_table(tmp_path, pump_sched_run):
    _, rrd0, s0 = pump_sched_run
    _, rrd1, s1 = sil(tmp_path, "again", "lpv", PUMP_SCHED, 260)
    assert s0["faults"] == s1["faults"] and s0["metrics"] == s1["metrics"]
    a, b = rrd_columns(rrd0), rrd_columns(rrd1)
    for e in ("/patient/map_mmhg", "/pump/command_ml_h", "/safety/state"):
        np.testing.assert_array_equal(list(a[e].values()), list(b[e].values()))
