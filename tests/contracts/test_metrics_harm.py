"""The harm metrics (contracts/metrics/harm.py) on hand-made traces whose answers are counted by
hand in each test: hypertensive stretches, time to the band, divergence, the step overshoot in
mmHg, and the cohort percentiles that rank "never" last."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pressor.contracts.metrics import (
    HARM_METRICS,
    divergence_pct_per_h,
    longest_above_s,
    percentiles_never_last,
    run_metrics,
    step_overshoot_mmhg,
    time_to_band_s,
)

TS = 0.1


def _grid(n: int) -> np.ndarray:
    return np.arange(n) * TS


def test_the_longest_stretch_above_target_plus_10_counts_samples_times_the_period():
    t = _grid(1000)  # 100 s, target 80 mmHg, MAP on target except:
    y = np.full(t.size, 80.0)
    y[100:120] = 95.0  # 20 samples above 90 mmHg: 2.0 s
    y[300:355] = 91.0  # 55 samples: 5.5 s
    y[400:440] = 92.0
    y[420] = 90.0  # exactly +10 mmHg is not above: this one splits into 2.0 s and 1.9 s
    y[600:670] = 93.0  # 70 samples with one monitor dropout inside: 69 valid, 6.9 s in one piece
    y[633] = np.nan
    assert longest_above_s(t, y, 80.0, 0.0) == pytest.approx(6.9)
    y[633] = 80.0  # the same stretch broken by a sample on target: 3.3 s and 3.6 s, 5.5 s wins
    assert longest_above_s(t, y, 80.0, 0.0) == pytest.approx(5.5)
    assert longest_above_s(t, y, 80.0, 35.0) == pytest.approx(3.6)  # from 35 s on only
    assert longest_above_s(t, np.full(t.size, 89.9), 80.0, 0.0) == 0.0
    assert longest_above_s(t, np.full(t.size, np.nan), 80.0, 0.0) is None


def test_the_time_to_the_band_is_the_first_sample_within_5_mmhg_after_the_step():
    t = _grid(3000)
    t0 = 5.0
    # 60 -> 80 mmHg over 100.2 s from t0: e = -20 + 20 (t - t0) / 100.2 reaches -5 mmHg at
    # t - t0 = 75.15 s, so the first sample inside is t = 80.2 s, 75.2 s after the step.
    y = 60.0 + 20.0 * np.clip((t - t0) / 100.2, 0.0, 1.0)
    target = np.where(t >= t0, 80.0, 60.0)
    assert time_to_band_s(t, y, target, t0) == pytest.approx(75.2)
    y[800:803] = np.nan  # the monitor drops 80.0-80.2 s: the next valid sample, 80.3 s, counts
    assert time_to_band_s(t, y, target, t0) == pytest.approx(75.3)
    assert time_to_band_s(t, np.full(t.size, 74.9), 80.0, t0) is None  # 5.1 mmHg short: never
    assert time_to_band_s(t, np.full(t.size, 84.0), 80.0, t0) == 0.0


def test_divergence_is_the_slope_of_the_absolute_percentage_error_per_hour():
    t = _grid(36000)  # one hour
    # target 100 mmHg, MAP 110 -> 106 mmHg linearly: |PE| = 10 - 4 t_h %, a slope of -4 %/h
    y = 110.0 - 4.0 * t / 3600.0
    assert divergence_pct_per_h(t, y, 100.0, 0.0) == pytest.approx(-4.0, rel=1e-9)
    # |PE| grows by 2 % per hour from 1 %: +2 %/h, the sign of a loop drifting away
    assert divergence_pct_per_h(t, 99.0 - 2.0 * t / 3600.0, 100.0, 0.0) == pytest.approx(2.0)
    assert divergence_pct_per_h(t, np.full(t.size, 97.0), 100.0, 0.0) == pytest.approx(0.0)
    one_valid = np.full(t.size, np.nan)
    one_valid[5] = 90.0
    assert divergence_pct_per_h(t, one_valid, 100.0, 0.0) is None


def test_the_step_overshoot_in_mmhg_stops_at_the_first_event():
    t = _grid(3000)  # target 80 mmHg from 0 s, the first event at 200 s
    y = np.full(t.size, 80.0)
    y[600:700] = 83.5  # 3.5 mmHg past the target at 60-70 s
    y[2500:2600] = 99.0  # after the event: not the step's
    assert step_overshoot_mmhg(t, y, 80.0, 0.0, 20.0, 200.0) == pytest.approx(3.5)
    assert step_overshoot_mmhg(t, y, 80.0, 0.0, 20.0, math.inf) == pytest.approx(19.0)
    # a step down (-20 mmHg) overshoots below the target: 2 mmHg under 60 mmHg
    down = np.full(t.size, 60.0)
    down[100:150] = 58.0
    assert step_overshoot_mmhg(t, down, 60.0, 0.0, -20.0, 200.0) == pytest.approx(2.0)
    assert step_overshoot_mmhg(t, np.full(t.size, 70.0), 80.0, 0.0, 20.0, 200.0) == 0.0
    assert step_overshoot_mmhg(t, y, 80.0, 0.0, 20.0, 0.05) is None  # one sample in the window


def test_run_metrics_carry_the_harm_metrics_and_their_null_rules():
    t = _grid(3000)
    y = np.full(t.size, 80.0)
    y[:50] = 60.0  # reaches the band at 5.0 s
    y[1000:1150] = 92.0  # 15.0 s above +10 mmHg, inside the step window (event at 200 s)
    m = run_metrics(
        t, y, 80.0, np.zeros(t.size), 120.0, step_time_s=0.0, step_mmhg=20.0,
        events=[("hemorrhage", 200.0)],
    )  # fmt: skip
    assert set(HARM_METRICS) <= set(m)
    assert m["step_overshoot_mmhg"] == pytest.approx(12.0)
    assert m["step_overshoot_pct"] == pytest.approx(60.0)  # the same excursion, in % of 20 mmHg
    assert m["longest_above_10_mmhg_s"] == pytest.approx(15.0)
    assert m["time_to_band_s"] == pytest.approx(5.0)
    unknown_events = run_metrics(t, y, 80.0, np.zeros(t.size), 120.0, 0.0, 20.0)
    assert unknown_events["step_overshoot_mmhg"] is None  # no step window without the events
    assert unknown_events["longest_above_10_mmhg_s"] == pytest.approx(15.0)
    no_step = run_metrics(t, y, 80.0, np.zeros(t.size), 120.0, events=[])
    assert no_step["step_overshoot_mmhg"] is None
    assert no_step["time_to_band_s"] == pytest.approx(5.0)  # from the first sample


def test_percentiles_rank_never_after_every_time():
    # 1, 2, 3, 4, never: the median is the third value; p90 sits at position 3.6, between 4 and
    # never, so it is not within the run
    assert percentiles_never_last([4.0, None, 1.0, 3.0, 2.0]) == {
        "p50": 3.0, "p90": None, "n": 5, "n_never": 1,
    }  # fmt: skip
    # no never: numpy's linear rule, p90 of (1, 3, 5) at position 1.8 = 3 + 0.8 * 2
    assert percentiles_never_last([5.0, 1.0, 3.0]) == {
        "p50": 3.0, "p90": pytest.approx(4.6), "n": 3, "n_never": 0,
    }  # fmt: skip
    # two of three never: even the median lies among them
    assert percentiles_never_last([None, None, 1.0])["p50"] is None
    assert percentiles_never_last([])["p50"] is None
