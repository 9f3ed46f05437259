"""The PI baseline: gains, clamping, anti-windup."""

from __future__ import annotations

import math

import pytest

from pressor.baselines.pi import PIController
from pressor.contracts.controller import Controller


def test_pi_satisfies_controller_interface():
    assert isinstance(PIController(), Controller)


def test_first_step_is_proportional_to_error():
    pi = PIController()
    assert pi.step(60.0, 80.0, 0.55, 150.0, 40.0) == pytest.approx(3.0 * 20.0)


def test_integral_accumulates_ki_ts_error_per_tick():
    pi = PIController(sample_period_s=0.5)
    pi.step(60.0, 70.0, 0.55, 150.0, 40.0)
    second = pi.step(60.0, 70.0, 0.55, 150.0, 40.0)
    assert second == pytest.approx(3.0 * 10.0 + 0.017 * 0.5 * 10.0)


def test_command_never_leaves_pump_limits_and_flags_saturation():
    pi = PIController(max_rate_ml_h=120.0)
    assert pi.step(0.0, 200.0, 0.55, 150.0, 40.0) == 120.0
    assert pi.status.saturated
    assert pi.step(200.0, 0.0, 0.55, 150.0, 40.0) == 0.0
    assert pi.status.saturated


def test_integrator_does_not_wind_up_while_saturated_high():
    pi = PIController(max_rate_ml_h=120.0)
    for _ in range(10_000):
        pi.step(0.0, 100.0, 0.55, 150.0, 40.0)
    # Once the error reverses, the command leaves the limit within one tick (no stored windup).
    assert pi.step(101.0, 100.0, 0.55, 150.0, 40.0) < 120.0


def test_reset_clears_integrator():
    pi = PIController()
    for _ in range(100):
        pi.step(60.0, 80.0, 0.55, 150.0, 40.0)
    pi.reset()
    assert pi.step(80.0, 80.0, 0.55, 150.0, 40.0) == 0.0


@pytest.mark.parametrize(
    "kwargs", [{"sample_period_s": 0.0}, {"max_rate_ml_h": -1.0}, {"kp": -1.0}]
)
def test_invalid_parameters_are_rejected(kwargs):
    with pytest.raises(ValueError):
        PIController(**kwargs)


def test_nan_measurement_holds_last_command_and_never_returns_nan():
    pi = PIController()
    held = pi.step(60.0, 80.0, 0.55, 150.0, 40.0)
    for bad in (math.nan, math.inf, -math.inf):
        out = pi.step(bad, 80.0, 0.55, 150.0, 40.0)
        assert out == held
    # The bad samples did not feed the integrator.
    assert pi.step(60.0, 80.0, 0.55, 150.0, 40.0) == pytest.approx(held + 0.017 * 0.1 * 20.0)
