"""The clinician's acknowledgement: the supervisor resumes from HOLD or FAILSAFE only when the
fault has cleared (pressor.runtime.core.supervisor_io), and the ``ack`` line on stdin or in the target file
reaches it (pressor.runtime.inputs.target_source). The real ``pressor run`` paths are in
tests/runtime/inputs/test_clinician.py."""

from __future__ import annotations

import io
import math
import os
from pathlib import Path

from pressor.runtime.core.supervisor_config import State, SupervisorConfig
from pressor.runtime.inputs.clinician import ClinicianInput, read_target_file, split_ack
from pressor.runtime.inputs.target_source import TargetSource
from tests.support.link_doubles import tick_inputs
from tests.support.supervisor_rig import TS, Rig


def _fail_over(rig: Rig) -> None:
    """Good, then NaN MAP for 11 s: HOLD, FAILSAFE after hold_max_s (10 s)."""
    rig.ticks(10)
    rig.ticks(110, map_mmhg=math.nan)
    assert rig.sup.state == State.FAILSAFE


def test_an_ack_while_the_fault_persists_is_refused_naming_it_and_changes_nothing():
    rig = Rig()
    _fail_over(rig)
    rig.sup.acknowledge()
    rig.tick(map_mmhg=math.nan)
    ack = rig.sup.last_ack
    assert ack is not None and not ack.accepted and ack.state == State.FAILSAFE
    assert ack.text == "refused: FAILSAFE, fault persists: MAP_NAN"
    assert rig.sup.state == State.FAILSAFE and not rig.out.run_controller
    rig.tick()  # the acknowledgement is not kept for later: one tick, one judgement
    assert rig.sup.last_ack is None and rig.sup.state == State.FAILSAFE


def test_an_ack_after_the_fault_cleared_resumes_at_once_through_recovering_to_auto():
    rig = Rig(SupervisorConfig(sample_period_s=TS, recover_after_s=5.0))
    _fail_over(rig)
    rig.ticks(3)  # good again, 0.3 s: the automatic rule would wait 5 s
    assert rig.sup.state == State.FAILSAFE
    rig.sup.acknowledge()
    rig.tick(controller_command=33.0)
    ack = rig.sup.last_ack
    assert ack.accepted and ack.text == "FAILSAFE -> RECOVERING, resuming automatic control"
    assert rig.out.transition[:2] == (State.FAILSAFE, State.RECOVERING)
    assert rig.out.run_controller and rig.out.command_ml_h == 30.5  # bumpless: 0.5 ml/h a tick
    rig.ticks(5, controller_command=33.0)
    assert rig.sup.state == State.AUTO and rig.out.command_ml_h == 33.0


def test_an_ack_with_only_an_advisory_fault_present_is_accepted():
    rig = Rig()
    _fail_over(rig)
    rig.sup.acknowledge()
    rig.tick(link_errors=3)  # LINK_ERRORS is advisory: it never holds the loop
    assert rig.sup.last_ack.accepted and rig.sup.state in (State.RECOVERING, State.AUTO)


def test_an_ack_in_auto_is_ignored():
    rig = Rig()
    rig.ticks(3)
    rig.sup.acknowledge()
    rig.tick()
    assert rig.sup.last_ack.text == "ignored: nothing to acknowledge in AUTO"
    assert rig.sup.state == State.AUTO


def test_ack_lines_are_split_from_the_target_text():
    assert split_ack("75\nack\n") == ("75", True)
    assert split_ack("  ACK \n") == ("", True)
    assert split_ack("80\n") == ("80", False)


def test_a_target_file_with_an_ack_line_still_gives_its_starting_target(tmp_path: Path):
    path = tmp_path / "target.txt"
    path.write_text("72\nack\n")
    assert read_target_file(path) == 72.0


def test_each_rewrite_of_the_target_file_with_an_ack_line_is_one_ack_but_not_the_first_read(
    tmp_path: Path,
):
    path = tmp_path / "target.txt"
    path.write_text("70\nack\n")
    err = io.StringIO()
    source = TargetSource(ClinicianInput(target_mmhg=70.0, target_file=path), err=err, stdin_fd=-1)
    source.apply(tick_inputs(0, 0.0, 60.0, target_mmhg=80.0))
    assert source.take_acks() == []  # the file as read at start acknowledges nothing
    tmp = path.with_suffix(".tmp")
    tmp.write_text("75\nack\n")
    os.replace(tmp, path)
    out = source.apply(tick_inputs(1, 0.1, 60.0, target_mmhg=80.0))
    assert out.target_mmhg == 75.0 and source.take_acks() == [f"file {path}"]
    assert source.take_acks() == []
