"""What the loop checks of each tick's inputs before the core, and of its own writers.

The supervisor judges MAP, scheduling, target and pump values; what only the shell can see is
checked here, at the boundary, and turned into fault bits (``SupervisorInput.boundary_faults``),
never into an exception:

``SAMPLE_TIME`` (holding)
    A MAP sample's ``sim_time_s`` must be finite, not earlier than the previous sample's, and
    its tick times the period to within half a period (docs/PROTOCOL.md: ``tick *
    sample_period_s``). Otherwise - time running backwards, NaN, a tick number that jumped while
    the time did not - the sample is not trusted: the loop runs the tick on the tick's own time
    (tick × period, never before the previous one) and the supervisor holds until a sample with a
    consistent time comes.
``RECORD_ERROR`` (advisory)
    A writer of the run's record failed (the ``.tlog``, the ``.rrd``: a full disk, an I/O error).
    The writer stops, control goes on; the fault stays raised (an alarm) for the rest of the run,
    and the first failure of each writer is one line on stderr and in the summary (``record``).
``DEVICE_CHANGED`` (holding, latched until the clinician's ``ack``)
    A device hello in the middle of the run that changes its terms (drug, concentration, pump
    maximum, noise, sample period, link mode): the link session refused it on the wire and kept
    the first hello's terms (:meth:`link.RuntimeSession.take_hello_changes`); the loop latches
    the fault, prints the refusal and logs it.

``TARGET_INVALID`` (holding; ``pressor run`` with the device's target)
    The device's MAP_TARGET is bound like the clinician's own target, [50, 120] mmHg (not only
    to the supervisor's plausible MAP, [20, 250]): outside, the loop holds and the controller is
    not given it; the next target inside clears it.

A pump status's delivered rate is range-checked for the record: one outside [0, the device's
pump maximum] (or not finite) is filed as NaN, so the summary's drug totals never hold it (the
supervisor raises ``PUMP_MISMATCH`` on it).
"""

from __future__ import annotations

import math
import sys
from dataclasses import replace
from typing import Any, TextIO

from pressor.link import TickInputs
from pressor.runtime.core.supervisor_config import Fault

_SAMPLE_TIME = int(Fault.SAMPLE_TIME)
_RECORD_ERROR = int(Fault.RECORD_ERROR)
_DEVICE_CHANGED = int(Fault.DEVICE_CHANGED)
_TARGET_INVALID = int(Fault.TARGET_INVALID)


class Unwritten:
    """A record writer that could not start (no room on its disk): its ``error`` says why."""

    def __init__(self, error: str) -> None:
        self.error = error


class Boundary:
    """The loop's boundary checks (see the module docstring).

    Parameters
    ----------
    period_s
        The loop period (s).
    pump_max_ml_h
        The largest delivered rate (ml/h) a pump status may report: the device's announced pump
        maximum (at least the controller's).
    writers
        ``(name, writer)`` pairs of the run's record writers, each with an ``error`` attribute
        (``None`` while it works): the ``.tlog`` and the ``.rrd``.
    prog
        Program name in front of the lines on stderr.
    err
        Where those lines go (default ``sys.stderr``).
    target_limits
        ``(low, high)`` (mmHg): the targets a device's MAP_TARGET may set (``pressor run``: the
        clinician's own [50, 120] mmHg); ``None``: the supervisor's plausible-MAP range only.

    Attributes
    ----------
    record_errors
        The first failure of each writer: name -> one line naming the file and the cause.
    sample_time_faults
        Samples whose time was not trusted (``SAMPLE_TIME``).
    device_changes
        The refusals of mid-run hellos (their texts), in order.
    """

    def __init__(
        self,
        period_s: float,
        pump_max_ml_h: float,
        writers: list[tuple[str, Any]] | None = None,
        prog: str = "pressor",
        err: TextIO | None = None,
        target_limits: tuple[float, float] | None = None,
    ) -> None:
        self.period_s = float(period_s)
        self.pump_max_ml_h = float(pump_max_ml_h) * (1.0 + 1e-6)  # float32 on the wire
        self.writers = [(name, w) for name, w in writers or () if w is not None]
        self.prog = prog
        self.err = err
        self.target_limits = target_limits
        self.record_errors: dict[str, str] = {}
        self.sample_time_faults = 0
        self.device_changes: list[str] = []
        self._last_time_s = -math.inf
        self._record_fault = 0

    def sample_time(self, inp: TickInputs) -> tuple[TickInputs, int]:
        """The tick's inputs with a time the loop can run on, and ``SAMPLE_TIME`` if the sample's
        own time was not trusted (then replaced by tick × period, never before the previous)."""
        t = inp.sim_time_s
        expected = inp.tick * self.period_s
        if self._last_time_s <= t and abs(t - expected) <= 0.5 * self.period_s:  # False for NaN
            self._last_time_s = t
            return inp, 0
        now = max(expected, self._last_time_s)
        self._last_time_s = now
        self.sample_time_faults += 1
        return replace(inp, sim_time_s=now), _SAMPLE_TIME

    def device_target(self, inp: TickInputs) -> int:
        """``TARGET_INVALID`` when the device's MAP_TARGET lies outside :attr:`target_limits`
        (the device is bound as the clinician is: the loop holds, the controller never sees it)."""
        lim = self.target_limits
        if lim is None or lim[0] <= inp.target_mmhg <= lim[1]:
            return 0
        return _TARGET_INVALID  # NaN too: the supervisor raises it anyway

    def tick_faults(self, tick: int, t: float, recorder: Any = None) -> int:
        """The record writers' state at this tick (``RECORD_ERROR`` once one failed); a new
        failure is one line on stderr and an event in the recording (if it still works)."""
        for name, writer in self.writers:
            why = writer.error
            if why is not None and name not in self.record_errors:
                self.record_errors[name] = why
                self._record_fault = _RECORD_ERROR
                self._say(
                    f"RECORD_ERROR: the {name} stopped at tick {tick} (t = {t:g} s): {why};"
                    " control goes on",
                    tick,
                    t,
                    recorder,
                )
        return self._record_fault

    def device_changed(self, refusals: list[Any], tick: int, t: float, recorder: Any) -> int:
        """``DEVICE_CHANGED`` for the mid-run hellos the session refused (each told on stderr and
        in the recording), else 0."""
        for refusal in refusals:
            self.device_changes.append(refusal.text)
            self._say(
                f"DEVICE_CHANGED: {refusal.text}; HOLD until the clinician acknowledges (ack)",
                tick,
                t,
                recorder,
            )
        return _DEVICE_CHANGED if refusals else 0

    def delivered(self, delivered_ml_h: float) -> float:
        """The pump's delivered rate (ml/h) for the record: NaN unless in [0, pump maximum]."""
        if 0.0 <= delivered_ml_h <= self.pump_max_ml_h:  # False for NaN too
            return delivered_ml_h
        return math.nan

    def _say(self, line: str, tick: int, t: float, recorder: Any) -> None:
        print(f"{self.prog}: {line}", file=self.err or sys.stderr, flush=True)
        if recorder is not None:
            recorder.event(tick, t, line, warn=True)

    def summary(self) -> dict[str, Any]:
        """What the summary reports, only what happened: ``record`` (writer -> error),
        ``sample_time_faults`` and ``device_changes``."""
        out: dict[str, Any] = {}
        if self.record_errors:
            out["record"] = dict(self.record_errors)
        if self.sample_time_faults:
            out["sample_time_faults"] = self.sample_time_faults
        if self.device_changes:
            out["device_changes"] = list(self.device_changes)
        return out
