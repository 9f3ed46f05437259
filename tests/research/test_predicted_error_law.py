"""The research plugin of the Smith law that integrates the predicted error."""

from __future__ import annotations

import math

import pytest

from pressor.runtime.core.supervisor_config import sched_limits_of
from pressor.runtime.inputs.controller_loader import load_controller
from research.predicted_error_law import GRID_HI, GRID_LO, RATE_BOUNDS, PredictedErrorLaw


def _haemorrhage(law: str, tau_s: float, lag_s: float, gain_error: float = 1.0):
    """A FOPDT patient (K 0.5, the given T and τ) stepped to +15 mmHg, then -10 mmHg at 1500 s;
    returns (IAE after the drop (mmHg·s), peak above target after it (mmHg), final error (mmHg))."""
    ts, k = 0.1, 0.5
    ctrl = PredictedErrorLaw(law=law)
    n, d = round(4000.0 / ts), round(tau_s / ts)
    sent = [0.0] * (n + d)
    decay = math.exp(-ts / lag_s)
    y, after = 0.0, []
    for i in range(n):
        measured = 65.0 + y - (10.0 if i * ts >= 1500.0 else 0.0)
        sent[i + d] = ctrl.step(measured, 80.0, k, lag_s, tau_s)
        y = decay * y + (1.0 - decay) * k * gain_error * sent[i]
        if i * ts >= 1500.0:
            after.append(measured - 80.0)
    return sum(abs(v) for v in after) * ts, max(after), after[-1]


def test_exact_integral_rejects_a_drop_without_the_trapezoid_overshoot_at_a_long_delay():
    # tau = 200 s, lambda = T/3 = 33 s: the trapezoid leaves a delayed loop gain tau/(2 lambda) = 3
    exact = _haemorrhage("exact", 200.0, 100.0)
    trapezoid = _haemorrhage("trapezoid", 200.0, 100.0)
    assert exact[1] < 0.1 and trapezoid[1] > 1.0
    assert exact[0] < 0.8 * trapezoid[0]
    assert abs(exact[2]) < 0.01


def test_both_laws_agree_when_the_delay_is_short_against_the_lag():
    exact = _haemorrhage("exact", 40.0, 400.0)
    trapezoid = _haemorrhage("trapezoid", 40.0, 400.0)
    assert exact[0] == pytest.approx(trapezoid[0], rel=0.01)


def test_loads_as_a_plugin_and_declares_its_box():
    ctrl = load_controller("research.predicted_error_law:PredictedErrorLaw:law='trapezoid'", 0.1)
    assert isinstance(ctrl, PredictedErrorLaw) and ctrl.law == "trapezoid"
    box, rates = sched_limits_of(ctrl)
    assert box == tuple(zip(GRID_LO, GRID_HI, strict=True)) and rates == RATE_BOUNDS


def test_unknown_law_is_refused():
    with pytest.raises(ValueError, match="law='simpson'"):
        PredictedErrorLaw(law="simpson")


def test_a_missing_sample_holds_the_command():
    ctrl = PredictedErrorLaw()
    for _ in range(50):
        command = ctrl.step(60.0, 75.0, 0.5, 150.0, 60.0)
    assert command > 0.0
    assert ctrl.step(math.nan, 75.0, 0.5, 150.0, 60.0) == command
    assert math.isfinite(ctrl.step(60.0, 75.0, 0.5, 150.0, 60.0))
