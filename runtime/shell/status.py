"""One line of the run's state at a steady interval, for whoever watches a long run.

``pressor run`` (and ``pressor sil --realtime``) print, every ``--status-every`` wall seconds
(default 30 s; ``--quiet`` turns it off), one line on stderr: the run time, the supervisor's
state, the MAP and the target, the dose and the alarms::

    pressor run  0:05:00  AUTO  MAP 74.8 mmHg  target 75.0 mmHg  12.0 ml/h = 0.29 µg/kg/min  alarms: none

The lines are whole lines (not a redrawn one), so a log or a pipe keeps them. The per-tick cost is
one comparison; the wall clock is read every ``check_every`` ticks.
"""

from __future__ import annotations

import math
import sys
import time
from typing import Any, TextIO

from pressor.runtime.core.supervisor_config import State, fault_names
from pressor.runtime.shell.progress import clock

#: default wall time between two status lines (s)
DEFAULT_STATUS_EVERY_S = 30.0


class StatusLine:
    """Per-tick callback writing the run's state every ``interval_s`` wall seconds.

    Parameters
    ----------
    prog
        The command's name, first on each line.
    period_s
        Sample period (s): the run time is ``tick * period_s``.
    concentration_ug_ml
        The syringe (µg/ml), to show the dose beside the rate; None shows ml/h only.
    weight_kg
        The patient's weight (kg): the dose in µg/kg/min; None: in µg/min.
    interval_s
        Wall seconds between two lines, > 0.
    stream
        Where to write (default stderr).
    check_every
        Ticks between two looks at the wall clock, >= 1.
    """

    def __init__(
        self,
        prog: str,
        period_s: float,
        concentration_ug_ml: float | None = None,
        weight_kg: float | None = None,
        interval_s: float = DEFAULT_STATUS_EVERY_S,
        stream: TextIO | None = None,
        check_every: int = 10,
    ) -> None:
        if not (math.isfinite(interval_s) and interval_s > 0.0):
            raise ValueError(f"interval_s={interval_s!r} must be finite and > 0")
        self.prog = prog
        self.period_s = float(period_s)
        self.concentration_ug_ml = concentration_ug_ml
        self.weight_kg = weight_kg
        self.interval_s = float(interval_s)
        self.stream = sys.stderr if stream is None else stream
        self.check_every = max(1, int(check_every))
        self._last: float | None = None
        self.lines = 0

    def __call__(self, rec: Any) -> None:
        """The loop's per-tick status hook (``rec``: a :class:`pressor.runtime.core.closed_loop.TickRecord`)."""
        if rec.inputs.tick % self.check_every:
            return
        now = time.monotonic()
        if self._last is None:  # the interval starts with the loop
            self._last = now
            return
        if now - self._last >= self.interval_s:
            self._last = now
            self.stream.write(self.line(rec) + "\n")
            self.stream.flush()
            self.lines += 1

    def dose(self, rate_ml_h: float) -> str:
        """``rate_ml_h`` with its dose beside it: ``12.0 ml/h = 0.29 µg/kg/min`` (or µg/min)."""
        text = f"{rate_ml_h:.1f} ml/h"
        c = self.concentration_ug_ml
        if c is None:
            return text
        ug_min = rate_ml_h * c / 60.0
        if self.weight_kg is None:
            return f"{text} = {ug_min:.1f} µg/min"
        return f"{text} = {ug_min / self.weight_kg:.3g} µg/kg/min"

    def line(self, rec: Any) -> str:
        """The status text of the tick ``rec``."""
        out, inp = rec.supervisor, rec.inputs
        mp = "no sample" if not math.isfinite(inp.map_mmhg) else f"{inp.map_mmhg:.1f} mmHg"
        alarms = ", ".join(fault_names(out.faults)) or "none"
        return (
            f"{self.prog}  {clock(inp.tick * self.period_s)}  {State(out.state).name}"
            f"  MAP {mp}  target {inp.target_mmhg:.1f} mmHg  {self.dose(out.command_ml_h)}"
            f"  alarms: {alarms}"
        )
