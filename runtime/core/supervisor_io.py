"""What the safety supervisor (:mod:`pressor.runtime.core.supervisor`) takes and gives each tick, and how it
judges a clinician's acknowledgement.

The records are named tuples rather than frozen dataclasses: one is built every tick of every
trial patient.

Acknowledge and resume
----------------------
HOLD and FAILSAFE leave by themselves once every input has been good for ``recover_after_s``
(RECOVERING, then AUTO). A clinician's acknowledgement (``pressor run``: the line ``ack`` on stdin
or in the target file, :mod:`pressor.runtime.inputs.target_source`) shortens that wait: taken at the next
tick, it is accepted only when that tick has no fault that holds the loop (advisory faults do not
count), and then moves HOLD or FAILSAFE to RECOVERING at once, so the command slews back to the
controller's (bumpless) and the state reaches AUTO; while a fault persists it is refused naming the
faults, and the state is unchanged. In STARTUP, AUTO and RECOVERING there is nothing to
acknowledge. A latched controller fault (``controller_faults="latch"``, ``pressor run``:
``CONTROLLER_FAULT``, ``COMMAND_INVALID``) is the one fault the acknowledgement itself clears: the
clinician, not an input turning good, decides that the controller may run again
(:mod:`pressor.runtime.core.supervisor`, "Controller faults"); it is accepted when no *other* holding fault
persists. :func:`judge_ack` is the rule; :class:`AckOutcome` what the loop logs.
"""

from __future__ import annotations

from typing import NamedTuple

from pressor.runtime.core.supervisor_config import State, fault_names


class SupervisorInput(NamedTuple):
    """Everything the supervisor checks at one tick (every field required: nothing fails open).

    Immutable; a named tuple rather than a frozen dataclass because one is built every tick of
    every trial patient (~0.3 µs against ~1.4 µs).

    Attributes
    ----------
    now_s
        Time (s) of this tick on the loop's clock.
    map_mmhg, quality
        Newest MAP sample (mmHg) and its monitor quality bits.
    K, T_s, tau_s, sched_valid
        Newest scheduling parameters (mmHg/(ml/h), s, s) and their validity flag.
    sample_age_s
        Age (s) of the sample: since it was received, or for a ``QUALITY_HELD`` repeat since the
        last sample without the bit (:mod:`pressor.runtime.core.closed_loop`); 0 marks a new sample, the
        only kind the flatline rules judge. The MAP checks are skipped once stale.
    link_silence_s
        Time (s) since any frame was received from the device.
    target_mmhg
        The MAP target (mmHg) the controller will be given.
    link_errors
        Frames the link layer discarded since the last tick (advisory ``LINK_ERRORS``).
    pump_delivered_ml_h, pump_alarms
        This tick's pump status (delivered ml/h, alarm bits); NaN and 0: no fresh status.
    estimated
        Whether the online estimator runs (``--schedule estimated`` or ``validated``).
    estimate_healthy
        False when the estimator rejected its estimate and reports the prior instead.
    boundary_faults
        Fault bits the shell found at the boundary before the core (``SAMPLE_TIME``,
        ``RECORD_ERROR``; :data:`pressor.runtime.core.supervisor_config.BOUNDARY_FAULTS`); 0 in process.
    """

    now_s: float
    map_mmhg: float
    quality: int
    K: float
    T_s: float
    tau_s: float
    sched_valid: bool
    sample_age_s: float
    link_silence_s: float
    target_mmhg: float
    link_errors: int
    pump_delivered_ml_h: float
    pump_alarms: int
    estimated: bool
    estimate_healthy: bool
    boundary_faults: int


class SupervisorOutput(NamedTuple):
    """What the supervisor decided at one tick (immutable; a named tuple for the per-tick cost).

    Attributes
    ----------
    run_controller
        Whether the controller was to be stepped this tick.
    state
        The state after the tick.
    faults
        Fault bits found this tick.
    new_faults
        Fault bits that rose this tick (for event logs).
    transition
        ``(from_state, to_state, faults)`` if the tick changed the state, else ``None``.
    command_ml_h
        The pump command (ml/h), finite and in [0, max_rate_ml_h].
    alarm
        Whether the alarm is raised (HOLD, FAILSAFE or any fault but a clamped command).
    """

    run_controller: bool
    state: State
    faults: int
    new_faults: int
    transition: tuple[State, State, int] | None
    command_ml_h: float
    alarm: bool


class AckOutcome(NamedTuple):
    """What became of a clinician's acknowledgement, judged at one tick.

    Attributes
    ----------
    accepted
        Whether it moved the supervisor to RECOVERING.
    state
        The state it found (before the acknowledgement).
    faults
        The holding fault bits present at that tick (0 when accepted).
    text
        One line for the logs: ``FAILSAFE -> RECOVERING, resuming automatic control``,
        ``refused: FAILSAFE, fault persists: MAP_NAN`` or ``ignored: nothing to acknowledge
        in AUTO``.
    """

    accepted: bool
    state: State
    faults: int
    text: str


def judge_ack(state: State, holding_faults: int, latched: int = 0) -> AckOutcome:
    """Judge an acknowledgement taken at a tick whose state is ``state`` (after the tick's own
    transitions) and whose holding fault bits are ``holding_faults`` (the latched controller
    faults ``latched`` left out: an accepted acknowledgement clears them; see the module
    docstring).
    """
    if state not in (State.HOLD, State.FAILSAFE):
        return AckOutcome(False, state, 0, f"ignored: nothing to acknowledge in {state.name}")
    if holding_faults:
        persists = ", ".join(fault_names(holding_faults))
        return AckOutcome(
            False, state, holding_faults, f"refused: {state.name}, fault persists: {persists}"
        )
    text = f"{state.name} -> RECOVERING, resuming automatic control"
    if latched:
        text += f" ({', '.join(fault_names(latched))} acknowledged)"
    return AckOutcome(True, state, 0, text)


#: the clinician's commands (``pressor run``: lines on stdin or in the target file)
CLINICIAN_COMMANDS = ("stop", "manual", "resume")


def judge_command(kind: str, state: State, holding_faults: int, rate_ml_h: float) -> AckOutcome:
    """Judge the clinician's ``stop``, ``manual`` (at ``rate_ml_h``, ml/h) or ``resume`` taken at a
    tick whose state is ``state`` and whose holding fault bits are ``holding_faults``.

    ``stop`` and ``manual`` are always accepted (the clinician's hand is on the pump: the state
    becomes STOPPED, 0 ml/h, or MANUAL at the rate); ``resume`` from STOPPED or MANUAL goes to
    RECOVERING (the controller again, its command reached by the bumpless slew), or to HOLD at the
    current command while a fault persists (which ends as any HOLD does); elsewhere it is ignored.
    The outcome's ``state`` is the state after the command.
    """
    if kind == "stop":
        return AckOutcome(True, State.STOPPED, 0, f"{state.name} -> STOPPED: 0 ml/h until resume")
    if kind == "manual":
        return AckOutcome(
            True, State.MANUAL, 0, f"{state.name} -> MANUAL: {rate_ml_h:g} ml/h until resume"
        )
    if state not in (State.STOPPED, State.MANUAL):
        return AckOutcome(False, state, 0, f"resume ignored: {state.name}, not stopped or manual")
    if holding_faults:
        persists = ", ".join(fault_names(holding_faults))
        return AckOutcome(
            True, State.HOLD, holding_faults, f"{state.name} -> HOLD: fault persists: {persists}"
        )
    return AckOutcome(
        True, State.RECOVERING, 0, f"{state.name} -> RECOVERING, resuming automatic control"
    )
