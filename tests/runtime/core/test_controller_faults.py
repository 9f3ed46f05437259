"""A controller that fails, in the supervisor and the core: under ``controller_faults="latch"``
(``pressor run``) a step that raises, returns a non-number or a non-finite command holds the
last command with the alarm until the clinician acknowledges; under ``"stop"`` (``pressor sil``,
``trial``) an exception ends the run and a non-finite command recovers by itself. The real
``pressor run`` over a pty: tests/integration/test_controller_faults_run.py."""

from __future__ import annotations

import math

import pytest

from pressor.link import TickInputs
from pressor.runtime.core.closed_loop import CLEAN_LINK, ClosedLoopCore, ControllerError
from pressor.runtime.core.supervisor import Supervisor, SupervisorInput
from pressor.runtime.core.supervisor_config import Fault, State, SupervisorConfig
from pressor.runtime.inputs.controller_loader import load_controller
from tests.support.link_doubles import tick_inputs
from tests.support.supervisor_rig import TS, Rig, good_inputs

LATCH = SupervisorConfig(sample_period_s=TS, controller_faults="latch")


def _fail(rig: Rig, how: str) -> float:
    """One tick whose controller step fails: raises (``failed=True``) or returns NaN."""
    run = rig.sup.assess(SupervisorInput(**good_inputs(rig.k * TS)))
    rig.k += 1
    assert run
    rig.out = rig.sup.finalize(None, failed=True) if how == "raise" else rig.sup.finalize(math.nan)
    return rig.out.command_ml_h


@pytest.mark.parametrize(
    ("how", "bit"), [("raise", Fault.CONTROLLER_FAULT), ("nan", Fault.COMMAND_INVALID)]
)
def test_a_latched_controller_fault_holds_through_good_inputs_until_acknowledged(how, bit):
    rig = Rig(LATCH)
    rig.ticks(5, controller_command=17.5)
    assert _fail(rig, how) == 17.5  # the held rate: the last command
    assert rig.sup.state == State.HOLD and rig.out.alarm and rig.out.faults & bit
    assert rig.out.new_faults & bit
    commands = rig.ticks(80, controller_command=40.0)  # inputs good for 8 s: no self-recovery
    assert set(commands) == {17.5} and rig.sup.state == State.HOLD
    assert not rig.out.run_controller and rig.out.faults & bit and not rig.out.new_faults
    rig.ticks(25, controller_command=40.0)  # 10 s of fault: FAILSAFE, ramping to the held rate
    assert rig.sup.state == State.FAILSAFE and rig.out.command_ml_h == 17.5
    rig.sup.acknowledge()
    rig.tick(controller_command=40.0)
    ack = rig.sup.last_ack
    name = bit.name
    assert ack.accepted
    assert ack.text == f"FAILSAFE -> RECOVERING, resuming automatic control ({name} acknowledged)"
    assert rig.out.run_controller and not rig.out.faults & bit
    assert rig.out.command_ml_h == 18.0  # bumpless: 0.5 ml/h a tick towards the controller's 40
    assert rig.sup.detections[name] == 1


def test_an_ack_while_an_input_fault_persists_is_refused_naming_only_that_fault():
    rig = Rig(LATCH)
    rig.ticks(3)
    _fail(rig, "raise")
    rig.sup.acknowledge()
    rig.tick(map_mmhg=math.nan)
    assert rig.sup.last_ack.text == "refused: HOLD, fault persists: MAP_NAN"
    assert rig.sup.state == State.HOLD and rig.out.faults & Fault.CONTROLLER_FAULT
    rig.sup.acknowledge()
    rig.tick()
    assert rig.sup.last_ack.accepted and rig.sup.state in (State.RECOVERING, State.AUTO)


def test_a_controller_that_fails_again_after_the_ack_is_held_again():
    rig = Rig(LATCH)
    rig.ticks(3, controller_command=12.0)
    _fail(rig, "raise")
    rig.sup.acknowledge()
    rig.tick(controller_command=12.0)
    assert rig.sup.state == State.AUTO  # within one slew step: AUTO at once
    assert _fail(rig, "raise") == 12.0 and rig.sup.state == State.HOLD
    assert rig.sup.detections["CONTROLLER_FAULT"] == 2


def test_without_the_latch_a_non_finite_command_recovers_by_itself():
    rig = Rig()  # controller_faults="stop": pressor sil, trial, the API, the gym environment
    rig.ticks(3, controller_command=15.0)
    assert _fail(rig, "nan") == 15.0 and rig.sup.state == State.HOLD
    rig.ticks(51)  # inputs good for 5 s (from the tick after the fault)
    assert rig.sup.state in (State.RECOVERING, State.AUTO)


def test_the_controller_fault_action_is_checked():
    with pytest.raises(ValueError, match="'controller_faults' = 'ignore'; allowed 'stop' or"):
        SupervisorConfig(controller_faults="ignore")


def _core(spec: str, action: str) -> ClosedLoopCore:
    controller = load_controller(spec, TS)
    sup = Supervisor(SupervisorConfig(sample_period_s=TS, controller_faults=action))
    return ClosedLoopCore(controller, sup)


def _inputs(k: int) -> TickInputs:
    return tick_inputs(k, k * TS, 60.0 + 0.01 * k, target_mmhg=80.0)


@pytest.mark.parametrize(
    ("how", "cause", "bit"),
    [
        ("raise", "ZeroDivisionError('plugin bug')", Fault.CONTROLLER_FAULT),
        ("none", "TypeError(", Fault.CONTROLLER_FAULT),
        ("nan", "returned nan", Fault.COMMAND_INVALID),
    ],
)
def test_the_core_under_latch_keeps_stepping_holds_and_names_the_failure(how, cause, bit):
    core = _core(f"tests.support.controller_plugins:FailsAt:at=50,how='{how}'", "latch")
    records = [core.step(_inputs(k), k * TS, None, CLEAN_LINK) for k in range(200)]
    held = records[48].command_ml_h
    assert held > 0.0 and all(r.controller_error is None for r in records[:49])
    failed = records[49]
    assert failed.command_ml_h == held and failed.supervisor.faults & bit
    assert failed.controller_error.startswith("controller 'FailsAt' (module ")
    assert "failed at tick 49 (t = 4.9 s)" in failed.controller_error
    assert cause in failed.controller_error
    assert [r.command_ml_h for r in records[49:]] == [held] * 151  # HOLD, then FAILSAFE: held
    assert all(r.controller_error is None for r in records[50:])  # logged once: not stepped
    assert records[-1].supervisor.state == State.FAILSAFE


def test_the_core_under_stop_ends_the_run_on_an_exception():
    core = _core("tests.support.controller_plugins:FailsAt:at=3", "stop")
    core.step(_inputs(0), 0.0, None, CLEAN_LINK)
    core.step(_inputs(1), TS, None, CLEAN_LINK)
    with pytest.raises(ControllerError, match=r"'FailsAt'.*tick 2 .*ZeroDivisionError"):
        core.step(_inputs(2), 2 * TS, None, CLEAN_LINK)
