"""Supervisor: one transition test per fault kind, bumpless re-entry, and the [0, max] invariant."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pressor.runtime.core.supervisor import Supervisor, SupervisorInput
from pressor.runtime.core.supervisor_config import Fault, State, SupervisorConfig
from tests.support.supervisor_rig import GOOD_MAP, TS, Rig, good_inputs

BOX = ((0.45, 0.66), (100.0, 200.0), (10.0, 35.0))
RATES = (2e-4, 0.06, 0.06)


def sched_cfg(**kw) -> SupervisorConfig:
    return SupervisorConfig(
        sample_period_s=TS, sched_required=True, sched_box=BOX, sched_rate_bounds=RATES, **kw
    )


def test_first_good_sample_enters_auto_and_passes_command_through_unchanged():
    rig = Rig()
    assert rig.sup.state == State.STARTUP
    out = rig.tick(controller_command=37.123456789)
    assert rig.sup.state == State.AUTO
    assert out == 37.123456789
    assert not rig.sup.alarm


def test_startup_with_bad_sample_commands_zero_and_does_not_run_controller():
    rig = Rig()
    assert rig.tick(controller_command=50.0, map_mmhg=math.nan) == 0.0
    assert rig.sup.state == State.STARTUP


@pytest.mark.parametrize(
    ("bad_inputs", "fault"),
    [
        ({"map_mmhg": math.nan}, Fault.MAP_NAN),
        ({"map_mmhg": 2.0}, Fault.MAP_RANGE),  # line disconnect reads ~0
        ({"map_mmhg": 300.0}, Fault.MAP_RANGE),  # flush
        ({"map_mmhg": GOOD_MAP + 35.0}, Fault.MAP_SPIKE),
        ({"quality": 1}, Fault.SENSOR_QUALITY),
        ({"sample_age_s": 3.1}, Fault.STALE_SAMPLE),  # past the 3 s default age limit
        ({"target_mmhg": math.nan}, Fault.TARGET_INVALID),
    ],
)
def test_sensor_fault_is_detected_same_tick_and_holds_last_command_with_alarm(bad_inputs, fault):
    rig = Rig()
    rig.ticks(5, controller_command=42.0)
    out = rig.tick(controller_command=99.0, **bad_inputs)
    assert rig.sup.faults & fault
    assert rig.sup.state == State.HOLD
    assert rig.sup.alarm
    assert out == 42.0
    assert rig.out.transition == (State.AUTO, State.HOLD, rig.sup.faults)
    assert rig.sup.detections[fault.name] == 1


def test_flatline_detected_after_window_only_when_sensor_is_noisy():
    cfg = SupervisorConfig(sample_period_s=TS, sensor_noise_mmhg=0.1, flatline_s=2.0)
    rig = Rig(cfg)
    for m in (80.3, 79.8, 80.2, 80.25):  # the monitor reads to 0.1 mmHg (or finer)
        rig.tick(map_mmhg=m)
    # stuck for 2 s and 23 samples (the count a 1e-9 false alarm needs at 0.1 mmHg noise)
    rig.ticks(22, map_mmhg=80.0)
    assert rig.sup.state == State.AUTO
    rig.tick(map_mmhg=80.0)
    assert rig.sup.faults & Fault.MAP_FLATLINE
    assert rig.sup.state == State.HOLD
    quiet = Rig(SupervisorConfig(sample_period_s=TS))  # noise-free sensor: constant MAP is fine
    quiet.ticks(500, map_mmhg=80.0)
    assert quiet.sup.state == State.AUTO


def test_level_change_is_one_spike_then_accepted_after_recovery_time():
    rig = Rig()
    rig.ticks(5)
    rig.tick(map_mmhg=110.0)
    assert rig.sup.state == State.HOLD
    states = [(rig.tick(map_mmhg=110.0), rig.sup.state)[1] for _ in range(60)]
    assert State.RECOVERING in states or State.AUTO in states
    assert rig.sup.state == State.AUTO


def test_link_loss_goes_straight_to_failsafe_and_ramps_to_safe_rate():
    cfg = SupervisorConfig(sample_period_s=TS, safe_rate_ml_h=10.0, failsafe_ramp_ml_h_per_s=5.0)
    rig = Rig(cfg)
    rig.ticks(3, controller_command=40.0)
    outs = rig.ticks(100, link_silence_s=2.0, sample_age_s=2.0)
    assert rig.sup.state == State.FAILSAFE
    assert rig.sup.faults & Fault.LINK_LOSS
    steps = [abs(b - a) for a, b in zip([40.0, *outs], outs, strict=False)]
    assert max(steps) <= 5.0 * TS + 1e-12
    assert outs[-1] == 10.0


def test_long_fault_escalates_hold_to_failsafe_after_hold_max():
    cfg = SupervisorConfig(sample_period_s=TS, hold_max_s=1.0, safe_rate_ml_h=0.0)
    rig = Rig(cfg)
    rig.ticks(3, controller_command=20.0)
    rig.ticks(10, map_mmhg=math.nan)
    assert rig.sup.state == State.HOLD
    rig.tick(map_mmhg=math.nan)
    assert rig.sup.state == State.FAILSAFE


@pytest.mark.parametrize(
    ("bad_inputs", "fault"),
    [
        ({"K": 0.9}, Fault.SCHED_OUT_OF_BOX),
        ({"tau_s": 50.0}, Fault.SCHED_OUT_OF_BOX),
        ({"sched_valid": False}, Fault.SCHED_INVALID),
        ({"T_s": math.nan}, Fault.SCHED_INVALID),
        ({"T_s": 151.0}, Fault.SCHED_RATE),  # 1 s in 0.1 s = 10 s/s >> 0.06 s/s
    ],
)
def test_scheduling_fault_holds(bad_inputs, fault):
    rig = Rig(sched_cfg())
    rig.ticks(5, controller_command=25.0)
    assert rig.sup.state == State.AUTO
    out = rig.tick(controller_command=80.0, **bad_inputs)
    assert rig.sup.faults & fault
    assert rig.sup.state == State.HOLD
    assert out == 25.0


def test_scheduling_change_within_rate_bound_is_accepted():
    rig = Rig(sched_cfg())
    T = 150.0
    for _ in range(50):
        T += 0.06 * TS  # exactly at the synthesis bound
        rig.tick(T_s=T)
    assert rig.sup.state == State.AUTO
    assert not rig.sup.faults


def test_unscheduled_controller_ignores_scheduling_inputs():
    rig = Rig()  # default config: no box, no rate bounds, not required
    rig.ticks(5, K=math.nan, sched_valid=False, T_s=1e6)
    assert rig.sup.state == State.AUTO


def test_recovery_waits_for_good_time_then_reenters_bumplessly():
    cfg = SupervisorConfig(sample_period_s=TS, recover_after_s=2.0, reentry_step_ml_h=0.5)
    rig = Rig(cfg)
    rig.ticks(5, controller_command=20.0)
    rig.ticks(30, map_mmhg=math.nan)  # 3 s fault, held at 20
    held = rig.sup.command_ml_h
    assert held == 20.0
    outs = rig.ticks(20, controller_command=30.0)  # good for 1.9 s < 2 s: still holding
    assert rig.sup.state == State.HOLD and set(outs) == {20.0}
    outs, states = [], []
    for _ in range(40):
        outs.append(rig.tick(controller_command=30.0))
        states.append(rig.sup.state)
    assert states[0] == State.RECOVERING
    assert rig.sup.state == State.AUTO
    steps = [abs(b - a) for a, b in zip([held, *outs], outs, strict=False)]
    assert max(steps) <= 0.5 + 1e-12
    assert outs[-1] == 30.0


def test_fault_during_recovery_returns_to_hold():
    cfg = SupervisorConfig(sample_period_s=TS, recover_after_s=0.5, reentry_step_ml_h=0.1)
    rig = Rig(cfg)
    rig.ticks(3, controller_command=10.0)
    rig.tick(map_mmhg=math.nan)
    rig.ticks(6, controller_command=50.0)
    assert rig.sup.state == State.RECOVERING
    rig.tick(map_mmhg=math.nan)
    assert rig.sup.state == State.HOLD


def test_nonfinite_controller_command_is_held_and_out_of_range_is_clamped_with_flag():
    rig = Rig(SupervisorConfig(sample_period_s=TS, max_rate_ml_h=120.0))
    rig.ticks(3, controller_command=15.0)
    assert rig.tick(controller_command=math.nan) == 15.0
    assert rig.sup.faults & Fault.COMMAND_INVALID and rig.sup.state == State.HOLD
    rig2 = Rig(SupervisorConfig(sample_period_s=TS, max_rate_ml_h=120.0))
    assert rig2.tick(controller_command=500.0) == 120.0
    assert rig2.sup.faults & Fault.COMMAND_CLAMPED and rig2.sup.state == State.AUTO
    assert rig2.tick(controller_command=-3.0) == 0.0


def test_config_rejects_out_of_range_field_naming_it():
    with pytest.raises(ValueError, match="safe_rate_ml_h"):
        SupervisorConfig(safe_rate_ml_h=500.0)
    with pytest.raises(ValueError, match="sched_box"):
        SupervisorConfig(sched_box=((1.0, 0.0), (1.0, 2.0), (1.0, 2.0)))


finite_or_not = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64),
    st.floats(min_value=-50.0, max_value=350.0),
)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(
            finite_or_not,  # MAP
            finite_or_not,  # controller command
            st.integers(0, 3),  # quality
            st.floats(0.0, 3.0),  # sample age
            st.floats(0.0, 3.0),  # link silence
            finite_or_not,  # K
            st.booleans(),
        ),
        min_size=1,
        max_size=80,
    ),
    st.one_of(st.none(), st.floats(0.0, 120.0)),
)
def test_command_is_always_finite_and_within_pump_limits(rows, safe_rate):
    cfg = SupervisorConfig(
        sample_period_s=TS,
        max_rate_ml_h=120.0,
        safe_rate_ml_h=safe_rate,
        recover_after_s=0.2,
        sched_required=True,
        sched_box=BOX,
        sched_rate_bounds=RATES,
        sensor_noise_mmhg=1.0,
        flatline_s=0.5,
    )
    sup = Supervisor(cfg)
    for k, (map_mmhg, cmd, quality, age, silence, K, valid) in enumerate(rows):
        inputs = good_inputs(k * TS)
        inputs.update(
            map_mmhg=map_mmhg,
            quality=quality,
            K=K,
            sched_valid=valid,
            sample_age_s=age,
            link_silence_s=silence,
        )
        run = sup.assess(SupervisorInput(**inputs))
        out = sup.finalize(cmd if run else None).command_ml_h
        assert math.isfinite(out) and 0.0 <= out <= 120.0
        assert out == sup.command_ml_h


def test_advisory_sched_action_flags_envelope_exit_but_keeps_auto_and_passes_command():
    rig = Rig(sched_cfg(sched_action="advise"))
    rig.ticks(5, controller_command=25.0)
    out = rig.tick(controller_command=80.0, K=0.2)  # below the box
    assert rig.sup.faults & Fault.SCHED_OUT_OF_BOX
    assert rig.out.new_faults & Fault.SCHED_OUT_OF_BOX
    assert rig.sup.state == State.AUTO and out == 80.0
    assert rig.sup.detections["SCHED_OUT_OF_BOX"] == 1
    out = rig.tick(controller_command=81.0, sched_valid=False)  # invalid is never advisory
    assert rig.sup.state == State.HOLD and out == 80.0


def test_supervisor_input_has_no_defaults_so_a_missing_input_cannot_fail_open():
    full = good_inputs(0.0)
    for name in full:
        partial = {k: v for k, v in full.items() if k != name}
        with pytest.raises(TypeError, match=name):
            SupervisorInput(**partial)
