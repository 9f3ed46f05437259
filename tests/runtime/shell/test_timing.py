"""Clocks and timing statistics."""

from __future__ import annotations

import time

import numpy as np
import pytest

from pressor.runtime.shell.clock import MonotonicClock, PeriodicSchedule, VirtualClock
from pressor.runtime.shell.timing import TimingStats


def test_virtual_clock_follows_device_time_and_refuses_to_run_backwards():
    clock = VirtualClock()
    clock.advance_to(0.1)
    clock.advance_to(0.2)
    assert clock.now_s() == 0.2
    assert clock.wait_until(5.0) == 0.2  # lockstep: the sample is the release, no waiting
    with pytest.raises(ValueError, match="sim_time_s"):
        clock.advance_to(0.1)


def test_monotonic_clock_never_returns_before_the_deadline():
    clock = MonotonicClock()
    start = clock.now_s()
    reached = clock.wait_until(start + 0.01)
    assert reached >= start + 0.01
    assert clock.now_s() - start < 0.5


def test_schedule_uses_absolute_deadlines_and_counts_skipped_periods():
    sched = PeriodicSchedule(0.1, origin_s=1.0)
    assert sched.next_release(now_s=1.05) == (pytest.approx(1.1), 0)
    # a stall after release 1 (1.1 s) until 1.55 s: 1.2, 1.3, 1.4 are skipped, 1.5 runs late
    deadline, skipped = sched.next_release(now_s=1.55)
    assert skipped == 3
    assert deadline == pytest.approx(1.5)
    assert sched.deadline_s() == pytest.approx(1.0 + 0.1 * sched.index)


def test_stats_count_overruns_skips_and_give_percentiles_in_us():
    stats = TimingStats(period_s=0.1, capacity=1000)
    for i in range(100):
        stats.record(exec_s=(i + 1) * 1e-5, lateness_s=1e-4 if i == 50 else 0.0)
    stats.record(exec_s=0.2, skipped=2)
    s = stats.summary()
    assert s["ticks"] == 101
    assert s["overruns"] == 1
    assert s["skipped_periods"] == 2
    assert s["exec_max_us"] == pytest.approx(2e5)
    expected_p50 = np.percentile([*((i + 1) * 10.0 for i in range(100)), 2e5], 50)
    assert s["exec_p50_us"] == pytest.approx(expected_p50)
    assert s["lateness_max_us"] == pytest.approx(100.0)


def test_stats_ring_keeps_max_over_whole_run_after_wrapping():
    stats = TimingStats(period_s=0.1, capacity=16)
    stats.record(exec_s=0.05)
    for _ in range(40):
        stats.record(exec_s=1e-6)
    s = stats.summary()
    assert s["exec_max_us"] == pytest.approx(5e4)
    assert s["exec_p99_us"] == pytest.approx(1.0)


def test_recording_a_tick_does_not_allocate_arrays():
    stats = TimingStats(period_s=0.1, capacity=64)
    buffers = (id(stats._exec_s), id(stats._late_s))
    t0 = time.perf_counter()
    for _ in range(1000):
        stats.record(1e-6, 0.0)
    assert (id(stats._exec_s), id(stats._late_s)) == buffers
    assert time.perf_counter() - t0 < 1.0
