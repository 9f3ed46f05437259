"""The one closed-loop core: supervisor, scheduling source and controller stepped in one place.

Per tick the caller hands over what arrived for the tick (:class:`link.TickInputs`: MAP sample,
target and whatever scheduling parameters the device sent), the pump status of the tick
(:class:`link.PumpStatus`, if one arrived) and the link's health; :meth:`ClosedLoopCore.step`
feeds the scheduling source (:mod:`pressor.runtime.core.scheduling`: oracle, estimated, nominal or
validated) the MAP sample, its quality bits and the pump's latest delivered rate (0 ml/h before any
status), assesses the inputs - the supervisor's scheduling checks see the K, T, τ the source
returned -
steps the controller with those K, T, τ if the supervisor allows it, finalizes the command and
returns a :class:`TickRecord`. The caller sends ``record.command_ml_h`` to the pump.

Sample-and-hold (docs/PROTOCOL.md). A monitor slower than the loop leaves ticks without a new
value: in lockstep the device repeats the last one with ``QUALITY_HELD``, in real time no sample
arrives and the loop hands over the newest one with its link age. The sample's age is the time
since the last sample *without* ``QUALITY_HELD`` was received; the supervisor sees that age
(``STALE_SAMPLE`` past its limit, and its flatline rules judge only new samples, age 0). Until the
limit the controller and the scheduling source both get the held value (``QUALITY_HELD`` removed
from the bits the source's gate sees): a digital loop with a slower sensor is a zero-order hold of
the measurement, and a NaN would freeze the controllers instead (the generated LPV and the PI hold
their command and stop their integrators and reference model on a non-finite MAP, the Smith
predictor stops integrating), while the estimator's window means need the held values (a 1 Hz
monitor fills a tenth of a 10 Hz window). Past the limit the source gets NaN and the supervisor
does not step the controller.

Two callers drive the same core, so they cannot drift apart:

- the runtime loop (:mod:`pressor.runtime.shell.loop`), which adds only link I/O, timing and recording;
- the in-process trial (:func:`pressor.hil_sim.episode.simulate`), which feeds it the world's
  observations and pump statuses directly, with a perfect link (:data:`CLEAN_LINK`).

A lockstep SIL run and an in-process run of the same seed therefore give the same commands and
the same supervisor states, tick for tick.

A controller that fails. The controller is the algorithm; the core is part of the shell that
handles its faults (PX4's rule). When ``step`` raises, or returns something ``float()`` refuses,
the supervisor's ``controller_faults`` decides: ``"stop"`` (``pressor sil``, ``trial``, the API)
raises :class:`ControllerError` - the run ends and the researcher sees the bug; ``"latch"``
(``pressor run``) hands the failure to the supervisor (``CONTROLLER_FAULT``: HOLD at the held rate,
alarm, until the clinician acknowledges; :mod:`pressor.runtime.core.supervisor`) and the tick's record
carries the error's text (``TickRecord.controller_error``; also for a non-finite command, the
supervisor's ``COMMAND_INVALID``) for the shell to log; the loop goes on.
"""

from __future__ import annotations

import math
import sys
from typing import NamedTuple

from pressor.contracts.controller import Controller
from pressor.contracts.faults import QUALITY_HELD
from pressor.link import PumpStatus, TickInputs
from pressor.runtime.core.scheduling import OracleSchedule, Schedule, ScheduleInput, ScheduleSource
from pressor.runtime.core.supervisor import Supervisor, SupervisorInput, SupervisorOutput


class LinkHealth(NamedTuple):
    """The link's state at a tick, as the supervisor's watchdogs need it (immutable).

    Attributes
    ----------
    sample_age_s
        Time (s) since the newest MAP sample was received (a held one too; the core ages a
        ``QUALITY_HELD`` sample from the last sample without the bit).
    link_silence_s
        Time (s) since any frame was received from the device.
    link_errors
        Frames the link layer discarded since the previous tick.
    boundary_faults
        Fault bits the shell found in the tick's inputs before the core
        (:data:`pressor.runtime.core.supervisor_config.BOUNDARY_FAULTS`: a sample time that is not
        finite, runs backwards or disagrees with its tick; a record writer that failed); 0 in
        process.
    """

    sample_age_s: float
    link_silence_s: float
    link_errors: int
    boundary_faults: int = 0


