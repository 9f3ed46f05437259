"""``pressor run`` with a plugin controller that fails, as real processes over real ttys: the run
goes on, the commands after the failure are the HOLD rate (the last command, held), the device
sees them as INFUSION_COMMAND frames with mode SAFE, and the failure is in the summary, on stderr
and in the recording; the clinician's ``ack`` resumes the controller. ``pressor sil`` with the
same plugin still stops with exit 1: tests/integration/test_controller_plugins_sil.py."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pressor.link import MODE_AUTO, MODE_SAFE, read_tlog
from pressor.link.dialect import pressor as mavlink
from tests.support.scripted_run import recorded_events, run_against_device
from tests.support.sil_helpers import ROOT, bridged_ttys, pressor, rrd_columns

PLUGINS = str(Path(__file__).resolve().parents[1] / "support" / "controller_plugins.py")
#: the plugin's 50th step is tick 49 (AUTO from tick 0)
FAULT_TICK = 49


def _commands(tlog: Path) -> dict[int, tuple[float, int]]:
    """tick -> (rate ml/h, mode) of every INFUSION_COMMAND frame in the device's tlog."""
    mav = mavlink.MAVLink(None)
    out = {}
    for _, frame in read_tlog(tlog):
        msg = mav.decode(bytearray(frame))
        if msg.get_type() == "INFUSION_COMMAND":
            out[msg.tick] = (msg.rate_ml_h, msg.mode)
    return out


@pytest.mark.parametrize(
    ("how", "fault", "cause"),
    [
        ("raise", "CONTROLLER_FAULT", "ZeroDivisionError('plugin bug')"),
        ("nan", "COMMAND_INVALID", "returned nan"),
    ],
)
def test_run_holds_on_a_failing_plugin_and_the_device_sees_the_held_rate_in_safe_mode(
    tmp_path, how, fault, cause
):
    tlog, summary_path, rrd = tmp_path / "device.tlog", tmp_path / "s.json", tmp_path / "run.rrd"
    with bridged_ttys() as (device_port, runtime_port):
        device = subprocess.Popen(
            [sys.executable, "-m", "pressor", "device", "--port", device_port, "--no-signing"]
            + ["--duration", "20", "--patient-seed", "4", "--tlog", str(tlog)],
            cwd=ROOT,
            env=dict(os.environ, PYTHONPATH=str(ROOT), CI="1"),
            stderr=subprocess.DEVNULL,
        )
        try:
            proc = pressor(
                "run", "--port", runtime_port, "--no-signing",
                "--controller", f"{PLUGINS}:FailsAt:at=50,how={how}",
                "--summary", str(summary_path), "--rrd", str(rrd),
                cwd=tmp_path,
            )  # fmt: skip
        finally:
            assert device.wait(timeout=60) == 0
    assert proc.returncode == 1, proc.stderr  # the run completed; the controller failed
    summary = json.loads(summary_path.read_text())
    assert summary["ticks"] == 200 and summary["ended"] in ("completed", "device finished")

    # the device side: real MAVLink frames as the device received them
    sent = _commands(tlog)
    assert sorted(sent) == list(range(200))
    held = sent[FAULT_TICK - 1][0]
    assert held > 1.0  # the PI's own rate, not a constant the test could match by chance
    assert {sent[k][1] for k in range(FAULT_TICK)} == {MODE_AUTO}
    assert {sent[k] for k in range(FAULT_TICK, 200)} == {(held, MODE_SAFE)}

    sup = summary["supervisor"]
    assert sup["detections"][fault] == 1
    moves = [(t["from"], t["to"], t["faults"]) for t in sup["transitions"]]
    assert moves[1:] == [  # latched: no recovery without an ack (none: the device's target)
        ("AUTO", "HOLD", [fault]),
        ("HOLD", "FAILSAFE", [fault]),
    ]
    hold_s = sup["transitions"][2]["sim_time_s"] - sup["transitions"][1]["sim_time_s"]
    assert sup["transitions"][1]["tick"] == FAULT_TICK and hold_s == pytest.approx(10.0, abs=0.11)
    [failure] = sup["controller_faults"]
    assert (failure["tick"], failure["fault"], failure["state"]) == (FAULT_TICK, fault, "HOLD")
    assert np.float32(failure["command_ml_h"]) == np.float32(held)
    assert "controller 'FailsAt'" in failure["error"] and cause in failure["error"]

    lines = [ln for ln in proc.stderr.splitlines() if fault in ln or "failed" in ln]
    assert len(lines) == 2, proc.stderr  # once when it failed, once at the end
    assert lines[0].startswith(f"pressor run: {fault}: {failure['error']}; HOLD at ")
    assert lines[0].endswith(
        " ml/h for the rest of the run (no acknowledgement input:"
        " --target-stdin or --target-file gives one)"
    )
    assert lines[1].startswith("pressor run: the controller failed 1 time(s), first at tick 49")
    events = recorded_events(rrd)
    assert (FAULT_TICK, lines[0].removeprefix("pressor run: ")) in events
    alarm = rrd_columns(rrd)["/safety/alarm"]
    assert [alarm[k] for k in range(FAULT_TICK, 200)] == [1.0] * (200 - FAULT_TICK)


def test_run_resumes_a_failed_plugin_on_the_clinicians_ack_through_recovering(tmp_path):
    def before_tick(k: int, run: subprocess.Popen) -> None:
        if k == 60:
            run.stdin.write("ack\n")
            run.stdin.flush()

    rc, output, summary, rrd = run_against_device(
        tmp_path,
        ["--controller", f"{PLUGINS}:FailsAt:at=50,once=True", "--target-mmhg", "70"]
        + ["--target-stdin"],
        120,
        before_tick=before_tick,
    )
    assert rc == 1, output
    [ack] = summary["target"]["acks"]
    assert (ack["tick"], ack["state"], ack["accepted"]) == (60, "HOLD", True)
    assert ack["outcome"] == (
        "HOLD -> RECOVERING, resuming automatic control (CONTROLLER_FAULT acknowledged)"
    )
    moves = [(t["tick"], t["from"], t["to"]) for t in summary["supervisor"]["transitions"]]
    assert moves[1:3] == [(FAULT_TICK, "AUTO", "HOLD"), (60, "HOLD", "RECOVERING")]
    assert moves[3][1:] == ("RECOVERING", "AUTO")
    [line] = [ln for ln in output.splitlines() if "CONTROLLER_FAULT: controller" in ln]
    assert line.endswith(" ml/h until the clinician acknowledges (ack)")
    commands = rrd_columns(rrd)["/pump/command_ml_h"]
    held = commands[FAULT_TICK - 1]
    assert [commands[k] for k in range(FAULT_TICK, 60)] == [held] * (60 - FAULT_TICK)
    assert commands[60] != held  # the controller runs again (the slew moves the command)
    assert abs(commands[60] - held) <= 0.5 + 1e-9
