"""The safety supervisor: a small, pure state machine between the inputs, the controller and the pump.

No I/O, no clock: every call gets the time (s) and the inputs explicitly, in a typed record, so the
same input sequence gives the same output sequence, byte for byte. The closed-loop core
(:mod:`pressor.runtime.core.closed_loop`) calls, once per tick::

    run_controller = sup.assess(SupervisorInput(now_s, map_mmhg, ...))   # every field given
    raw = controller.step(...) if run_controller else None
    out = sup.finalize(raw)       # SupervisorOutput; out.command_ml_h finite, in [0, max_rate_ml_h]
    out = sup.finalize(None, failed=True)   # instead, when the step raised (controller_faults="latch")

With ``config.dose_limits`` (``pressor run``: the drug library) the last step of every tick cuts
the command to the hard and hourly dose maxima and flags the soft one
(:mod:`pressor.runtime.core.dose_guard`).

States
------
STARTUP
    No good sample seen yet. Command 0 ml/h. The first good sample moves to AUTO *in the same tick*
    (no warm-up delay), so a clean run is tick-for-tick the controller's own run.
AUTO
    Inputs good: the controller's command is passed through **unchanged** (the exact float) when it
    lies in [0, max]; an out-of-range or non-finite command is clamped / held and flagged.
HOLD
    A fault was detected: the last command is held and the alarm is raised. The controller is not
    stepped (bad inputs must not wind it up). A fault lasting longer than ``hold_max_s`` → FAILSAFE.
FAILSAFE
    Link loss (immediately) or a long fault: the command ramps at ``failsafe_ramp_ml_h_per_s`` to
    ``safe_rate_ml_h`` (``None``: keep the held rate). Alarm raised.
STOPPED, MANUAL
    The clinician's (:meth:`Supervisor.command`): ``stop`` commands 0 ml/h at once and holds it,
    ``manual`` a rate of the clinician's, from any state, whatever the faults (still detected and
    alarmed); only the clinician's ``resume`` leaves them (RECOVERING, or HOLD while a fault
    persists). The controller is not stepped meanwhile.
RECOVERING
    From HOLD or FAILSAFE once every input has been good for ``recover_after_s``, or at once on a
    clinician's acknowledgement (:meth:`Supervisor.acknowledge`) at a tick without a holding fault:
    the controller is stepped again and the output slews towards its command by at most
    ``reentry_step_ml_h`` per tick (bumpless transfer); when the two meet the state is AUTO. A new
    fault → HOLD.

Input faults do not latch: a HOLD or FAILSAFE lasts exactly as long as a fault persists, plus
``recover_after_s`` (or until the acknowledgement). What clears each fault, and so ends the state:
docs/PROTOCOL.md, "Alarms"; the acknowledgement rule: :mod:`pressor.runtime.core.supervisor_io`.

Controller faults (``config.controller_faults``). With ``"stop"`` (``pressor sil``, ``trial``, the
API and the Gymnasium environment) a controller that raises ends the run (the core raises
:class:`pressor.runtime.core.closed_loop.ControllerError`: a researcher sees the bug) and a non-finite
command is ``COMMAND_INVALID``: HOLD, re-entry once the inputs have been good for
``recover_after_s``. With ``"latch"`` (``pressor run``: a patient on the line) a step that raises or
returns a non-number (``CONTROLLER_FAULT``, via ``finalize(None, failed=True)``) and a non-finite
command (``COMMAND_INVALID``) both HOLD the last command, raise the alarm and *stay* (HOLD, then
FAILSAFE after ``hold_max_s`` like any lasting fault) until the clinician acknowledges. Why: an
input fault ends when the input is good again, which the supervisor can see; nothing the supervisor
sees tells that a controller which crashed or produced garbage is sound again (its internal state
is unknown), and stepping it to find out would put its next output on the pump unattended. The
acknowledgement is the clinician's decision to try it again: accepted (when no other holding
fault persists) it clears the latch, moves to RECOVERING and the controller is stepped again as
it is (not reset: its integrator carries the dose the patient is on), its command reached by the
bumpless slew; a further failure latches again. Without an acknowledgement input (``pressor
run`` without ``--target-stdin`` or ``--target-file``) the latch lasts for the rest of the run.

The fault kinds, their detection bounds and the configuration are in
:mod:`pressor.runtime.core.supervisor_config`; the checks that turn each tick's inputs into fault
bits, in :mod:`pressor.runtime.core.input_checks`.

Deviation from the paper: the paper has no supervisor; this is the IEC 60601-1-10 shell around it.
"""

