"""The clinician's input on the runtime side: ``pressor run --target-*`` and the hello's syringe.

``pressor run`` runs as a real process on one end of two bridged ttys; the test drives the other
end as a scripted lockstep device (:class:`link.DeviceSession`, signed with the same key file), so
it knows exactly between which ticks a target file changes.
"""

from __future__ import annotations

import math
import os
import subprocess
from pathlib import Path

import pytest

from pressor.link import (
    LINK_LOCKSTEP,
    REFUSAL_CONCENTRATION,
    REFUSAL_DRUG,
    DeviceSession,
    Hello,
    PeerRefused,
    Signing,
    open_port,
)
from tests.support.scripted_run import (
    DEVICE_TARGET,
    SYRINGE,
    TS,
    new_key,
    recorded_events,
    run_against_device,
    start_run,
)
from tests.support.sil_helpers import bridged_ttys, pressor, rrd_columns


def test_run_target_mmhg_wins_over_the_device_target_in_summary_and_recording(tmp_path):
    # a pump that can deliver more than the controller's 120 ml/h is fine
    syringe = {**SYRINGE, "pump_max_ml_h": 200.0}
    rc, output, summary, rrd = run_against_device(
        tmp_path, ["--target-mmhg", "70"], 30, syringe=syringe
    )
    assert rc == 0, output
    assert summary["target"] == {
        "source": "runtime",
        "initial_mmhg": 70.0,
        "changes": [],
        "refused": 0,
        "acks": [],
    }
    assert summary["ticks"] == 30
    assert summary["syringe"] == {**syringe, "pump_max_ml_h": 200.0}  # as the device announced
    # the drug library's limits for phenylephrine at 100 ug/ml, doses beside ml/h
    assert summary["dose"]["unit"] == "ug/min" and summary["dose"]["hard_max_ml_h"] == 120.0
    assert summary["dose"]["max_command_ug_min"] == summary["dose"]["max_command_ml_h"] * 100 / 60
    recorded = rrd_columns(rrd)["/controller/target_mmhg"]
    assert sorted(recorded) == list(range(30)) and set(recorded.values()) == {70.0}
    assert any(
        k == 0 and "target 70 mmHg from the runtime" in text and "ignored" in text
        for k, text in recorded_events(rrd)
    )


def test_run_without_target_option_uses_the_device_target_and_says_so(tmp_path):
    rc, output, summary, rrd = run_against_device(tmp_path, [], 20)
    assert rc == 0, output
    assert summary["target"] == {"source": "device"}
    assert "target: the device's MAP_TARGET" in output.splitlines()
    assert set(rrd_columns(rrd)["/controller/target_mmhg"].values()) == {DEVICE_TARGET}


def test_run_target_mmhg_needs_no_map_target_from_the_device(tmp_path):
    rc, output, summary, rrd = run_against_device(
        tmp_path, ["--target-mmhg", "75"], 20, send_target=False
    )
    assert rc == 0, output  # without its own target the runtime would wait for MAP_TARGET forever
    assert summary["ticks"] == 20 and summary["ended"] == "completed"
    assert set(rrd_columns(rrd)["/controller/target_mmhg"].values()) == {75.0}


def _replace_file(path: Path, text: str) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def test_a_target_file_change_is_applied_at_the_next_tick_recorded_and_listed(tmp_path):
    target = tmp_path / "target.txt"
    target.write_text("70\n")
    script = {5: "abc\n", 10: "90\n"}  # written after tick k-1 was answered, before tick k

    def before_tick(k: int, _run: subprocess.Popen) -> None:
        if k in script:
            _replace_file(target, script[k])

    rc, output, summary, rrd = run_against_device(
        tmp_path, ["--target-file", str(target)], 20, before_tick=before_tick
    )
    assert rc == 0, output
    assert summary["target"] == {
        "source": "runtime",
        "initial_mmhg": 70.0,
        "changes": [
            {
                "tick": 10,
                "sim_time_s": pytest.approx(1.0),
                "old_mmhg": 70.0,
                "new_mmhg": 90.0,
                "from": f"file {target}",
            }
        ],
        "refused": 1,
        "acks": [],
    }
    [refusal] = [line for line in output.splitlines() if line.startswith("pressor run: target")]
    assert refusal.startswith(f"pressor run: target from file {target} refused: 'abc'")
    assert "keeping 70 mmHg" in refusal
    assert "target: the runtime's, 70 mmHg; at 1 s 70 -> 90 mmHg; 1 refused" in output.splitlines()
    recorded = rrd_columns(rrd)["/controller/target_mmhg"]
    assert [recorded[k] for k in range(20)] == [70.0] * 10 + [90.0] * 10
    events = recorded_events(rrd)
    assert (10, f"target 70 -> 90 mmHg (file {target})") in events
    assert any(k == 5 and "refused" in text for k, text in events)