class ControllerError(RuntimeError):
    """The controller raised, or returned something that is not a number, at a tick, and the
    supervisor's ``controller_faults`` is ``"stop"``: the run ends with this error (its message
    names the controller's class and module, the tick and the cause) instead of a traceback or a
    hang; the callers turn it into exit 1 (``pressor sil``) or raise it (``pressor trial``,
    :mod:`pressor.api`). ``pressor run`` latches a ``CONTROLLER_FAULT`` instead."""


def _controller_failed(controller: Controller, tick: int, now_s: float, cause: str) -> str:
    """One line naming the controller's class and module (or file), the tick, its time (s) and
    ``cause`` (the exception's repr, or what it returned)."""
    cls = type(controller)
    module = cls.__module__
    if module.startswith("_pressor_"):  # imported from a file: name the file
        module = getattr(sys.modules.get(module), "__file__", None) or module
    return (
        f"controller {cls.__qualname__!r} (module {module!r}) failed at tick {tick}"
        f" (t = {now_s:g} s): {cause}"
    )


#: builds a named tuple from a tuple of its fields without the named tuple's Python-level __new__
_new_tuple = tuple.__new__
#: ``math.nan`` and ``math.inf`` without the module attribute lookups (the per-tick path)
_NAN, _INF = math.nan, math.inf

#: a link that delivers every tick on time and loses nothing (the in-process trial)
CLEAN_LINK = LinkHealth(sample_age_s=0.0, link_silence_s=0.0, link_errors=0)


class TickRecord(NamedTuple):
    """One tick of the closed loop (immutable; a named tuple for the per-tick cost).

    Attributes
    ----------
    inputs
        What the tick was given.
    controller_ml_h
        The controller's raw command (ml/h); NaN when the supervisor did not step it.
    pump_delivered_ml_h
        Delivered rate (ml/h) of the tick's pump status; NaN when none arrived for the tick.
    supervisor
        The supervisor's decision; ``supervisor.command_ml_h`` is the command for the pump.
    schedule
        The scheduling source's report of the tick: the K, T, τ the controller was given.
    controller_error
        When the controller failed at this tick under ``controller_faults="latch"``: one line
        naming it, the tick and the cause (:class:`ControllerError`'s text); else ``None``.
    """

    inputs: TickInputs
    controller_ml_h: float
    pump_delivered_ml_h: float
    supervisor: SupervisorOutput
    schedule: Schedule
    controller_error: str | None = None

    @property
    def command_ml_h(self) -> float:
        """The command (ml/h) for the pump."""
        return self.supervisor.command_ml_h


