"""Clocks injected into the loop: virtual (lockstep, device-driven) and monotonic wall clock.

The loop never calls ``time`` itself; it asks a clock. Two clocks offer the same ``now_s`` and
``wait_until``:

``VirtualClock``
    Lockstep mode (PX4 SITL style). Time is the device's sim time: it advances only when the loop
    hands it the sim time carried by the sample for tick k (``advance_to``). Releases are the
    samples themselves, so ``wait_until`` returns at once and release lateness is 0 by
    construction. Everything that depends on time (watchdogs, signing timestamps) is therefore a
    pure function of the device's stream: two runs with the same seed are byte-identical.

``MonotonicClock``
    ``--realtime`` mode. ``time.perf_counter`` (monotonic, ns resolution on Linux). Releases are
    absolute deadlines ``t0 + k·period`` — never ``previous + period`` — so lateness does not
    accumulate. ``wait_until`` sleeps for the bulk of the interval and spins only the last
    ``spin_s`` (default 0.2 ms) to trade a little CPU for sub-millisecond release accuracy. Host
    stalls of 10–20 ms happen whatever the sleep method (docs/PLATFORM-NOTES.md); they show up as lateness
    and skipped periods in :mod:`pressor.runtime.shell.timing`, never as drift.

Both return seconds as float. ``perf_counter_s`` (always the wall clock) is used to measure the
loop's own execution time in both modes: execution time is a property of the host, not of sim time.
"""

from __future__ import annotations

import math
import time

from pressor.contracts.checks import check_range

perf_counter_s = time.perf_counter


class VirtualClock:
    """Sim time driven by the device in lockstep.

    Parameters
    ----------
    start_s
        Initial sim time (s), finite and ≥ 0.
    """

    def __init__(self, start_s: float = 0.0) -> None:
        if not (math.isfinite(start_s) and start_s >= 0.0):
            raise ValueError(f"start_s={start_s!r} must be finite and >= 0 s")
        self._now_s = float(start_s)

    def now_s(self) -> float:
        """The sim time (s) of the newest sample handed to :meth:`advance_to`."""
        return self._now_s

    def advance_to(self, sim_time_s: float) -> None:
        """Set the time to the device's ``sim_time_s`` (s); time never runs backwards.

        Raises
        ------
        ValueError
            If ``sim_time_s`` is not finite or is earlier than the current time.
        """
        if not math.isfinite(sim_time_s) or sim_time_s < self._now_s:
            raise ValueError(
                f"sim_time_s={sim_time_s!r} must be finite and >= current {self._now_s!r} s"
            )
        self._now_s = float(sim_time_s)

    def wait_until(self, deadline_s: float) -> float:
        """Lockstep releases are the samples themselves: return the current time at once."""
        return self._now_s


class MonotonicClock:
    """The monotonic wall clock with absolute deadlines (``--realtime``).

    Parameters
    ----------
    spin_s
        The last part (s) of each wait is a busy spin for release accuracy; in [0, 0.01].
    """

    def __init__(self, spin_s: float = 2e-4) -> None:
        check_range("spin_s", spin_s, 0.0, 0.01, unit="s")
        self._spin_s = float(spin_s)
        self._origin_s = time.perf_counter()

    def now_s(self) -> float:
        """Seconds since this clock was created (monotonic)."""
        return time.perf_counter() - self._origin_s

    def wait_until(self, deadline_s: float) -> float:
        """Sleep, then spin, until ``deadline_s``; return the time reached (s, ≥ deadline)."""
        now = self.now_s()
        remaining = deadline_s - now
        if remaining > self._spin_s:
            time.sleep(remaining - self._spin_s)
        now = self.now_s()
        while now < deadline_s:
            now = self.now_s()
        return now


class PeriodicSchedule:
    """Absolute release times ``origin + k·period`` with skipped-period accounting.

    After a stall longer than one period the next release is the most recent deadline already
    passed (so the tick runs at once, less than one period late); the periods jumped over before it
    are counted as skipped. The loop never catches up by running a burst of late ticks — a bedside
    box must not do that either.

    Parameters
    ----------
    period_s
        Loop period (s), > 0.
    origin_s
        Time (s, the clock's) of release 0.
    """

    def __init__(self, period_s: float, origin_s: float = 0.0) -> None:
        if not (math.isfinite(period_s) and period_s > 0.0):
            raise ValueError(f"period_s={period_s!r} must be finite and > 0 s")
        self.period_s = float(period_s)
        self.origin_s = float(origin_s)
        self.index = 0

    def deadline_s(self) -> float:
        """The release time (s) of the current period."""
        return self.origin_s + self.index * self.period_s

    def next_release(self, now_s: float) -> tuple[float, int]:
        """Advance to the next period; skip those already past at ``now_s``.

        Returns
        -------
        (deadline_s, skipped)
            The new release time (s) and how many periods were skipped to reach it.
        """
        self.index += 1
        skipped = 0
        deadline = self.deadline_s()
        if now_s > deadline + self.period_s:
            skipped = int((now_s - deadline) // self.period_s)
            self.index += skipped
            deadline = self.deadline_s()
        return deadline, skipped
