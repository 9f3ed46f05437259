"""The frozen nominal step: the PI baseline against the independent reference figures."""

from __future__ import annotations

import numpy as np
import pytest

from pressor.baselines.pi import PIController
from pressor.synthesis.verification.pi_baseline import PIBaseline
from pressor.synthesis.verification.step_response import StepLoop, response_metrics, simulate_step

# docs/DESIGN-CHOICES.md: PI baseline, nominal plant, +20 mmHg, no noise, computed two independent ways
REF_OVERSHOOT_PCT = 0.0
REF_RISE_S = 109.5
REF_SETTLING_S = 418.8


@pytest.fixture(scope="module")
def pi_step():
    return simulate_step(PIBaseline().step_loop(0.55, 150.0, 40.0), t_end_s=1500.0)


def test_pi_nominal_step_matches_reference_figures(pi_step) -> None:
    m = response_metrics(pi_step)
    assert m["overshoot_pct"] == pytest.approx(REF_OVERSHOOT_PCT, abs=0.1)
    assert m["rise_time_s"] == pytest.approx(REF_RISE_S, abs=1.0)
    assert m["settling_time_s"] == pytest.approx(REF_SETTLING_S, abs=1.0)


def test_pi_step_settles_to_target_with_the_steady_state_dose(pi_step) -> None:
    assert pi_step.map_mmhg[-1] == pytest.approx(20.0, abs=0.01)
    # steady state: K u = 20 mmHg -> u = 20 / 0.55 ml/h
    assert pi_step.infusion_ml_h[-1] == pytest.approx(20.0 / 0.55, abs=0.05)
    # first command is the proportional kick kp * 20
    assert pi_step.infusion_ml_h[0] == pytest.approx(60.0)


def test_nothing_moves_before_the_delay_has_elapsed(pi_step) -> None:
    before = pi_step.t_s < 40.0 - 1e-9
    assert np.all(pi_step.map_mmhg[before] == 0.0)
    assert pi_step.map_mmhg[pi_step.t_s > 41.0][0] > 0.0


def test_halving_the_step_changes_the_metrics_by_far_less_than_their_resolution(pi_step) -> None:
    fine = simulate_step(PIBaseline().step_loop(0.55, 150.0, 40.0), t_end_s=1500.0, h_max_s=0.025)
    a, b = response_metrics(pi_step), response_metrics(fine)
    assert abs(a["rise_time_s"] - b["rise_time_s"]) < 0.01
    assert abs(a["settling_time_s"] - b["settling_time_s"]) <= 0.05 + 1e-9


def test_continuous_pi_agrees_with_the_runtime_discrete_pi() -> None:
    # the runtime PI (forward-Euler integrator at 0.1 s) on an exact delay line of the same plant
    ts, k, t_lag, n_delay = 0.1, 0.55, 150.0, 400
    pi = PIController(sample_period_s=ts, max_rate_ml_h=1e4)
    line = [0.0] * n_delay
    x, ys = 0.0, []
    a = np.exp(-ts / t_lag)
    for _ in range(6000):
        ys.append(x)
        line.append(pi.step(x, 20.0, k, t_lag, 40.0))
        x = a * x + (1.0 - a) * k * line.pop(0)
    cont = simulate_step(PIBaseline().step_loop(k, t_lag, 40.0), t_end_s=599.9, h_max_s=0.1)
    assert np.max(np.abs(np.array(ys) - cont.map_mmhg[: len(ys)])) < 0.1


def test_zero_delay_loop_is_integrated_without_a_buffer() -> None:
    # x' = -x + r, x(0) = 0: x = r (1 - e^-t)
    loop = StepLoop(
        A=np.array([[-1.0]]),
        Ad=np.zeros((1, 1)),
        b_r=np.array([1.0]),
        bd_r=np.array([0.0]),
        c_map=np.array([1.0]),
        c_u=np.array([0.0]),
        d_u=0.0,
        tau_s=0.0,
    )
    r = simulate_step(loop, step_mmhg=2.0, t_end_s=3.0, h_max_s=0.1)
    assert np.allclose(r.map_mmhg, 2.0 * (1.0 - np.exp(-r.t_s)), atol=1e-12)


def test_bad_step_arguments_are_rejected() -> None:
    loop = PIBaseline().step_loop(0.55, 150.0, 40.0)
    with pytest.raises(ValueError, match="step_mmhg"):
        simulate_step(loop, step_mmhg=0.0)
    with pytest.raises(ValueError, match="t_end_s"):
        simulate_step(loop, t_end_s=-1.0)
