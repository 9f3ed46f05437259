"""One status line on a terminal while a run lasts: simulated time and real-time factor.

``pressor sil`` passes a :class:`TerminalProgress` as the loop's per-tick callback. It writes to
stderr only when stderr is a terminal (``isatty``), so logs, pipes and tests stay clean, and
redraws at most every ``interval_s`` wall seconds (checked every ``check_every`` ticks, so the
per-tick cost is one increment and one comparison).
"""

from __future__ import annotations

import sys
import time
from typing import TextIO


def clock(seconds: float) -> str:
    """``seconds`` as ``H:MM:SS`` (or ``M:SS`` under an hour)."""
    s = int(seconds)
    h, rest = divmod(s, 3600)
    return f"{h}:{rest // 60:02d}:{rest % 60:02d}" if h else f"{rest // 60}:{rest % 60:02d}"


class TerminalProgress:
    """Per-tick callback drawing ``sim M:SS / M:SS (P %)  N x real time`` on one line.

    Parameters
    ----------
    period_s
        Sample period (s): simulated time is ``tick * period_s``.
    total_ticks
        Ticks the run will take (0: unknown; no percentage shown).
    stream
        Where to draw (default stderr); nothing is drawn unless it is a terminal.
    interval_s
        Shortest wall time (s) between two redraws.
    check_every
        Ticks between two looks at the wall clock.
    """

    def __init__(
        self,
        period_s: float,
        total_ticks: int = 0,
        stream: TextIO | None = None,
        interval_s: float = 0.5,
        check_every: int = 100,
    ) -> None:
        self.stream = sys.stderr if stream is None else stream
        self.enabled = bool(getattr(self.stream, "isatty", lambda: False)())
        self.period_s = float(period_s)
        self.total_ticks = int(total_ticks)
        self.interval_s = float(interval_s)
        self.check_every = max(1, int(check_every))
        self._start = time.perf_counter()
        self._last = self._start
        self._drawn = False
        self._first_tick: int | None = None

    def __call__(self, tick: int, state: int, faults: int, command_ml_h: float) -> None:
        """The loop's ``on_tick``: redraw when due (the other arguments are not used)."""
        if not self.enabled or tick % self.check_every:
            return
        now = time.perf_counter()
        if self._first_tick is None:  # the clock starts with the loop, not at the handshake
            self._first_tick, self._start, self._last = tick, now, now
            return
        if now - self._last >= self.interval_s:
            self._last = now
            self.draw(tick + 1, now - self._start, tick - self._first_tick)

    def line(self, ticks: int, wall_s: float, ticks_timed: int | None = None) -> str:
        """The status text after ``ticks`` ticks, ``ticks_timed`` of them (default all) in
        ``wall_s`` wall seconds."""
        sim_s = ticks * self.period_s
        timed_s = sim_s if ticks_timed is None else ticks_timed * self.period_s
        text = f"sim {clock(sim_s)}"
        if self.total_ticks:
            total_s = self.total_ticks * self.period_s
            text += f" / {clock(total_s)} ({100.0 * ticks / self.total_ticks:.0f} %)"
        if wall_s > 0:
            text += f"  {timed_s / wall_s:.0f}x real time"
        return text

    def draw(self, ticks: int, wall_s: float, ticks_timed: int | None = None) -> None:
        """Overwrite the status line (:meth:`line`)."""
        self.stream.write("\r" + self.line(ticks, wall_s, ticks_timed) + "\033[K")
        self.stream.flush()
        self._drawn = True

    def close(self) -> None:
        """Clear the status line (if one was drawn), leaving the terminal as it was."""
        if self._drawn:
            self.stream.write("\r\033[K")
            self.stream.flush()
            self._drawn = False