from __future__ import annotations

import math

from pressor.runtime.core.dose_guard import DoseGuard
from pressor.runtime.core.input_checks import InputChecks
from pressor.runtime.core.supervisor_config import (
    ADVISORY,
    ALARM_FAULTS,
    SCHED_ENVELOPE,
    Fault,
    State,
    SupervisorConfig,
    fault_names,
)
from pressor.runtime.core.supervisor_io import (
    AckOutcome,
    SupervisorInput,
    SupervisorOutput,
    judge_ack,
    judge_command,
)

__all__ = ["AckOutcome", "Supervisor", "SupervisorInput", "SupervisorOutput"]

#: the fault bits as plain ints: ``faults |= Fault.X`` would turn ``faults`` into an IntFlag, whose
#: arithmetic runs Python-level enum code at every later ``|`` and ``&`` of the tick (the input
#: checks' own bits: :mod:`pressor.runtime.core.input_checks`)
_COMMAND_CLAMPED, _COMMAND_INVALID = int(Fault.COMMAND_CLAMPED), int(Fault.COMMAND_INVALID)
_CONTROLLER_FAULT, _LINK_ERRORS = int(Fault.CONTROLLER_FAULT), int(Fault.LINK_ERRORS)
_LINK_LOSS, _STALE_SAMPLE = int(Fault.LINK_LOSS), int(Fault.STALE_SAMPLE)
_TARGET_INVALID = int(Fault.TARGET_INVALID)

#: the states as module constants: ``State.AUTO`` is an attribute lookup on the enum's class
#: (~60 ns under its metaclass), several of them a tick; a member compares by identity in ``in``
_STARTUP, _AUTO, _HOLD, _FAILSAFE = State.STARTUP, State.AUTO, State.HOLD, State.FAILSAFE
_RECOVERING, _STOPPED, _MANUAL = State.RECOVERING, State.STOPPED, State.MANUAL
#: the states in which the controller is stepped, and those that raise the alarm
_CONTROLLED = (_AUTO, _RECOVERING)
_ALARMED = (_HOLD, _FAILSAFE)

#: builds the output's named tuple from a tuple of its fields without the named tuple's
#: Python-level ``__new__`` (the per-tick path, ~0.25 µs; fields in declaration order)
_new_tuple = tuple.__new__
#: ``math.isfinite`` without the module attribute lookup (the per-tick path)
_isfinite = math.isfinite

#: slack (s) on time comparisons so that k·Ts sums reach a bound that is a whole number of ticks
_EPS_S = 1e-9


def _clamp(value: float, high: float) -> float:
    # NaN-safe: a non-finite value never reaches the pump.
    if value != value or value <= 0.0:
        return 0.0
    return high if value >= high else value


