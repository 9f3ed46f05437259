"""§3 metric definitions checked on hand-made signals whose answers are known by construction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pressor.contracts.metrics import (
    aggregate,
    percentile_summary,
    run_metrics,
    stable_flag,
    step_metrics,
)

TS = 0.1


def _ramp_then_hold(
    t: np.ndarray, t0: float, ramp_s: float, base: float, step: float
) -> np.ndarray:
    """MAP that rises linearly from base to base+step over ramp_s after t0, then holds."""
    return base + step * np.clip((t - t0) / ramp_s, 0.0, 1.0)


def test_linear_ramp_rise_time_is_eighty_percent_of_ramp_duration():
    t = np.arange(0.0, 500.0, TS)
    y = _ramp_then_hold(t, 10.0, 100.0, 60.0, 20.0)
    m = step_metrics(t, y, 80.0, step_time_s=10.0, step_mmhg=20.0)
    assert m["rise_time_s"] == pytest.approx(80.0, abs=1e-6)
    assert m["overshoot_pct"] == 0.0


def test_overshoot_is_peak_excess_over_step_size_in_percent():
    t = np.arange(0.0, 300.0, TS)
    y = _ramp_then_hold(t, 0.0, 50.0, 60.0, 20.0)
    y[(t > 60) & (t < 70)] = 83.0  # 3 mmHg above an 80 mmHg target = 15 % of a 20 mmHg step
    m = step_metrics(t, y, 80.0, 0.0, 20.0)
    assert m["overshoot_pct"] == pytest.approx(15.0)


def test_settling_time_is_last_sample_outside_two_percent_band_minus_t0():
    t = np.arange(0.0, 600.0, TS)
    y = np.full_like(t, 80.0)
    y[t < 5.0] = 60.0
    y[np.isclose(t, 250.0)] = 80.5  # 0.5 mmHg > 2 % of 20 mmHg = 0.4 mmHg
    m = step_metrics(t, y, 80.0, step_time_s=5.0, step_mmhg=20.0)
    assert m["settling_time_s"] == pytest.approx(245.0)


def test_noisy_runs_settle_on_five_mmhg_band():
    t = np.arange(0.0, 600.0, TS)
    y = np.full_like(t, 80.0)
    y[np.isclose(t, 100.0)] = 84.0  # inside ±5 mmHg, outside 2 % band
    y[np.isclose(t, 50.0)] = 70.0
    assert step_metrics(t, y, 80.0, 0.0, 20.0, noisy=True)["settling_time_s"] == pytest.approx(50.0)
    assert step_metrics(t, y, 80.0, 0.0, 20.0, noisy=False)["settling_time_s"] == pytest.approx(
        100.0
    )


def test_never_settled_and_never_reached_are_none_not_numbers():
    t = np.arange(0.0, 300.0, TS)
    y = np.full_like(t, 65.0)  # stuck 15 mmHg short of target
    m = step_metrics(t, y, 80.0, 0.0, 20.0)
    assert m["settling_time_s"] is None
    assert m["rise_time_s"] is None
    assert m["steady_state_dev_mmhg"] == pytest.approx(15.0)


def test_iae_of_constant_error_is_error_times_duration():
    t = np.arange(0.0, 100.0, TS)  # 1000 samples
    m = step_metrics(t, np.full_like(t, 77.0), 80.0, 0.0, 20.0)
    assert m["iae_mmhg_s"] == pytest.approx(3.0 * 100.0)


def test_nan_samples_are_ignored_by_map_metrics():
    t = np.arange(0.0, 100.0, TS)
    y = np.full_like(t, 77.0)
    y[::2] = np.nan
    m = step_metrics(t, y, 80.0, 0.0, 20.0)
    assert m["iae_mmhg_s"] == pytest.approx(3.0 * 50.0)
    assert m["steady_state_dev_mmhg"] == pytest.approx(3.0)


def test_varvel_mdpe_mdape_wobble_on_known_errors():
    t = np.arange(0.0, 5 * TS, TS)
    target = 100.0
    y = np.array([90.0, 95.0, 100.0, 110.0, 120.0])  # PE = -10, -5, 0, 10, 20 %
    m = run_metrics(t, y, target, np.zeros(5), 120.0)
    assert m["mdpe_pct"] == pytest.approx(0.0)
    assert m["mdape_pct"] == pytest.approx(10.0)
    assert m["wobble_pct"] == pytest.approx(10.0)  # |PE - 0| median


def test_varvel_figures_count_from_the_step_on_skip_invalid_samples_and_tell_wobble_from_mdape():
    t = np.arange(0.0, 11.0, 1.0)
    target = np.where(t < 3.0, 60.0, 80.0)
    # before the step 50 % low (would pull the median to -5 %); after it PE = -20, -15, 5, 10,
    # (NaN), 10, 15, 30 %
    y = np.array([30.0, 30.0, 30.0, 64.0, 68.0, 84.0, 88.0, np.nan, 88.0, 92.0, 104.0])
    m = run_metrics(t, y, target, np.zeros_like(t), 120.0, step_time_s=3.0, step_mmhg=20.0)
    assert m["mdpe_pct"] == pytest.approx(10.0)  # median of the seven PE
    assert m["mdape_pct"] == pytest.approx(15.0)  # |PE| = 20, 15, 5, 10, 10, 15, 30
    assert m["wobble_pct"] == pytest.approx(5.0)  # |PE - 10| = 30, 25, 5, 0, 0, 5, 20


def test_drug_total_max_rate_and_time_at_limit():
    t = np.arange(0.0, 3600.0, 1.0)
    rate = np.full_like(t, 60.0)
    rate[:900] = 120.0  # a quarter of the hour at the limit
    m = run_metrics(t, np.full_like(t, 80.0), 80.0, rate, 120.0)
    assert m["drug_total_ml"] == pytest.approx(120.0 * 0.25 + 60.0 * 0.75)
    assert m["max_rate_ml_h"] == 120.0
    assert m["time_at_limit_pct"] == pytest.approx(25.0)


def test_time_in_band_and_below_counted_after_first_arrival():
    t = np.arange(0.0, 100.0, 1.0)
    y = np.full_like(t, 80.0)
    y[:10] = 60.0  # approach: not counted
    y[50:60] = 70.0  # 10 of the 90 samples after arrival are 10 mmHg low
    m = run_metrics(t, y, 80.0, np.zeros_like(t), 120.0, step_time_s=0.0, step_mmhg=20.0)
    assert m["time_below_pct"] == pytest.approx(100.0 * 10 / 90)
    assert m["time_in_band_pct"] == pytest.approx(100.0 * 80 / 90)


def test_no_step_gives_null_step_metrics():
    t = np.arange(0.0, 100.0, 1.0)
    m = run_metrics(t, np.full_like(t, 80.0), 80.0, np.zeros_like(t), 120.0)
    assert m["overshoot_pct"] is None and m["rise_time_s"] is None
    assert m["settling_time_s"] is None
    assert m["iae_mmhg_s"] == 0.0


def test_sustained_oscillation_is_unstable_and_decay_is_stable():
    t = np.arange(0.0, 2000.0, 1.0)
    growing = 80.0 + 10.0 * np.sin(2 * math.pi * t / 100.0)
    decaying = 80.0 + 10.0 * np.exp(-t / 100.0) * np.sin(2 * math.pi * t / 100.0)
    assert not stable_flag(growing, 80.0, 0.4)
    assert stable_flag(decaying, 80.0, 0.4)
    diverged = decaying.copy()
    diverged[-1] = np.inf
    assert not stable_flag(diverged, 80.0, 0.4)


def test_aggregate_reports_unreachable_apart_and_percentiles_skip_none():
    runs = [
        {"settling_time_s": float(v), "reachable": True, "stable": True} for v in range(1, 11)
    ] + [{"settling_time_s": None, "reachable": False, "stable": True}]
    agg = aggregate(runs)
    assert agg["n_reachable"] == 10 and agg["n_unreachable"] == 1
    s = agg["reachable"]["settling_time_s"]
    assert s["median"] == pytest.approx(5.5)
    assert s["p90"] == pytest.approx(9.1)
    assert s["p10"] == pytest.approx(1.9)  # linear interpolation between 1 and 2 at 0.9 of the gap
    assert agg["unreachable"]["settling_time_s"] == {
        "median": None,
        "p10": None,
        "p90": None,
        "n": 0,
        "n_null": 1,
    }
    assert percentile_summary([]) == {
        "median": None,
        "p10": None,
        "p90": None,
        "n": 0,
        "n_null": 0,
    }
