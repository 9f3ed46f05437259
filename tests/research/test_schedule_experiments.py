"""The experimental scheduling sources of research/schedule_experiments.py and
research/fit_schedules.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pressor.runtime.core.scheduling import NominalSchedule, ScheduleInput
from research.fit_schedules import KHandover, SecantK
from research.schedule_experiments import BatchFit, OnsetSwitch, fit_closed_loop


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


def _onset_run(delay_s: float) -> tuple[list, OnsetSwitch]:
    # 1 s ticks, an infusion from t = 1 s, MAP ramps 0.1 mmHg/s from 1 s + delay_s
    source = OnsetSwitch(NominalSchedule(0.55, 150.0, 40.0), (0.55, 200.0, 80.0), 48.0, 2.0, 1.0)
    seen = []
    for k in range(120):
        y = 55.0 + 0.1 * max(0.0, k - 1 - delay_s)
        seen.append(source.update(ScheduleInput(y, 0, 10.0 * (k >= 1), *(math.nan,) * 3, False)))
    return seen, source


def test_onset_switch_keeps_the_first_source_when_the_map_rises_in_time():
    seen, source = _onset_run(10.0)  # 2 mmHg (its 2 s mean) about 32 s after the infusion
    assert {(s.K, s.T_s, s.tau_s) for s in seen} == {(0.55, 150.0, 40.0)}
    assert 30.0 < source.rise_time_s < 36.0


def test_onset_switch_jumps_once_for_good_to_the_long_delay_schedule_when_the_rise_is_late():
    seen, source = _onset_run(60.0)  # no rise within 48 s; rises later, the jump stays
    taus = [s.tau_s for s in seen]
    assert taus[:47] == [40.0] * 47 and taus[50:] == [80.0] * 70
    assert sum(a != b for a, b in zip(taus, taus[1:], strict=False)) == 1
    assert math.isnan(source.rise_time_s)


def test_secant_k_moves_at_its_rate_toward_the_gain_the_settled_loop_measures():
    # baseline 55 mmHg, held at the 70 mmHg target by 30 ml/h from the start: secant 0.5
    box = ((0.15, 3.0), (100.0, 700.0), (10.0, 200.0))
    source = SecantK(box, (0.2, 300.0, 100.0), 70.0, 1e-3, 1.0, after_s=60.0, window_s=30.0)
    ks = []
    for k in range(400):
        y = 55.0 if k == 0 else 70.0
        ks.append(source.update(ScheduleInput(y, 0, 30.0, *(math.nan,) * 3, False)).K)
    assert ks[59] == 0.2  # nothing before after_s
    assert ks[60] == pytest.approx(0.201)  # then at 1e-3 per s
    assert ks[-1] == pytest.approx(0.5)  # until the secant gain


def test_secant_k_holds_while_the_loop_is_not_settled():
    box = ((0.15, 3.0), (100.0, 700.0), (10.0, 200.0))
    source = SecantK(box, (0.2, 300.0, 100.0), 70.0, 1e-3, 1.0, after_s=60.0, window_s=30.0)
    for k in range(200):  # 3 mmHg short of the target: not settled
        s = source.update(ScheduleInput(55.0 if k == 0 else 67.0, 0, 30.0, *(math.nan,) * 3, False))
    assert s.K == 0.2