class ClosedLoopCore:
    """Supervisor and controller stepped together, once per tick.

    Parameters
    ----------
    controller
        Any :class:`~pressor.contracts.controller.Controller`.
    supervisor
        The safety supervisor (its config's period must match the controller's).
    schedule
        Where K, T, τ come from (:func:`pressor.runtime.estimation.sources.make_schedule`); default the
        oracle (the device's values, as sent).
    """

    def __init__(
        self,
        controller: Controller,
        supervisor: Supervisor,
        schedule: ScheduleSource | None = None,
    ) -> None:
        if abs(supervisor.config.sample_period_s - controller.sample_period_s) > 1e-12:
            raise ValueError(
                f"supervisor sample_period_s={supervisor.config.sample_period_s} s differs from"
                f" the controller's {controller.sample_period_s} s"
            )
        self.controller = controller
        self.supervisor = supervisor
        self.schedule = schedule if schedule is not None else OracleSchedule()
        self._estimated = self.schedule.source in ("estimated", "validated")
        self._latest_delivered_ml_h = 0.0  # the pump's latest delivered rate; 0 before any status
        self._fresh_s = -math.inf  # when the last sample without QUALITY_HELD was received (s)
        self._age_limit_s = supervisor.config.stale_after_s
        self._stop_on_error = supervisor.config.controller_faults == "stop"

    def sample_age_s(self, quality: int, now_s: float, link_age_s: float) -> float:
        """The age (s) of this tick's sample: since its receipt, or for a ``QUALITY_HELD`` one since
        the last sample without the bit (infinite before any)."""
        if quality & QUALITY_HELD:
            return now_s - self._fresh_s
        self._fresh_s = now_s - link_age_s
        return link_age_s

    def step(
        self, inp: TickInputs, now_s: float, pump: PumpStatus | None, link: LinkHealth
    ) -> TickRecord:
        """Run one tick and return its record.

        Parameters
        ----------
        inp
            The tick's inputs (newest sample, target, scheduling parameters).
        now_s
            Time (s) of the tick on the loop's clock.
        pump
            The pump status that arrived for this tick (``pump.tick == inp.tick``), else ``None``.
        link
            The link's health at this tick.
        """
        if pump is not None:
            self._latest_delivered_ml_h = pump.delivered_ml_h
            if pump.tick == inp.tick:
                delivered, alarms = pump.delivered_ml_h, pump.alarms
            else:
                delivered, alarms = _NAN, 0
        else:
            delivered, alarms = _NAN, 0
        age_s = self.sample_age_s(inp.quality, now_s, link.sample_age_s)
        # tuple.__new__ rather than ScheduleInput(...): the per-tick path, and a named tuple's
        # own __new__ is a Python-level call (~0.2 µs a tick; fields in declaration order)
        sched = self.schedule.update(
            _new_tuple(
                ScheduleInput,
                (
                    inp.map_mmhg if age_s <= self._age_limit_s else _NAN,
                    inp.quality & ~QUALITY_HELD,
                    self._latest_delivered_ml_h,
                    inp.K,
                    inp.T_s,
                    inp.tau_s,
                    inp.sched_valid,
                    inp.target_mmhg,
                ),
            )
        )
        K, T_s, tau_s = sched.K, sched.T_s, sched.tau_s
        sup = self.supervisor
        run = sup.assess(  # tuple.__new__ again (fields in declaration order, every one given)
            _new_tuple(
                SupervisorInput,
                (
                    now_s,
                    inp.map_mmhg,
                    inp.quality,
                    K,
                    T_s,
                    tau_s,
                    sched.valid,
                    age_s,
                    link.link_silence_s,
                    inp.target_mmhg,
                    link.link_errors,
                    delivered,
                    alarms,
                    self._estimated,
                    sched.healthy,
                    link.boundary_faults,
                ),
            )
        )
        raw = None
        if run:
            try:
                raw = self.controller.step(inp.map_mmhg, inp.target_mmhg, K, T_s, tau_s)
                if raw.__class__ is not float:  # numpy scalars, ints; a str or None is an error
                    raw = float(raw)
            except Exception as exc:
                error = _controller_failed(self.controller, inp.tick, now_s, repr(exc))
                if self._stop_on_error:
                    raise ControllerError(error) from exc
                out = sup.finalize(None, failed=True)
                return TickRecord(inp, math.nan, delivered, out, sched, error)
        out = sup.finalize(raw)
        # the record of a tick without an error built with tuple.__new__ too (its default given)
        if raw is None:
            return _new_tuple(TickRecord, (inp, _NAN, delivered, out, sched, None))
        if not self._stop_on_error and not -_INF < raw < _INF:  # nan fails it too
            error = _controller_failed(self.controller, inp.tick, now_s, f"returned {raw!r}")
            return TickRecord(inp, raw, delivered, out, sched, error)
        return _new_tuple(TickRecord, (inp, raw, delivered, out, sched, None))
