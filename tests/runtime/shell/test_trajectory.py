"""The trajectory a run keeps: every value read back as stored, in memory that grows by less than
1 MB per simulated hour at 10 Hz (a ring: not at all)."""

from __future__ import annotations

import gc
import math
import tracemalloc

import numpy as np
import pytest

from pressor.link import TickInputs
from pressor.runtime.core.closed_loop import TickRecord
from pressor.runtime.core.supervisor_config import State
from pressor.runtime.core.supervisor_io import SupervisorOutput
from pressor.runtime.shell.trajectory import Trajectory

PERIOD_S = 0.1
TICKS_PER_H = 36000


def _record(tick: int, t_s: float, target: float, command: float, faults: int, state: int):
    inputs = TickInputs(tick, t_s, math.nan, 0, target, 1.0, 200.0, 20.0, True, tick, tick)
    out = SupervisorOutput(True, State(state), faults, 0, None, command, False)
    return TickRecord(inputs, command, math.nan, out, None)


def _feed(traj: Trajectory, start: int, stop: int, rng: np.random.Generator) -> None:
    """Ticks ``start`` … ``stop − 1`` as a run at 10 Hz gives them: MAP and the delivered rate as
    float32 (the wire's), a float64 command, a target step, an AUTO state with a fault now and
    then, the device's time ``tick × period``."""
    maps = rng.normal(70.0, 5.0, stop - start).astype(np.float32)
    commands = rng.uniform(0.0, 120.0, stop - start)
    for k in range(start, stop):
        i = k - start
        faults = 4 if k % 5000 < 30 else 0
        rec = _record(k, k * PERIOD_S, 65.0 if k < 3000 else 85.0, commands[i], faults, 1)
        traj.append(rec, float(maps[i]))
        traj.delivered(k + 1, float(np.float32(commands[i])))


def _kept_mb(traj: Trajectory) -> float:
    gc.collect()
    return tracemalloc.get_traced_memory()[0] / 1e6


@pytest.mark.parametrize("ring", [False, True])
def test_the_kept_trajectory_grows_by_less_than_1_mb_per_hour_and_a_ring_not_at_all(ring):
    rng = np.random.default_rng(1)
    ten_min, forty_min = TICKS_PER_H // 6, 4 * TICKS_PER_H // 6
    tracemalloc.start()
    try:
        traj = (
            Trajectory(4096, ring=True, period_s=PERIOD_S)
            if ring
            else Trajectory(period_s=PERIOD_S)
        )
        _feed(traj, 0, ten_min, rng)
        at_10_min = _kept_mb(traj)
        _feed(traj, ten_min, forty_min, rng)
        at_40_min = _kept_mb(traj)
    finally:
        tracemalloc.stop()
    growth_mb_h = (at_40_min - at_10_min) / 0.5
    if ring:
        assert abs(growth_mb_h) < 0.05 and len(traj.arrays()["tick"]) == 4096
    else:
        assert growth_mb_h <= 1.0, f"{growth_mb_h:.2f} MB/h"  # all 72 bytes a tick: 2.6 MB/h
        assert traj.nbytes / (forty_min / TICKS_PER_H) / 1e6 <= 1.0
        assert len(traj.arrays()["tick"]) == forty_min


def test_every_value_stored_reads_back_exactly():
    # a MAP that is no float32 (the column turns float64), an inf, a device clock that departs
    # from tick x period (then its own column), a tick jump, targets and states that change
    traj = Trajectory(period_s=PERIOD_S)
    rng = np.random.default_rng(2)
    rows = []
    tick = 0
    for row in range(3000):
        tick += 1 if row != 1500 else 10**6
        t = tick * PERIOD_S if row < 2000 else tick * PERIOD_S + rng.uniform(0, 0.01)
        map_mmhg = {700: 70.123456789, 800: math.inf, 900: math.nan}.get(row, float(row % 90))
        target = 60.0 + (row // 1000) * 10.0
        command = float(rng.uniform(0, 120))
        faults, state = (row // 250) % 3, 1 + (row // 600) % 3
        traj.append(_record(tick, t, target, command, faults, state), map_mmhg)
        delivered = command if row % 7 else math.nan
        if row % 7:
            traj.delivered(tick + 1, delivered)
        rows.append((tick, t, map_mmhg, target, command, delivered, faults, state))
    got = traj.arrays()
    expected = np.array(rows)
    for i, name in enumerate(Trajectory.FIELDS):
        np.testing.assert_array_equal(got[name], expected[:, i], err_msg=name)
    assert got["tick"].dtype == np.int64 and got["state"].dtype == np.int64
    assert traj.last_tick() == tick


def test_a_ring_reads_back_exactly_its_last_capacity_ticks():
    traj = Trajectory(4096, ring=True, period_s=PERIOD_S)
    _feed(traj, 0, 20000, np.random.default_rng(3))
    got = traj.arrays()
    assert list(got["tick"]) == list(range(20000 - 4096, 20000))
    np.testing.assert_array_equal(got["sim_time_s"], got["tick"] * PERIOD_S)
    assert set(got["target_mmhg"]) == {85.0}


@pytest.mark.parametrize(
    "clock",
    ["tick x period", "through float32", "float32 period", "the device's own"],
)
def test_sample_times_cost_nothing_while_they_follow_the_tick_and_always_read_back(clock):
    rng = np.random.default_rng(4)
    rule = {
        "tick x period": lambda k: k * PERIOD_S,
        "through float32": lambda k: float(np.float32(k * PERIOD_S)),  # the simulated device's
        "float32 period": lambda k: k * float(np.float32(PERIOD_S)),
        "the device's own": lambda k: k * PERIOD_S + float(rng.uniform(0.0, 0.01)),
    }[clock]
    traj = Trajectory(period_s=PERIOD_S)
    times = [rule(k) for k in range(8192)]
    for k, t in enumerate(times):
        traj.append(_record(k, t, 80.0, 10.0, 0, 1), 70.0)  # constant float32 columns
    assert list(traj.arrays()["sim_time_s"]) == times
    bytes_per_tick = traj.nbytes / len(times)  # MAP, command, delivered: float32 here
    if clock == "the device's own":
        assert 20 <= bytes_per_tick < 21  # the times stored, as float64
    else:
        assert bytes_per_tick < 12.1  # not stored