def test_a_stdin_line_changes_the_target_at_the_next_tick(tmp_path):
    def before_tick(k: int, run: subprocess.Popen) -> None:
        if k == 7:
            run.stdin.write("65\n")
            run.stdin.flush()

    rc, output, summary, rrd = run_against_device(
        tmp_path, ["--target-mmhg", "70", "--target-stdin"], 15, before_tick=before_tick
    )
    assert rc == 0, output
    [change] = summary["target"]["changes"]
    assert (change["tick"], change["old_mmhg"], change["new_mmhg"]) == (7, 70.0, 65.0)
    assert change["from"] == "stdin"
    recorded = rrd_columns(rrd)["/controller/target_mmhg"]
    assert [recorded[k] for k in range(15)] == [70.0] * 7 + [65.0] * 8


@pytest.mark.parametrize(
    ("syringe", "reason", "line"),
    [
        (
            {"drug": "norepinephrine", "concentration_ug_ml": 16.0},
            REFUSAL_DRUG,
            "device drug norepinephrine differs from the loaded design's phenylephrine",
        ),
        (
            {"concentration_ug_ml": 50.0},
            REFUSAL_CONCENTRATION,
            "device concentration 50 ug/ml differs from the loaded design's 100 ug/ml",
        ),
    ],
)
def test_a_phenylephrine_design_refuses_another_drug_or_syringe_telling_the_device(
    tmp_path, syringe, reason, line
):
    # the shipped LPV module is bound to phenylephrine at 100 ug/ml (its DRUG constants); the
    # device is told why. Every refusal kind against a device written from the document:
    # tests/integration/test_protocol_device.py
    key = new_key(tmp_path)
    with bridged_ttys() as (device_port, runtime_port):
        run = start_run(runtime_port, key, tmp_path, "--controller", "lpv")
        try:
            ep = DeviceSession(open_port(device_port), signing=Signing.from_file(key))
            hello = Hello("scripted", 0, TS, 0.0, 10, LINK_LOCKSTEP, **{**SYRINGE, **syringe})
            with pytest.raises(PeerRefused) as refused:  # in the handshake or right after it
                ep.handshake(hello, 60.0)
                ep.wait_for_command(0, 60.0)
            _, err = run.communicate(timeout=60)
            ep.close()
        finally:
            run.kill()
    assert run.returncode == 2
    assert err.strip() == f"pressor run: {line}"
    assert (refused.value.reason, refused.value.text) == (reason, line)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--target-mmhg", "130"],
            "--target-mmhg '130' = 130.0: must be a finite number in [50, 120] mmHg",
        ),
        (
            ["--target-mmhg", "nan"],
            "--target-mmhg 'nan' = nan: must be a finite number in [50, 120] mmHg",
        ),
        (["--target-stdin"], "--target-stdin: needs a starting target"),
        (
            ["--concentration-ug-ml", "0"],
            "--concentration-ug-ml '0' = 0.0: must be a finite number in (0, 100000] ug/ml",
        ),
        (["--target-mmhg", "70", "--target-file", "t"], "--target-mmhg and --target-file"),
        (
            ["--controller", "lpv", "--drug", "norepinephrine"],
            "--drug norepinephrine: the loaded design (--controller lpv) is for phenylephrine at"
            " 100 ug/ml",
        ),
        (
            ["--controller", "lpv", "--concentration-ug-ml", "200"],
            "--concentration-ug-ml 200: the loaded design (--controller lpv) is for phenylephrine"
            " at 100 ug/ml; its gains count ml/h of that syringe",
        ),
        (["--weight-kg", "29"], "--weight-kg '29' = 29.0: must be a finite number in [30, 250] kg"),
        (
            ["--weight-kg", "inf"],
            "--weight-kg 'inf' = inf: must be a finite number in [30, 250] kg",
        ),
    ],
)
def test_bad_clinician_options_exit_2_with_one_line_naming_the_range(tmp_path, args, message):
    proc = pressor("run", "--port", str(tmp_path / "no-tty"), *args, cwd=tmp_path)
    assert proc.returncode == 2
    [line] = proc.stderr.strip().splitlines()
    assert message in line, line


def test_a_target_file_without_a_valid_target_at_start_exits_2(tmp_path):
    (tmp_path / "t").write_text("200\n")
    proc = pressor("run", "--port", "x", "--target-file", str(tmp_path / "t"), cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        f"pressor run: --target-file {tmp_path / 't'}: '200' = 200.0: must be a finite number in [50, 120] mmHg"
    )


