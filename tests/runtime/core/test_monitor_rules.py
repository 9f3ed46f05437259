"""Supervision of a real monitor: integer mmHg at 1 Hz with honest noise, under a 10 Hz loop.

Each rule has a run with the quantized monitor on a steady patient (must not fire) and one with the
real fault (must fire within its documented latency). The monitor is the simulator's
(:mod:`pressor.hil_sim.devices.sensor`, repeating its value with ``QUALITY_HELD`` between updates) driven through
the runtime's closed-loop core in process, as ``pressor trial`` and a lockstep ``pressor sil`` run.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pressor.baselines.pi import PIController
from pressor.contracts.faults import QUALITY_HELD, QUALITY_WAVEFORM, parse_faults
from pressor.hil_sim.episode import simulate
from pressor.hil_sim.scenarios.scenario import parse_scenario
from pressor.hil_sim.world import World
from pressor.link.messages import TickInputs
from pressor.runtime.core.closed_loop import CLEAN_LINK, ClosedLoopCore
from pressor.runtime.core.flatline import FlatlineRules, grain_mmhg, stuck_samples
from pressor.runtime.core.supervisor import Supervisor, SupervisorInput
from pressor.runtime.core.supervisor_config import (
    Fault,
    State,
    SupervisorConfig,
    supervisor_config_for,
)
from tests.support.supervisor_rig import good_inputs

TS = 0.1
HOUR_S = 3600.0


def bedside(noise_mmhg: float, duration_s: float = HOUR_S) -> dict:
    """A steady patient at its target (no step) watched by a 1 Hz, 1 mmHg monitor."""
    return {
        "name": "bedside",
        "duration_s": duration_s,
        "patient": {"mode": "frozen", "K": 0.5, "T_s": 150.0, "tau_s": 30.0, "baseline_mmhg": 65},
        "target": {"step_mmhg": 0.0},
        "sensor": {"period_s": 1.0, "quantum_mmhg": 1.0, "noise_std_mmhg": noise_mmhg},
    }


def run(noise_mmhg: float, faults: tuple[str, ...] = (), duration_s: float = HOUR_S):
    world = World(parse_scenario(bedside(noise_mmhg, duration_s)), 7, TS)
    if faults:
        world = World(world.scenario, 7, TS, faults=tuple(parse_faults(list(faults))))
    return simulate(world, PIController(TS), duration_s)


def first_tick(tr, fault: Fault) -> int | None:
    hits = np.flatnonzero(tr.faults.astype(np.int64) & int(fault))
    return int(hits[0]) if hits.size else None


@pytest.mark.parametrize("noise_mmhg", [1.0, 0.5])
def test_a_quantized_1hz_monitor_on_a_steady_patient_for_an_hour_raises_no_fault(noise_mmhg):
    tr = run(noise_mmhg)
    assert np.count_nonzero(tr.quality & QUALITY_HELD) >= 0.89 * tr.t_s.size  # 9 ticks in 10
    assert len(set(tr.map_mmhg[tr.map_mmhg == tr.map_mmhg])) >= 3  # integer mmHg, moving
    assert np.all(np.mod(tr.map_mmhg, 1.0) == 0.0)
    assert tr.faults.max() == 0  # no MAP_FLATLINE, STALE_SAMPLE or SENSOR_QUALITY, ever
    assert np.all(tr.state == State.AUTO)


def test_a_frozen_line_on_the_quantized_monitor_is_a_flatline_within_the_stuck_count():
    n = stuck_samples(1.0, 1.0, SupervisorConfig().flatline_eps_mmhg)
    assert n == 23  # new samples: 23 s at 1 Hz for a 1e-9 false alarm per sample
    # never flagged by the monitor's own waveform check: only the supervisor can see it
    tr = run(1.0, ("sensor-flatline:start_s=600,duration_s=120,flag_after_s=86400",), 900.0)
    k = first_tick(tr, Fault.MAP_FLATLINE)
    assert k is not None and 600.0 < tr.t_s[k] <= 600.0 + n
    assert first_tick(tr, Fault.SENSOR_QUALITY) is None
    assert tr.state[k] == State.HOLD


def test_a_disconnected_line_reading_atmospheric_is_out_of_range_at_the_next_update():
    tr = run(1.0, ("sensor-disconnect:start_s=600,duration_s=20",), 700.0)
    k = first_tick(tr, Fault.MAP_RANGE)
    assert k is not None and tr.t_s[k] == pytest.approx(600.0)
    assert tr.state[k] == State.HOLD


def test_a_damped_line_flagged_by_the_monitors_waveform_check_is_a_quality_fault_on_held_ticks_too():
    tr = run(1.0, ("sensor-damped:start_s=600,duration_s=60,flag_after_s=5",), 700.0)
    k = first_tick(tr, Fault.SENSOR_QUALITY)
    assert k is not None and tr.t_s[k] == pytest.approx(605.0)
    later = slice(k, k + 10)  # the repeats of the flagged value until the next update
    assert np.all(tr.quality[later] & QUALITY_WAVEFORM)
    assert np.all(tr.quality[k + 1 : k + 10] & QUALITY_HELD)
    assert np.all(tr.faults[later].astype(np.int64) & int(Fault.SENSOR_QUALITY))


class Feed:
    """A supervisor fed one monitor update per second and HELD repeats in between (10 Hz)."""

    def __init__(self, noise_mmhg: float) -> None:
        self.sup = Supervisor(SupervisorConfig(sample_period_s=TS, sensor_noise_mmhg=noise_mmhg))
        self.k = 0
        self.first: dict[str, float] = {}

    def second(self, map_mmhg: float) -> None:
        for j in range(10):
            args = {
                **good_inputs(self.k * TS),
                "map_mmhg": map_mmhg,
                "quality": QUALITY_HELD if j else 0,
                "sample_age_s": j * TS,
            }
            self.k += 1
            self.sup.finalize(10.0 if self.sup.assess(SupervisorInput(**args)) else None)
            for name in self.sup.detections:
                self.first.setdefault(name, self.k * TS)


def test_a_damped_line_that_smooths_away_the_noise_is_a_variance_collapse_flatline():
    rng = np.random.default_rng(3)
    drift = 80.0 + 0.1 * np.arange(300.0)  # the patient drifts 0.1 mmHg/s: steps, never stuck
    honest, damped = Feed(1.0), Feed(1.0)
    for t, truth in enumerate(drift):
        honest.second(round(truth + rng.normal(0.0, 1.0)))
        # before 100 s the same honest monitor; then a damped line: the beat-to-beat noise is gone
        damped.second(round(truth + (rng.normal(0.0, 1.0) if t < 100 else 0.0)))
    assert honest.first == {}
    assert set(damped.first) == {"MAP_FLATLINE"}
    # the window: 30 new samples (and 10 s) of smooth readings after the damping began
    assert 100.0 + 29.0 <= damped.first["MAP_FLATLINE"] <= 100.0 + 31.0


def test_held_repeats_do_not_count_towards_a_flatline_and_are_no_quality_fault():
    feed = Feed(1.0)
    rng = np.random.default_rng(5)
    for _ in range(600):
        feed.second(round(80.0 + rng.normal(0.0, 1.0)))
    assert feed.first == {}
    assert feed.sup.state == State.AUTO


def test_an_unknown_quality_bit_still_counts_as_bad():
    sup = Supervisor(SupervisorConfig(sample_period_s=TS))
    args = dict(
        now_s=0.0, map_mmhg=80.0, quality=8, K=0.5, T_s=150.0, tau_s=30.0, sched_valid=True,
        sample_age_s=0.0, link_silence_s=0.0, target_mmhg=80.0, link_errors=0,
        pump_delivered_ml_h=math.nan, pump_alarms=0, estimated=False, estimate_healthy=True,
        boundary_faults=0,
    )  # fmt: skip
    sup.assess(SupervisorInput(**args))
    assert sup.faults & Fault.SENSOR_QUALITY


class Recording:
    """A scheduling source that records what the core gives it (and schedules nominally)."""

    source = "oracle"

    def __init__(self) -> None:
        self.seen: list[tuple[float, int]] = []

    def update(self, inputs):
        from pressor.runtime.core.scheduling import OracleSchedule

        self.seen.append((inputs.map_mmhg, inputs.quality))
        return OracleSchedule().update(inputs)


def held_inputs(k: int, map_mmhg: float, quality: int) -> TickInputs:
    return TickInputs(k, k * TS, map_mmhg, quality, 90.0, 0.5, 150.0, 30.0, True, k, k)


def test_held_samples_age_from_the_last_new_one_and_go_stale_past_the_limit():
    source = Recording()
    pi = PIController(TS)
    core = ClosedLoopCore(pi, Supervisor(supervisor_config_for(pi, 1.0)), source)
    states, commands = [], []
    for k in range(40):  # one new sample, then 39 repeats: 3.9 s without a newer value
        rec = core.step(held_inputs(k, 80.0, QUALITY_HELD if k else 0), k * TS, None, CLEAN_LINK)
        states.append(rec.supervisor.state)
        commands.append(rec.controller_ml_h)
    # the default limit is 3 s: ticks 0..30 (age <= 3.0 s) use the held value, 31.. are stale
    assert states[:31] == [State.AUTO] * 31
    assert states[31] == State.HOLD and core.supervisor.faults & Fault.STALE_SAMPLE
    # the controller was stepped on the held value every tick (its integrator moves) until stale
    assert all(math.isfinite(c) for c in commands[:31]) and len(set(commands[:31])) == 31
    assert all(math.isnan(c) for c in commands[31:])
    # the scheduling source sees the held value without the HELD bit, and NaN once stale
    assert source.seen[:31] == [(80.0, 0)] * 31
    assert all(math.isnan(m) for m, _ in source.seen[31:])


def test_a_new_sample_after_held_repeats_resets_the_age():
    pi = PIController(TS)
    core = ClosedLoopCore(pi, Supervisor(supervisor_config_for(pi, 1.0)))
    for k in range(300):  # a 1 Hz monitor for 30 s: never stale
        q = QUALITY_HELD if k % 10 else 0
        rec = core.step(held_inputs(k, 80.0 + (k // 10) % 3, q), k * TS, None, CLEAN_LINK)
        assert rec.supervisor.state == State.AUTO and rec.supervisor.faults == 0


def test_the_sample_age_limit_is_a_supervisor_setting_validated_against_the_loop_period():
    with pytest.raises(ValueError, match="stale_after_s"):
        SupervisorConfig(sample_period_s=TS, stale_after_s=0.05)
    with pytest.raises(ValueError, match="stale_after_s"):
        SupervisorConfig(sample_period_s=TS, stale_after_s=61.0)
    assert SupervisorConfig().stale_after_s == 3.0


def test_the_quantum_is_read_off_the_values_so_a_line_frozen_from_the_start_is_caught():
    assert [grain_mmhg(x) for x in (80.0, 80.5, 80.3, 80.25)] == [1.0, 0.5, 0.1, 0.25]
    assert grain_mmhg(float(np.float32(80.0317))) == 0.0  # a continuous reading (float32)
    # a 10 Hz monitor reading 0.01 mmHg or finer with 0.1 mmHg noise, frozen from its first value
    rules = FlatlineRules(0.1, 10.0, 0.05, 30, 0.25)
    fired = [rules.update(k * TS, 80.0317) for k in range(101)]
    assert rules.quantum_mmhg == 0.0 and fired.index(True) == 100  # after 10 s, as before
    # the same value from an integer-mmHg monitor with 0.1 mmHg noise is a steady patient
    coarse = FlatlineRules(0.1, 10.0, 0.05, 30, 0.25)
    assert not any(coarse.update(k * TS, 80.0) for k in range(3000))
    assert coarse.quantum_mmhg == 1.0
