"""The least-squares FOPDT fit of an open-loop step (research/step_fit.py)."""

from __future__ import annotations

import numpy as np
import pytest

from pressor.hil_sim.patients.pkpd import PatientParams
from research.step_fit import apparent_fopdt, fit_fopdt, held_patient, step_response_fit


def test_fit_recovers_a_first_order_plus_delay_response_whose_values_are_on_the_grid():
    t = np.arange(0.0, 600.0, 0.5)
    u = 20.0
    dy = 0.7 * u * (1.0 - np.exp(-np.clip(t - 40.0, 0.0, None) / 200.0))
    K, T, tau = fit_fopdt(t, dy, u)
    assert (T, tau) == (200.0, 40.0)
    assert K == pytest.approx(0.7, rel=1e-9)


def test_fit_refuses_a_rate_that_is_not_positive():
    with pytest.raises(ValueError, match="rate_ml_h=0.0 must be > 0"):
        fit_fopdt(np.arange(3.0), np.zeros(3), 0.0)


def _one_compartment_with_an_effect_lag() -> PatientParams:
    # one compartment (plasma 60 V1 / CL = 300 s), a 60 s effect-site lag, a 20 s line delay,
    # Hill 1: a second-order response that apparent_fopdt reads as T = 360 s, tau = 20 s
    return PatientParams(
        baseline_mmhg=50.0, delay_s=20.0, cl_l_min=2.0, v1_l=10.0, q_l_min=0.0, v2_l=200.0,
        effect_lag_s=60.0, emax_mmhg=60.0, ec50_ng_ml=30.0, hill=1.0, tolerance_tau_s=1800.0,
        tolerance_gain=0.0, hemorrhage_mmhg=10.0, hemorrhage_ramp_s=60.0, bolus_mmhg=8.0,
        bolus_rise_s=90.0, bolus_decay_s=600.0,
    )  # fmt: skip


def test_step_fit_of_a_patient_with_an_effect_lag_moves_the_lag_into_the_delay():
    p = _one_compartment_with_an_effect_lag()
    _, T_app, tau_app = apparent_fopdt(p, 70.0)
    K, T, tau = step_response_fit(p, 70.0, 0.1, 100.0, 120.0)
    assert tau >= tau_app + 20.0  # a good part of the 60 s lag is carried as delay
    assert T < T_app
    # one compartment: the steady gain 20/18 mmHg/(ml/h), from the curve of the first 10 min
    assert K == pytest.approx(20.0 / 18.0, rel=0.05)


def test_a_realistic_devices_fit_is_seeded_and_keeps_the_lag_in_the_delay():
    p = _one_compartment_with_an_effect_lag()
    ideal = step_response_fit(p, 70.0, 0.1, 100.0, 120.0)
    rate = held_patient(p, 70.0)[1]  # the ideal device's rate: 18 ml/h
    noisy = step_response_fit(p, 70.0, 0.1, 100.0, 120.0, rate_ml_h=rate, noise_mmhg=0.3, seed=4)
    assert noisy == step_response_fit(
        p, 70.0, 0.1, 100.0, 120.0, rate_ml_h=rate, noise_mmhg=0.3, seed=4
    )
    assert abs(noisy[2] - ideal[2]) <= 4.0 and abs(noisy[1] - ideal[1]) <= 0.1 * ideal[1]
    assert noisy[0] == pytest.approx(ideal[0], rel=0.02)
    # twice that rate climbs the Hill curve further: a lower secant gain, the lag still in tau
    double = step_response_fit(p, 70.0, 0.1, 100.0, 120.0, rate_ml_h=2 * rate, noise_mmhg=0.3)
    assert double[0] < 0.9 * ideal[0]
    assert double[2] >= apparent_fopdt(p, 70.0)[2] + 20.0


def test_a_realistic_devices_fit_refuses_a_rate_beyond_the_pump_and_negative_noise():
    p = _one_compartment_with_an_effect_lag()
    with pytest.raises(ValueError, match=r"rate_ml_h=130.0 outside \(0, 120.0\] ml/h"):
        step_response_fit(p, 70.0, 0.1, 100.0, 120.0, rate_ml_h=130.0)
    with pytest.raises(ValueError, match="noise_mmhg=-0.1 must be >= 0 mmHg"):
        step_response_fit(p, 70.0, 0.1, 100.0, 120.0, noise_mmhg=-0.1)
