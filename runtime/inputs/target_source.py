"""The runtime's own MAP target, changed while the loop runs (``pressor run --target-*``).

A :class:`TargetSource` holds the target the clinician gave the runtime. The loop it is given to
(:class:`pressor.runtime.shell.loop.Loop`'s ``target``, which runs every tick through it, silent ones
included) asks it at each tick boundary to :meth:`~TargetSource.apply` itself to the tick's
inputs: it first reads what arrived since the previous tick (the ``--target-file`` when its
modification time, size or inode changed; complete lines on stdin with ``--target-stdin``), then
puts the current target into the tick's :class:`~link.TickInputs` in place of the device's
MAP_TARGET. A new value therefore takes effect at the first tick after it was read. It is logged
to the recording's event log and listed in :meth:`~TargetSource.summary` (tick, sim time, old,
new, source). A bad value (not a number, outside [50, 120] mmHg, an unreadable file) is refused
with one line on stderr, logged, counted, and the old target kept; an empty file or a blank line
is ignored (a writer that truncates the file before it writes).

The same two inputs carry the clinician's acknowledgement: the line ``ack`` on stdin, or an
``ack`` line in the target file (each time the file changes and holds one; the file read at start
acknowledges nothing). It is taken at the next tick: the supervisor judges it
(:func:`pressor.runtime.core.supervisor_io.judge_ack`: HOLD or FAILSAFE resume at once, through RECOVERING,
only if no fault holds the loop at that tick) and the outcome is printed on stderr, logged to the
event log with the tick and the time, and listed in :meth:`~TargetSource.summary` (``acks``).

They carry the clinician's hand on the pump as well: the lines ``stop`` (0 ml/h now, held),
``manual RATE`` (RATE ml/h, held) and ``resume`` (back to automatic control) are taken at the next
tick (:meth:`TargetSource.take_commands`), judged by the supervisor
(:func:`pressor.runtime.core.supervisor_io.judge_command`) and their outcome printed, logged and listed
in :meth:`~TargetSource.summary` (``commands``). A ``manual`` line without a rate in [0, the
controller's maximum] is refused with one line. The file as read at start commands nothing.

Which tick a change lands on depends on when it was written in wall-clock time, so a lockstep run
with live changes is not reproducible byte for byte; a run with a fixed ``--target-mmhg`` is.
"""

from __future__ import annotations

import math
import os
import select
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any, TextIO

from pressor.link import TickInputs
from pressor.runtime.core.supervisor import AckOutcome
from pressor.runtime.inputs.clinician import (
    ClinicianInput,
    parse_target,
    read_input_file,
    split_ack,
    split_commands,
)


