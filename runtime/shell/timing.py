"""Loop timing statistics: execution time, release lateness, overruns, skipped periods.

PX4-style perf counters for the loop shell. :class:`TimingStats` stores one execution time and one
lateness per tick in preallocated ``float64`` ring buffers (``capacity`` ticks, default 2**16 =
1.8 h at 10 Hz); recording a tick writes two array slots and bumps integer counters — no allocation
on the hot path. Percentiles (p50/p99) are computed on demand over the ticks still in the ring; the
maximum and the counters cover the whole run.

Definitions (all per tick k, times in s, reported in µs):

- execution time: wall time from the tick's release (sample in hand) to the command sent and the
  tick recorded — the loop's own work, always measured on the wall clock;
- release lateness: actual start minus the absolute deadline ``t0 + k·period`` (0 in lockstep, where
  the sample *is* the release);
- overrun: execution time > period;
- skipped periods: deadlines passed without a tick (a stall longer than a period).
"""

from __future__ import annotations

import numpy as np


class TimingStats:
    """Allocation-free per-tick timing counters with p50/p99/max on demand.

    Parameters
    ----------
    period_s
        Loop period (s), > 0; an execution time above it is an overrun.
    capacity
        Ring size (ticks) kept for percentiles, ≥ 16.
    """

    def __init__(self, period_s: float, capacity: int = 1 << 16) -> None:
        if not period_s > 0.0:
            raise ValueError(f"period_s={period_s!r} must be > 0 s")
        if capacity < 16:
            raise ValueError(f"capacity={capacity!r} must be >= 16 ticks")
        self.period_s = float(period_s)
        self._exec_s = np.zeros(capacity, dtype=np.float64)
        self._late_s = np.zeros(capacity, dtype=np.float64)
        self._capacity = capacity
        self.ticks = 0
        self.overruns = 0
        self.skipped = 0
        self.exec_max_s = 0.0
        self.late_max_s = 0.0

    def record(self, exec_s: float, lateness_s: float = 0.0, skipped: int = 0) -> None:
        """Count one tick: its execution time (s), release lateness (s) and periods skipped before it."""
        i = self.ticks % self._capacity
        self._exec_s[i] = exec_s
        self._late_s[i] = lateness_s
        self.ticks += 1
        self.skipped += skipped
        if exec_s > self.period_s:
            self.overruns += 1
        if exec_s > self.exec_max_s:
            self.exec_max_s = exec_s
        if lateness_s > self.late_max_s:
            self.late_max_s = lateness_s

    def _window(self, ring: np.ndarray) -> np.ndarray:
        return ring[: min(self.ticks, self._capacity)]

    def summary(self) -> dict[str, float | int]:
        """Counters and p50/p99/max (µs) of execution time and lateness; JSON-ready.

        Percentiles are over the last ``capacity`` ticks; max and counts over the whole run.
        With no tick recorded the percentiles are 0.
        """
        out: dict[str, float | int] = {
            "ticks": self.ticks,
            "overruns": self.overruns,
            "skipped_periods": self.skipped,
        }
        for name, ring, peak in (
            ("exec", self._exec_s, self.exec_max_s),
            ("lateness", self._late_s, self.late_max_s),
        ):
            window = self._window(ring)
            if window.size:
                p50, p99 = np.percentile(window, [50.0, 99.0])
            else:
                p50 = p99 = 0.0
            out[f"{name}_p50_us"] = round(float(p50) * 1e6, 3)
            out[f"{name}_p99_us"] = round(float(p99) * 1e6, 3)
            out[f"{name}_max_us"] = round(float(peak) * 1e6, 3)
        return out
