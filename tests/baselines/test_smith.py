"""The scheduled Smith predictor against an independent whole-history simulation of the same law.

The reference below keeps every model sample in a numpy array indexed by tick and reads the delayed
model output with ``np.interp`` on the time axis (zero before t = 0); the controller keeps a ring
buffer and interpolates between lags. Both follow the law in ``pressor.baselines.smith``'s
docstring: Kc = T/(K·λ), Ti = T, conditional integration, ZOH model on the command sent.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pressor.baselines.smith import SmithController
from pressor.contracts.controller import Controller

TS = 0.1
LAMBDA = 30.0
U_MAX = 120.0


def reference_commands(
    map_mmhg: np.ndarray,
    target_mmhg: np.ndarray,
    k: np.ndarray,
    t_s: np.ndarray,
    tau_s: np.ndarray,
    lam: float = LAMBDA,
    ts: float = TS,
    u_max: float = U_MAX,
) -> np.ndarray:
    """Open loop: the commands the law gives for given input sequences (schedule inside limits)."""
    n = map_mmhg.size
    ym = np.zeros(n + 1)  # ym[i]: model output at tick i
    u = np.zeros(n)
    integral, held = 0.0, 0.0
    times = np.arange(n + 1) * ts
    window = int(np.nanmax(tau_s) / ts) + 2  # older samples are never read
    for i in range(n):
        lo = max(0, i - window)
        delayed = np.interp(times[i] - tau_s[i], times[lo : i + 1], ym[lo : i + 1], left=0.0)
        e = target_mmhg[i] - (map_mmhg[i] + ym[i] - delayed)
        if np.isfinite(e):
            kc, ti = t_s[i] / (k[i] * lam), t_s[i]
            v = kc * e + integral
            held = float(np.clip(v, 0.0, u_max))
            if not ((v > u_max and e > 0) or (v < 0 and e < 0)):
                integral += kc * ts * e / ti
        u[i] = held
        # exact response of T dym/dt = -ym + K u over one tick, written as a relaxation
        steady = k[i] * u[i]
        ym[i + 1] = steady + (ym[i] - steady) * math.exp(-ts / t_s[i])
    return u


def run(ctrl: SmithController, *seqs: np.ndarray) -> np.ndarray:
    return np.array([ctrl.step(*(float(s[i]) for s in seqs)) for i in range(seqs[0].size)])


def test_smith_satisfies_controller_interface():
    c = SmithController()
    assert isinstance(c, Controller)
    assert c.sample_period_s == 0.1 and c.max_rate_ml_h == 120.0 and c.lambda_s == 30.0


def test_first_command_is_kc_times_error_with_kc_t_over_k_lambda():
    c = SmithController(max_rate_ml_h=1000.0)
    # empty delay line and zero model: predicted MAP = MAP, so u = T/(K λ) · 20 mmHg
    assert c.step(60.0, 80.0, 0.55, 150.0, 40.0) == pytest.approx(150.0 / (0.55 * 30.0) * 20.0)


def test_closed_loop_on_matching_plant_equals_reference_and_reaches_target():
    """Constant K, T, τ; the plant is the model with an exact 400-tick delay (ZOH)."""
    k, t_s, tau = 0.55, 150.0, 40.0
    n, lag = 12000, 400
    a = math.exp(-TS / t_s)
    ctrl = SmithController()
    y = np.zeros(n + 1)
    u = np.zeros(n)
    for i in range(n):
        u[i] = ctrl.step(y[i], 20.0, k, t_s, tau)
        y[i + 1] = a * y[i] + (1 - a) * k * (u[i - lag] if i >= lag else 0.0)
    ones = np.ones(n)
    ref = reference_commands(y[:n], 20.0 * ones, k * ones, t_s * ones, tau * ones)
    np.testing.assert_allclose(u, ref, rtol=0, atol=1e-9)
    assert u.max() == 120.0 and u.min() >= 0.0  # the +20 mmHg step saturates the pump first
    # the PI zero cancels the 150 s model pole, which saturation excites: settled after 1200 s
    assert abs(y[n] - 20.0) < 0.01
    assert y.max() < 20.0 * 1.001  # no overshoot on a matching plant


def test_time_varying_schedule_fractional_delay_and_both_limits_equal_reference():
    rng = np.random.default_rng(7)
    n = 6000
    t = np.arange(n) * TS
    # within the rate limits: |dK/dt| <= 0.0006, |dT/dt| <= 0.5, |dτ/dt| <= 1.2 per s
    k = 0.4 + 0.2 * np.sin(2 * np.pi * t / 600.0) ** 2 * 0.5
    t_s = 150.0 + 40.0 * np.sin(2 * np.pi * t / 500.0)
    tau = 25.0 + 20.0 * np.sin(2 * np.pi * t / 105.0 + 0.3)  # τ/Ts mostly non-integer
    map_mmhg = 60.0 + 8.0 * np.sin(2 * np.pi * t / 300.0) + rng.normal(0.0, 0.5, n)
    target = np.where(t < 150.0, 90.0, np.where(t < 350.0, 40.0, 70.0))  # far above, far below
    map_mmhg[[1000, 1001, 2500]] = np.nan  # held commands, no integration
    target[3000] = np.inf
    ctrl = SmithController()
    got = run(ctrl, map_mmhg, target, k, t_s, tau)
    ref = reference_commands(map_mmhg, target, k, t_s, tau)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-8)
    assert (got == 120.0).any() and (got == 0.0).any()  # both limits were exercised
    assert ctrl.status.rho_clamped_count == 0 and ctrl.status.rho_rate_limited_count == 0


def test_integrator_does_not_wind_up_at_the_upper_limit():
    c = SmithController()
    for _ in range(10_000):
        assert c.step(0.0, 100.0, 0.55, 150.0, 40.0) == 120.0
        assert c.status.saturated
    # model and delayed model agree after 1000 s at a constant command, so y_p = MAP: once MAP is
    # 1 mmHg above target the command drops off the limit at once (no stored windup)
    assert c.step(101.0, 100.0, 0.55, 150.0, 40.0) < 120.0


def test_integrator_does_not_wind_up_at_the_lower_limit():
    c = SmithController()
    for _ in range(10_000):
        assert c.step(200.0, 60.0, 0.55, 150.0, 40.0) == 0.0
        assert c.status.saturated
    assert c.step(59.0, 60.0, 0.55, 150.0, 40.0) > 0.0


def test_schedule_outside_the_physical_range_is_clamped_and_counted():
    a, b = SmithController(max_rate_ml_h=5000.0), SmithController(max_rate_ml_h=5000.0)
    assert a.step(60.0, 70.0, 0.001, 5.0, 500.0) == b.step(60.0, 70.0, 0.02, 10.0, 120.0)
    assert a.status.rho_clamped and not b.status.rho_clamped
    a.step(60.0, 70.0, 0.02, 10.0, 120.0)
    assert not a.status.rho_clamped
    a.step(60.0, 70.0, 9.0, 10.0, 120.0)
    assert a.status.rho_clamped_count == 2


def test_delay_jump_is_rate_limited_to_five_seconds_per_second():
    jumped, ramped = SmithController(), SmithController()
    rng = np.random.default_rng(3)
    maps = 60.0 + rng.normal(0.0, 2.0, 400)
    for i in range(400):
        tau_ramp = min(40.0 + 0.5 * max(i - 199, 0), 80.0)  # 0.5 s per 0.1 s tick
        u1 = jumped.step(maps[i], 75.0, 0.55, 150.0, 40.0 if i < 200 else 80.0)
        u2 = ramped.step(maps[i], 75.0, 0.55, 150.0, tau_ramp)
        assert u1 == pytest.approx(u2, abs=1e-12)
        assert jumped.status.rho_rate_limited == (200 <= i < 279)
    assert jumped.status.rho_rate_limited_count == 79


def test_non_finite_map_holds_the_previous_command():
    c = SmithController()
    first = c.step(60.0, 70.0, 0.55, 150.0, 40.0)
    assert c.step(math.nan, 70.0, 0.55, 150.0, 40.0) == first
    assert c.step(60.0, math.inf, 0.55, 150.0, 40.0) == first


def test_non_finite_schedule_keeps_the_last_valid_value():
    a, b = SmithController(), SmithController()
    seq = [(0.5, 140.0, 30.0), (math.nan, 140.0, 30.0), (0.5, math.inf, math.nan), (0.5, 140, 30)]
    for i, (k, t_s, tau) in enumerate(seq):
        assert a.step(60.0 + i, 75.0, k, t_s, tau) == b.step(60.0 + i, 75.0, 0.5, 140.0, 30.0)
    assert not a.status.rho_clamped_count and not a.status.rho_rate_limited_count


def test_reset_returns_to_the_initial_state():
    c, fresh = SmithController(), SmithController()
    for _ in range(500):
        c.step(50.0, 80.0, 0.3, 120.0, 20.0)
    c.reset()
    assert c.status.rho_clamped_count == 0
    for i in range(500):
        assert c.step(55.0 + 0.01 * i, 70.0, 0.7, 180.0, 33.3) == fresh.step(
            55.0 + 0.01 * i, 70.0, 0.7, 180.0, 33.3
        )


@pytest.mark.parametrize(
    "kwargs",
    [
        {"sample_period_s": 0.0},
        {"max_rate_ml_h": -1.0},
        {"lambda_s": 4.9},
        {"lambda_s": 601.0},
        {"lambda_s": math.nan},
        {"tau_max_s": -1.0},
    ],
)
def test_invalid_parameters_are_rejected(kwargs):
    with pytest.raises(ValueError):
        SmithController(**kwargs)


def test_delay_at_the_line_length_reads_the_oldest_sample():
    """τ = tau_max exactly (a multiple of Ts) must read lag N−1, not wrap to the newest sample."""
    short, ref_len = SmithController(tau_max_s=2.0), SmithController(tau_max_s=20.0)
    for i in range(300):
        m = 60.0 + 3.0 * math.sin(i / 7.0)
        assert short.step(m, 70.0, 0.55, 150.0, 2.0) == ref_len.step(m, 70.0, 0.55, 150.0, 2.0)
