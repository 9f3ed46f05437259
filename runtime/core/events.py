"""What the runtime loop logs of each tick: supervisor transitions, advisory faults and
controller faults (:class:`EventLog`).

A transition is kept for the summary (``supervisor.transitions``) and written to the recording's
event log (HOLD and FAILSAFE as warnings); a rising advisory fault only to the event log. A
controller fault (``pressor run``: the controller raised or returned a non-number, the supervisor
holds, :mod:`pressor.runtime.core.supervisor`) is logged once per failure, with the error's text: one line
on stderr, a warning in the recording's event log, and a record in the summary's
``supervisor.controller_faults``.
"""

from __future__ import annotations

import sys
from typing import Any, TextIO

from pressor.runtime.core.closed_loop import TickRecord
from pressor.runtime.core.supervisor_config import DOSE_FAULTS, Fault, State, fault_names


class EventLog:
    """The loop's event log (see the module docstring).

    Parameters
    ----------
    recorder
        The run's :class:`pressor.runtime.record.recorder.Recorder`, or ``None``.
    prog
        Program name in front of each line written to ``err``.
    err
        Where controller faults are reported (default ``sys.stderr``).
    ack_input
        Whether the clinician can acknowledge (``--target-stdin``, ``--target-file``): the
        controller-fault line says the hold lasts until the ``ack``, else for the rest of the run.

    Attributes
    ----------
    transitions
        Every state transition: ``tick``, ``sim_time_s``, ``from``, ``to``, ``faults`` (names).
    controller_faults
        Every controller failure: ``tick``, ``sim_time_s``, ``fault`` (``CONTROLLER_FAULT``: it
        raised or returned a non-number; ``COMMAND_INVALID``: a non-finite command), ``error``
        (the controller, the tick and the exception or the value), ``state`` (after the tick)
        and ``command_ml_h`` (the held command).
    """

    def __init__(
        self,
        recorder: Any = None,
        prog: str = "pressor",
        err: TextIO | None = None,
        *,
        ack_input: bool = False,
    ) -> None:
        self.recorder = recorder
        self.prog = prog
        self.err = err
        self.until = (
            "until the clinician acknowledges (ack)"
            if ack_input
            else "for the rest of the run (no acknowledgement input: --target-stdin or"
            " --target-file gives one)"
        )
        self.transitions: list[dict[str, Any]] = []
        self.controller_faults: list[dict[str, Any]] = []

    def log(self, rec: TickRecord) -> None:
        """Log what happened at the tick of ``rec``."""
        inp, out = rec.inputs, rec.supervisor
        if rec.controller_error is not None:
            self._controller_fault(rec)
        if out.transition is not None:
            old, new, faults = out.transition
            event = {
                "tick": inp.tick,
                "sim_time_s": inp.sim_time_s,
                "from": old.name,
                "to": new.name,
                "faults": fault_names(faults),
            }
            self.transitions.append(event)
            if self.recorder is not None:
                self.recorder.event(
                    inp.tick,
                    inp.sim_time_s,
                    f"{old.name} -> {new.name}: {', '.join(event['faults']) or 'inputs good'}",
                    warn=new in (State.HOLD, State.FAILSAFE),
                    state=int(new),
                )
        elif out.new_faults and self.recorder is not None:  # advisory faults: no transition
            self.recorder.event(
                inp.tick,
                inp.sim_time_s,
                f"{out.state.name}: advisory {', '.join(fault_names(out.new_faults))}",
                warn=False,
            )

    def dose(self, rec: TickRecord, reason: str) -> None:
        """A dose limit started cutting the command, or its shortfall alarm rose: one line on
        stderr and in the recording naming the limit (the dose guard's ``reason``)."""
        inp, out = rec.inputs, rec.supervisor
        names = ", ".join(fault_names(out.new_faults & DOSE_FAULTS))
        line = f"{names} at {inp.sim_time_s:g} s, tick {inp.tick}: {reason}"
        print(f"{self.prog}: {line}", file=self.err or sys.stderr, flush=True)
        if self.recorder is not None:
            self.recorder.event(inp.tick, inp.sim_time_s, line, warn=True)

    def note(self, tick: int, sim_time_s: float, text: str) -> None:
        """An event of the loop itself (not of a tick's record): to the recording's event log."""
        if self.recorder is not None:
            self.recorder.event(tick, sim_time_s, text, warn=True)

    def _controller_fault(self, rec: TickRecord) -> None:
        inp, out = rec.inputs, rec.supervisor
        kind = "CONTROLLER_FAULT" if out.faults & Fault.CONTROLLER_FAULT else "COMMAND_INVALID"
        self.controller_faults.append(
            {
                "tick": inp.tick,
                "sim_time_s": inp.sim_time_s,
                "fault": kind,
                "error": rec.controller_error,
                "state": out.state.name,
                "command_ml_h": out.command_ml_h,
            }
        )
        line = (
            f"{kind}: {rec.controller_error}; {out.state.name} at {out.command_ml_h:g} ml/h"
            f" {self.until}"
        )
        print(f"{self.prog}: {line}", file=self.err or sys.stderr, flush=True)
        if self.recorder is not None:
            self.recorder.event(inp.tick, inp.sim_time_s, line, warn=True)
