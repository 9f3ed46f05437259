"""Patient model: exact variable delay, K/T/tau dynamics inside their ranges, frozen LTI mode."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pressor.hil_sim.patients.cohort import draw_patient
from pressor.hil_sim.patients.patient import (
    T_MAX_S,
    T_MIN_S,
    TAU_MAX_S,
    TAU_MIN_S,
    FrozenParams,
    Patient,
    PatientParams,
    VariableDelayBuffer,
)


def test_delay_buffer_shifts_a_step_by_a_fractional_delay_exactly():
    buf = VariableDelayBuffer(0.1, 1.0)
    out = []
    for k in range(20):
        buf.push(0.0 if k < 5 else 10.0)  # step at t = 0.5 s
        out.append(buf.delayed_mean(0.25, 0.25))
    # Delayed step at 0.75 s: the step [0.7, 0.8] sees half of it, exactly.
    assert out[6] == 0.0
    assert out[7] == pytest.approx(5.0, abs=1e-12)
    assert out[8] == pytest.approx(10.0, abs=1e-12)


def test_delay_buffer_time_varying_delay_averages_over_source_interval():
    buf = VariableDelayBuffer(1.0, 10.0)
    for k in range(10):
        buf.push(float(k))  # u = k on [k, k+1)
    # Step [9, 10] with tau going 2 -> 3: source interval [7, 7]: degenerate -> u at 7 = 7.
    assert buf.delayed_mean(2.0, 3.0) == pytest.approx(7.0)
    # tau 2 -> 1.5: source [7, 8.5]: mean = (7*1 + 8*0.5)/1.5
    assert buf.delayed_mean(2.0, 1.5) == pytest.approx((7.0 + 4.0) / 1.5)


def test_delay_buffer_refuses_delay_beyond_its_capacity():
    buf = VariableDelayBuffer(0.1, 1.0)
    for _ in range(100):
        buf.push(1.0)
    with pytest.raises(ValueError, match="beyond buffer"):
        buf.delayed_mean(5.0, 5.0)


def test_frozen_patient_step_response_matches_closed_form_with_delay():
    p = Patient(FrozenParams(K=0.55, T_s=150.0, tau_s=40.05, baseline_mmhg=60.0), step_s=0.1)
    ys = []
    for _ in range(3000):
        p.step(20.0)
        ys.append(p.delta_map_mmhg)
    t = 0.1 * np.arange(1, 3001)
    exact = np.where(t > 40.05, 0.55 * 20.0 * (1.0 - np.exp(-(t - 40.05) / 150.0)), 0.0)
    assert np.max(np.abs(np.array(ys) - exact)) < 2e-3
    assert ys[399] == 0.0  # t = 40.0 s: nothing has arrived yet


def test_k_relaxes_to_k0_exp_minus_k1_i_with_time_constant_a_k():
    params = PatientParams(550.0, 0.8, 0.005, 2e-4, 10.0, 10.0, 100.0, 55.0)
    p = Patient(params, 0.1)
    for _ in range(5500):  # one a_k
        p.step(100.0)
    k_inf = 0.8 * math.exp(-0.5)
    assert p.K == pytest.approx(k_inf + (0.8 - k_inf) * math.exp(-1.0), rel=1e-4)


def test_lag_and_delay_move_within_their_ranges_over_an_hour():
    for seed in range(5):
        p = Patient(draw_patient(seed), 0.1)
        T, tau = [], []
        for k in range(36000):
            p.step(60.0 if k < 1200 else 40.0)  # a loading dose, then maintenance
            T.append(p.T_s)
            tau.append(p.tau_s)
        T, tau = np.array(T), np.array(tau)
        assert T.min() >= T_MIN_S and T.max() <= T_MAX_S
        assert T[-1] - T[0] > 10.0  # T actually rises (b_T * ∫i dt)
        assert tau.min() >= TAU_MIN_S and tau.max() <= TAU_MAX_S
        peak = int(np.argmax(tau))
        assert tau[peak] > 25.0 and 30.0 < peak * 0.1 < 600.0  # peaks minutes after the start
        assert tau[-1] < tau[peak] - 5.0  # ... and decays afterwards


def test_delay_stays_at_floor_before_any_infusion():
    p = Patient(draw_patient(1), 0.1)
    for _ in range(100):
        p.step(0.0)
    assert p.tau_s == TAU_MIN_S and p.T_s == T_MIN_S and p.delta_map_mmhg == 0.0


def test_max_delta_map_uses_steady_state_sensitivity():
    params = PatientParams(550.0, 0.5, 0.005, 2e-4, 10.0, 10.0, 100.0, 55.0)
    assert params.max_delta_map_mmhg(120.0) == pytest.approx(0.5 * 120.0 * math.exp(-0.6))
    assert FrozenParams(0.55, 150.0, 40.0, 60.0).max_delta_map_mmhg(120.0) == pytest.approx(66.0)
