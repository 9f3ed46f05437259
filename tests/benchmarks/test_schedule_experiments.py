"""The batch least-squares experiment of benchmarks/schedule_experiments.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.schedule_experiments import BatchFit, KHandover, fit_closed_loop
from runtime.core.scheduling import ScheduleInput


def _fopdt_map(rate: np.ndarray, K: float, T: float, tau: int, baseline: float) -> np.ndarray:
    # 1 s samples: x[k + 1] = a x[k] + (1 - a) u[k - tau], MAP = baseline + K x
    a, x, out = math.exp(-1.0 / T), 0.0, []
    for k in range(rate.size):
        out.append(baseline + K * x)
        x = a * x + (1.0 - a) * (rate[k - tau] if k >= tau else 0.0)
    return np.array(out)


def test_closed_loop_fit_recovers_a_first_order_plus_delay_patient_on_its_grid():
    rate = np.where(np.arange(400) < 30, 100.0, 20.0)  # a bolus, then a maintenance rate
    K, T, tau = fit_closed_loop(_fopdt_map(rate, 0.7, 240.0, 84, 55.0), rate)
    assert (T, tau) == (240.0, 84.0)
    assert K == pytest.approx(0.7, rel=1e-9)


def test_batch_fit_holds_its_start_until_the_decision_then_the_clamped_fit():
    rate = np.where(np.arange(300) < 30, 100.0, 20.0)
    y = _fopdt_map(rate, 0.7, 240.0, 84, 55.0)
    box = ((0.15, 3.0), (100.0, 400.0), (10.0, 70.0))
    source = BatchFit(box, (1.0, 200.0, 40.0), decide_s=300.0, sample_period_s=0.5)
    seen = []
    for k in range(600):  # 0.5 s ticks: each 1 s mean is two equal samples
        inp = ScheduleInput(y[k // 2], 0, rate[k // 2], math.nan, math.nan, math.nan, False)
        seen.append(source.update(inp))
    assert (seen[598].K, seen[598].T_s, seen[598].tau_s) == (1.0, 200.0, 40.0)
    assert seen[598].from_prior
    assert (seen[599].T_s, seen[599].tau_s) == (240.0, 70.0)  # tau 84 s clamped to the box
    assert seen[599].K == pytest.approx(0.7, rel=1e-9)
    assert not seen[599].from_prior


def test_k_handover_holds_the_start_k_then_moves_at_its_rate_to_the_later_one():
    box = ((0.15, 3.0), (100.0, 400.0), (10.0, 200.0))
    source = KHandover(box, (0.9, 500.0, 90.0, 0.6), switch_s=10.0, rate_per_s=0.01,
                       sample_period_s=1.0)  # fmt: skip
    inp = ScheduleInput(60.0, 0, 0.0, math.nan, math.nan, math.nan, False)
    seen = [source.update(inp) for _ in range(60)]
    assert [s.K for s in seen[:11]] == [0.9] * 11  # t = 0 ... 10 s
    assert seen[20].K == pytest.approx(0.8)  # 10 s at 0.01 per s
    assert seen[59].K == 0.6  # reached, then held
    assert {(s.T_s, s.tau_s) for s in seen} == {(400.0, 90.0)}  # T clamped to the box
