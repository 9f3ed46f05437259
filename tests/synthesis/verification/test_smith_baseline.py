"""The Smith baseline's nominal step (what ``pressor verify`` reports as ``nominal_step.smith``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from pressor.synthesis.verification.smith_baseline import smith_step_response
from pressor.synthesis.verification.step_response import response_metrics


def test_plant_response_equals_a_fine_continuous_simulation_with_a_fractional_delay():
    """τ = 40.037 s (not a multiple of Ts): re-run the plant on a 1 ms grid from the commands sent."""
    k, t_s, horizon = 0.55, 150.0, 300.0
    resp = smith_step_response(k, t_s, 40.037, 20.0, horizon)
    # plant on a 1 ms grid: over [j h, (j+1) h) it sees the command of tick floor((j - 40037)/100)
    sub = 100
    n_fine = int(round(horizon / 0.1)) * sub
    src = (np.arange(n_fine) - 40037) // sub
    u_delayed = np.where(src >= 0, resp.infusion_ml_h[np.clip(src, 0, None)], 0.0)
    decay = math.exp(-0.001 / t_s)
    y_fine = lfilter([0.0, (1.0 - decay) * k], [1.0, -decay], np.append(u_delayed, 0.0))
    np.testing.assert_allclose(resp.map_mmhg, y_fine[::sub], rtol=0, atol=1e-7)
    assert resp.infusion_ml_h.max() == 120.0 and resp.infusion_ml_h.min() >= 0.0


def test_nominal_step_has_no_overshoot_and_settles_in_about_277_s():
    """The issue's measured figures for λ = 30 s: 0 % overshoot, 2 % settling ≈ 277 s."""
    m = response_metrics(smith_step_response(0.55, 150.0, 40.0, 20.0, 1500.0), 120.0)
    assert m["overshoot_pct"] == pytest.approx(0.0, abs=0.01)
    assert m["settling_time_s"] == pytest.approx(277.0, abs=1.0)
    assert m["max_rate_ml_h"] == 120.0 and m["stable"]


def test_a_slower_lambda_settles_later():
    fast = response_metrics(smith_step_response(0.55, 150.0, 40.0, 20.0, 1500.0, lambda_s=30.0))
    slow = response_metrics(smith_step_response(0.55, 150.0, 40.0, 20.0, 1500.0, lambda_s=90.0))
    assert slow["rise_time_s"] > fast["rise_time_s"] + 30.0


def test_bad_plant_is_rejected():
    with pytest.raises(ValueError, match="plant"):
        smith_step_response(0.0, 150.0, 40.0, 20.0, 100.0)