class TargetSource:
    """The runtime's MAP target and its live changes (see the module docstring).

    Parameters
    ----------
    clinician
        The checked options; its ``target_mmhg`` (not ``None``) is the starting target (mmHg).
    stdin_fd
        File descriptor read with ``--target-stdin`` (default 0).
    err
        Where refusals are reported (default ``sys.stderr``).
    prog
        Program name in front of each reported line.
    max_rate_ml_h
        The largest rate (ml/h) a ``manual`` command may set: the controller's maximum.
    own_target
        ``False`` (``pressor sil --clinician-stdin``): the device's target stays, stdin carries
        only ``ack``, ``stop``, ``manual RATE`` and ``resume``; a number is refused.
    """

    def __init__(
        self,
        clinician: ClinicianInput,
        *,
        stdin_fd: int = 0,
        err: TextIO | None = None,
        prog: str = "pressor run",
        max_rate_ml_h: float = 120.0,
        own_target: bool = True,
    ) -> None:
        if clinician.target_mmhg is None and own_target:
            raise ValueError("TargetSource needs a starting target")
        #: whether the runtime sets the target (else the device's stays: commands only)
        self.own_target = own_target
        self.initial_mmhg = math.nan if clinician.target_mmhg is None else clinician.target_mmhg
        #: the current target (mmHg)
        self.target_mmhg = self.initial_mmhg
        #: applied changes: tick, sim_time_s, old_mmhg, new_mmhg, source
        self.changes: list[dict[str, Any]] = []
        #: values refused (bad text, out of range, unreadable file)
        self.refused = 0
        #: acknowledgements taken: tick, sim_time_s, from, state, accepted, outcome
        self.acks: list[dict[str, Any]] = []
        self._pending_acks: list[str] = []
        #: the clinician's commands taken: tick, sim_time_s, from, command, rate_ml_h, state,
        #: outcome
        self.commands: list[dict[str, Any]] = []
        self._pending_commands: list[tuple[str, float, str]] = []
        self.max_rate_ml_h = float(max_rate_ml_h)
        self._path = clinician.target_file
        # never a real state: the first poll reads the file again (it may have changed since
        # the command line read the starting target)
        self._file_state: tuple[int, int, int] | None | str = "unread"
        self._first_read = True
        self._fd: int | None = stdin_fd if clinician.target_stdin else None
        self._buf = b""
        self._err = err
        self._prog = prog
        self._pending: list[tuple[float, str]] = []
        self._pending_refusals: list[str] = []
        self._announced = False

    # ------------------------------------------------------------------ reading
    def poll(self) -> None:
        """Read what changed since the last call (non-blocking); new values wait for the next
        :meth:`apply`."""
        path = self._path
        if path is not None:
            state = _file_state(path)
            if state != self._file_state:
                self._file_state = state
                try:  # never blocks: a FIFO or a device in its place is refused (a ValueError)
                    text = read_input_file(path)
                except ValueError as exc:
                    self._refuse(f"file {path}", str(exc))
                else:  # the file as read at start acknowledges nothing
                    first, self._first_read = self._first_read, False
                    self._offer(text, f"file {path}", ack=not first)
        if self._fd is not None:
            for line in self._read_lines():
                self._offer(line, "stdin")

    def _read_lines(self) -> list[str]:
        """Complete lines that arrived on stdin (the end of input ends the last one)."""
        fd = self._fd
        assert fd is not None
        data = b""
        while select.select([fd], [], [], 0.0)[0]:
            chunk = os.read(fd, 4096)
            if not chunk:  # end of input: keep the target, stop reading
                self._fd = None
                data += b"\n"
                break
            data += chunk
        if not data:
            return []
        *lines, self._buf = (self._buf + data).split(b"\n")
        return [line.decode("ascii", "replace") for line in lines]

    def _offer(self, text: str, source: str, *, ack: bool = True) -> None:
        text, acked = split_ack(text)
        if acked and ack:
            self._pending_acks.append(source)
        text, commands, refused = split_commands(text, self.max_rate_ml_h)
        if ack:  # as for ack: the file as read at start commands nothing
            self._pending_commands += [(kind, rate, source) for kind, rate in commands]
            for why in refused:
                self._refuse_command(source, why)
        if not text.strip():
            return  # an empty file (being rewritten) or a blank line
        if not self.own_target:
            self._refuse_command(source, f"{text.strip()!r}: the target is the device's here")
            return
        try:
            self._pending.append((parse_target(text), source))
        except ValueError as exc:
            self._refuse(source, str(exc))

    def _refuse(self, source: str, why: str) -> None:
        self.refused += 1
        keep = self._pending[-1][0] if self._pending else self.target_mmhg
        line = f"target from {source} refused: {why}; keeping {keep:g} mmHg"
        print(f"{self._prog}: {line}", file=self._err or sys.stderr)
        self._pending_refusals.append(line)

    # ------------------------------------------------------------------ applying
    def apply(self, inp: TickInputs, recorder: Any = None) -> TickInputs:
        """Read pending changes, apply them at this tick, and return ``inp`` carrying the
        runtime's target (``target_tick`` = the tick: it is current). Changes and refusals are
        logged to ``recorder`` (a :class:`pressor.runtime.record.recorder.Recorder`) when given."""
        self.poll()
        tick, t = inp.tick, inp.sim_time_s
        if not self.own_target:  # commands only: the device's target and the tick as they came
            for line in self._pending_refusals:
                if recorder is not None:
                    recorder.event(tick, t, line, warn=True)
            self._pending_refusals.clear()
            return inp
        if not self._announced:
            self._announced = True
            if recorder is not None:
                recorder.event(
                    tick,
                    t,
                    f"target {self.initial_mmhg:g} mmHg from the runtime; the device's MAP_TARGET"
                    " is ignored",
                    warn=False,
                )
        for line in self._pending_refusals:
            if recorder is not None:
                recorder.event(tick, t, line, warn=True)
        self._pending_refusals.clear()
        for value, source in self._pending:
            old = self.target_mmhg
            if value == old:
                continue  # rewritten with the same target: no change
            self.target_mmhg = value
            self.changes.append(
                {"tick": tick, "sim_time_s": t, "old_mmhg": old, "new_mmhg": value, "from": source}
            )
            if recorder is not None:
                recorder.event(tick, t, f"target {old:g} -> {value:g} mmHg ({source})", warn=False)
        self._pending.clear()
        return replace(inp, target_mmhg=self.target_mmhg, target_tick=tick)

    def _refuse_command(self, source: str, why: str) -> None:
        line = f"command from {source} refused: {why}"
        print(f"{self._prog}: {line}", file=self._err or sys.stderr)
        self._pending_refusals.append(line)
        self.refused += 1

    def take_commands(self) -> list[tuple[str, float, str]]:
        """The clinician's commands read since the last call: ``(kind, ml/h, source)``."""
        commands, self._pending_commands = self._pending_commands, []
        return commands

    def log_command(
        self, outcome: AckOutcome, command: tuple[str, float, str], tick: int, t: float,
        recorder: Any = None,
    ) -> None:  # fmt: skip
        """Keep, print and log what became of the clinician's ``command`` at ``tick`` (time
        ``t``, s): the summary's ``commands`` (``tick``, ``sim_time_s``, ``from``, ``command``,
        ``rate_ml_h``, ``state``, ``outcome``)."""
        kind, rate, source = command
        said = f"{kind} {rate:g}" if kind == "manual" else kind
        self.commands.append(
            {
                "tick": tick,
                "sim_time_s": t,
                "from": source,
                "command": kind,
                "rate_ml_h": rate if kind == "manual" else None,
                "state": outcome.state.name,
                "outcome": outcome.text,
            }
        )
        line = f"{said} ({source}) at {t:g} s, tick {tick}: {outcome.text}"
        print(f"{self._prog}: {line}", file=self._err or sys.stderr)
        if recorder is not None:
            recorder.event(tick, t, line, warn=kind != "resume")

    def take_acks(self) -> list[str]:
        """The sources of the acknowledgements read since the last call (taken by the tick)."""
        acks, self._pending_acks = self._pending_acks, []
        return acks

    def log_ack(
        self, outcome: AckOutcome, sources: list[str], tick: int, t: float, recorder: Any = None
    ) -> None:
        """Keep, print and log (to ``recorder``, a :class:`pressor.runtime.record.recorder.Recorder`) what
        became of the acknowledgement from ``sources`` taken at ``tick`` (sim time ``t``, s)."""
        source = ", ".join(dict.fromkeys(sources))
        self.acks.append(
            {
                "tick": tick,
                "sim_time_s": t,
                "from": source,
                "state": outcome.state.name,
                "accepted": outcome.accepted,
                "outcome": outcome.text,
            }
        )
        line = f"ack ({source}) at {t:g} s, tick {tick}: {outcome.text}"
        print(f"{self._prog}: {line}", file=self._err or sys.stderr)
        if recorder is not None:
            recorder.event(tick, t, line, warn=not outcome.accepted)

    def summary(self) -> dict[str, Any]:
        """The summary's ``target`` record: source, starting target, changes, refusals,
        acknowledgements."""
        return {
            "source": "runtime",
            "initial_mmhg": self.initial_mmhg,
            "changes": list(self.changes),
            "refused": self.refused,
            "acks": list(self.acks),
            **({"commands": list(self.commands)} if self.commands else {}),
        }


def _file_state(path: Path) -> tuple[int, int, int] | None:
    """What tells a rewritten file apart: (mtime ns, size, inode); ``None`` when missing."""
    try:
        st = path.stat()
    except OSError:
        return None
    return (st.st_mtime_ns, st.st_size, st.st_ino)