class Supervisor:
    """The state machine; see the module docstring.

    Parameters
    ----------
    config
        Limits and timings.

    Attributes
    ----------
    state
        Current :class:`State`.
    faults
        Fault bits found at the last :meth:`assess` / :meth:`finalize`.
    command_ml_h
        The last command output (ml/h), always in [0, max_rate_ml_h]; held between ticks.
    detections
        Count of rising edges of each fault kind (by name) over the run.
    last_ack
        What became of the acknowledgement taken at the last :meth:`assess`, else ``None``.
    """

    def __init__(self, config: SupervisorConfig | None = None) -> None:
        self.config = config or SupervisorConfig()
        advisory = ADVISORY | (SCHED_ENVELOPE if self.config.sched_action == "advise" else 0)
        #: the faults that change the state (plain int, for the per-tick path)
        self._holding_faults = ~int(advisory)
        self.reset()

    def reset(self) -> None:
        """Back to STARTUP with command 0 and no history."""
        self.state = State.STARTUP
        self.faults = 0
        self.command_ml_h = 0.0
        self.detections: dict[str, int] = {}
        self._prev_faults = 0
        cfg = self.config
        self._checks = InputChecks(cfg)  # the input checks and the history they keep
        self._fault_since_s: float | None = None
        self._good_since_s: float | None = None
        self._now_s = 0.0
        self._short_mmhg = math.nan
        self._run_controller = False
        self._entry_state = State.STARTUP
        self._ack_requested = False
        self.last_ack: AckOutcome | None = None
        self._clinician: tuple[str, float] | None = None
        self.last_command: AckOutcome | None = None
        self._manual_ml_h = 0.0
        self._latched = 0  # faults kept until acknowledged (controller faults, DEVICE_CHANGED)
        self._latch = cfg.controller_faults == "latch"
        limits = cfg.dose_limits
        #: the drug library's limits on the final command (None: no library)
        self.dose_guard = None if limits is None else DoseGuard(limits, cfg.sample_period_s)

    @property
    def alarm(self) -> bool:
        """True while the supervisor is not in normal automatic control or a fault is present."""
        return self.state in (State.HOLD, State.FAILSAFE) or bool(self.faults & ALARM_FAULTS)

    def latch(self, faults: int) -> None:
        """Hold on ``faults`` (``DEVICE_CHANGED``) from the next tick until the clinician's
        acknowledgement clears them, as a latched controller fault (the shell's boundary check)."""
        self._latched |= int(faults)

    def command(self, kind: str, rate_ml_h: float = 0.0) -> None:
        """The clinician's ``stop`` (0 ml/h now, held), ``manual`` (``rate_ml_h``, held) or
        ``resume`` (back to automatic control); judged at the next :meth:`assess`
        (:func:`pressor.runtime.core.supervisor_io.judge_command`), its outcome in ``last_command``."""
        self._clinician = (kind, float(rate_ml_h))

    def acknowledge(self) -> None:
        """The clinician acknowledges the alarm and asks to resume; judged at the next
        :meth:`assess` (:func:`pressor.runtime.core.supervisor_io.judge_ack`), its outcome in
        ``last_ack``."""
        self._ack_requested = True

    # -- the two phases of a tick -----------------------------------------------------------------
    def assess(self, inp: SupervisorInput) -> bool:
        """Check this tick's inputs and update the state; return True if the controller is to run."""
        now_s = inp.now_s
        cfg = self.config
        checks = self._checks
        self._now_s = now_s
        self._short_mmhg = inp.target_mmhg - inp.map_mmhg  # how far below the target (dose guard)
        self._entry_state = self.state
        faults = 0
        if inp.link_silence_s >= cfg.link_loss_after_s - _EPS_S:
            faults |= _LINK_LOSS
        if inp.sample_age_s > cfg.stale_after_s + _EPS_S:  # the limit itself is not stale
            faults |= _STALE_SAMPLE
        else:
            faults |= checks.map(now_s, inp.map_mmhg, inp.quality, inp.sample_age_s == 0.0)
            faults |= checks.sched(now_s, inp.K, inp.T_s, inp.tau_s, inp.sched_valid)
            if not cfg.map_min_mmhg <= inp.target_mmhg <= cfg.map_max_mmhg:  # False for NaN too
                faults |= _TARGET_INVALID
        if inp.link_errors:
            faults |= _LINK_ERRORS
        faults |= checks.pump(now_s, inp.pump_delivered_ml_h, inp.pump_alarms, self.command_ml_h)
        if inp.estimated:
            faults |= checks.estimate(now_s, inp)
        faults |= inp.boundary_faults | self._latched
        self.faults = faults
        state = self.state
        if faults & self._holding_faults:
            self._good_since_s = None
            if self._fault_since_s is None:
                self._fault_since_s = now_s
            if state in _CONTROLLED:
                state = _FAILSAFE if faults & _LINK_LOSS else _HOLD
            elif state == _HOLD and (
                faults & _LINK_LOSS or now_s - self._fault_since_s >= cfg.hold_max_s - _EPS_S
            ):
                state = _FAILSAFE
        else:
            self._fault_since_s = None
            if self._good_since_s is None:
                self._good_since_s = now_s
            if state == _STARTUP:
                state = _AUTO
            elif state in _ALARMED and now_s - self._good_since_s >= cfg.recover_after_s - _EPS_S:
                state = _RECOVERING
        self.last_ack = None
        if self._ack_requested:
            self._ack_requested = False
            latched = self._latched
            self.last_ack = judge_ack(state, faults & self._holding_faults & ~latched, latched)
            if self.last_ack.accepted:
                state = _RECOVERING
                self._latched = 0
                self.faults = faults & ~latched
        self.last_command = None
        if self._clinician is not None:  # the clinician's stop, manual rate or resume
            kind, rate = self._clinician
            self._clinician = None
            self.last_command = judge_command(kind, state, faults & self._holding_faults, rate)
            state = self.last_command.state
            if state == _MANUAL:
                self._manual_ml_h = rate
        self.state = state
        self._run_controller = state in _CONTROLLED
        return self._run_controller

    def finalize(self, raw_command_ml_h: float | None, failed: bool = False) -> SupervisorOutput:
        """Turn the controller's command (``None`` if it did not run) into the pump command.

        ``failed``: the controller was stepped and raised, or returned something that is not a
        number (``CONTROLLER_FAULT``; see the module docstring). The output's ``command_ml_h`` is
        finite and in [0, max_rate_ml_h] on every path.
        """
        cfg = self.config
        high = cfg.max_rate_ml_h
        previous = self.command_ml_h
        state = self.state
        if self._run_controller:
            raw = math.nan if raw_command_ml_h is None or failed else raw_command_ml_h
            if not _isfinite(raw):
                bit = _CONTROLLER_FAULT if failed else _COMMAND_INVALID
                self.faults |= bit
                if self._latch:
                    self._latched |= bit  # a plain int: it joins every tick's faults
                self._good_since_s = None
                self._fault_since_s = self._now_s
                state = _HOLD
                command = previous
            else:
                if not 0.0 <= raw <= high:
                    self.faults |= _COMMAND_CLAMPED
                target = _clamp(raw, high)
                if state == _AUTO:
                    command = target
                else:  # RECOVERING: bumpless slew towards the controller
                    step = cfg.reentry_step_ml_h
                    delta = target - previous
                    if abs(delta) <= step:
                        command = target
                        state = _AUTO
                    else:
                        command = previous + (step if delta > 0.0 else -step)
        elif state == _FAILSAFE:
            goal = previous if cfg.safe_rate_ml_h is None else cfg.safe_rate_ml_h
            step = cfg.failsafe_ramp_ml_h_per_s * cfg.sample_period_s
            delta = goal - previous
            command = goal if abs(delta) <= step else previous + (step if delta > 0.0 else -step)
        elif state == _STARTUP or state == _STOPPED:
            command = 0.0
        elif state == _MANUAL:
            command = self._manual_ml_h
        else:  # HOLD
            command = previous
        command = _clamp(command, high)
        if self.dose_guard is not None:  # the last word: the drug library's dose limits
            command, dose_faults = self.dose_guard.limit(
                command, self._now_s, self._short_mmhg, state == _MANUAL, high
            )
            self.faults |= dose_faults
        self.command_ml_h = command
        self.state = state
        faults = self.faults
        entry = self._entry_state
        transition = (entry, state, faults) if state != entry else None
        rising = faults & ~self._prev_faults
        if rising:
            for name in fault_names(rising):
                self.detections[name] = self.detections.get(name, 0) + 1
        self._prev_faults = faults
        alarm = state in _ALARMED or bool(faults & ALARM_FAULTS)
        return _new_tuple(
            SupervisorOutput,
            (self._run_controller, state, faults, rising, transition, command, alarm),
        )