def test_help_shows_the_clinician_options_with_defaults_and_units(tmp_path):
    run = " ".join(pressor("run", "--help", cwd=tmp_path).stdout.split())
    assert "--target-mmhg MMHG" in run and "(mmHg, allowed [50, 120])" in run
    assert "default: the device's MAP_TARGET" in run
    assert "--target-file FILE" in run and "--target-stdin" in run
    assert "the shipped one's is phenylephrine" in run and "the shipped one's is 100" in run
    assert "--weight-kg KG" in run and "(kg, allowed [30, 250])" in run
    device = " ".join(pressor("device", "--help", cwd=tmp_path).stdout.split())
    assert "--pump-max-ml-h ML_H" in device and "(ml/h, (0, 10000])" in device
    assert "120 ml/h in every shipped scenario" in device
    assert "(default: phenylephrine)" in device and "(ug/ml, default 100" in device


#: MAP NaN over ticks 20-139: HOLD at tick 20, FAILSAFE at 120 (10 s), good again from 140; the
#: automatic rule would go to RECOVERING at 190 (inputs good for 5 s)
FAULT_TICKS = range(20, 140)
#: acknowledgements written before these ticks: one while the fault persists, one after it cleared
ACK_BEFORE = (60, 143)


def _map_with_fault(k: int) -> float:
    return math.nan if k in FAULT_TICKS else 60.0 + 0.05 * k


def _assert_acks(summary: dict, output: str, rrd: Path, source: str) -> None:
    refused, accepted = summary["target"]["acks"]
    assert refused == {
        "tick": 60,
        "sim_time_s": pytest.approx(6.0),
        "from": source,
        "state": "HOLD",
        "accepted": False,
        "outcome": "refused: HOLD, fault persists: MAP_NAN",
    }
    assert accepted == {
        "tick": 143,
        "sim_time_s": pytest.approx(14.3),
        "from": source,
        "state": "FAILSAFE",
        "accepted": True,
        "outcome": "FAILSAFE -> RECOVERING, resuming automatic control",
    }
    moves = [(t["tick"], t["from"], t["to"]) for t in summary["supervisor"]["transitions"]]
    assert moves[1:4] == [
        (20, "AUTO", "HOLD"),
        (120, "HOLD", "FAILSAFE"),
        (143, "FAILSAFE", "RECOVERING"),  # the automatic rule: not before tick 190
    ]
    assert [m[1:] for m in moves[4:]] in ([], [("RECOVERING", "AUTO")])  # bumpless slew back
    assert summary["supervisor"]["ticks_in_state"]["FAILSAFE"] == 143 - 120
    lines = [line for line in output.splitlines() if line.startswith("pressor run: ack")]
    assert lines == [
        f"pressor run: ack ({source}) at 6 s, tick 60: refused: HOLD, fault persists: MAP_NAN",
        f"pressor run: ack ({source}) at 14.3 s, tick 143: FAILSAFE -> RECOVERING, resuming"
        " automatic control",
    ]
    events = recorded_events(rrd)
    assert (60, lines[0].removeprefix("pressor run: ")) in events
    assert (143, lines[1].removeprefix("pressor run: ")) in events


def test_an_ack_on_stdin_is_refused_while_the_fault_persists_and_resumes_once_it_cleared(
    tmp_path,
):
    def before_tick(k: int, run: subprocess.Popen) -> None:
        if k in ACK_BEFORE:
            run.stdin.write("ack\n")
            run.stdin.flush()

    rc, output, summary, rrd = run_against_device(
        tmp_path,
        ["--target-mmhg", "70", "--target-stdin"],
        160,
        before_tick=before_tick,
        map_at=_map_with_fault,
    )
    assert rc == 0, output
    _assert_acks(summary, output, rrd, "stdin")


def test_an_ack_line_in_the_target_file_is_refused_while_the_fault_persists_then_resumes(
    tmp_path,
):
    target = tmp_path / "target.txt"
    target.write_text("70\n")

    def before_tick(k: int, _run: subprocess.Popen) -> None:
        if k in ACK_BEFORE:
            _replace_file(target, "70\nack\n")  # the same text twice: each write is one ack

    rc, output, summary, rrd = run_against_device(
        tmp_path,
        ["--target-file", str(target)],
        160,
        before_tick=before_tick,
        map_at=_map_with_fault,
    )
    assert rc == 0, output
    assert summary["target"]["changes"] == []  # the file's target did not change
    _assert_acks(summary, output, rrd, f"file {target}")
