"""Step window and per-disturbance metrics on hand-made signals whose answers are derived here.

Every expected value is worked out in the test from the signal's construction (piecewise-linear
pieces, an exponential recovery), never taken from the code under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pressor.contracts.metrics import (
    aggregate,
    disturbance_metrics,
    event_labels,
    event_windows,
    run_metrics,
    step_window_metrics,
)

TARGET = 80.0


def _step_then_bolus(t: np.ndarray) -> np.ndarray:
    """+20 mmHg step at t = 0 reached by a 105 s ramp from 60 mmHg, then a bolus: +10 mmHg over
    300..310 s, back down linearly over 310..355 s, on target to the end."""
    y = 60.0 + 20.0 * np.clip(t / 105.0, 0.0, 1.0)
    rise = (t >= 300.0) & (t < 310.0)
    y[rise] += t[rise] - 300.0
    fall = (t >= 310.0) & (t < 355.0)
    y[fall] += 10.0 - (t[fall] - 310.0) * 10.0 / 45.0
    return y


def _run(t: np.ndarray, y: np.ndarray, events, **kw):
    return run_metrics(t, y, TARGET, np.zeros_like(t), 120.0, events=events, **kw)


def test_step_metrics_stop_at_the_first_disturbance_while_old_names_keep_the_whole_run():
    t = np.arange(0.0, 600.0, 1.0)
    y = _step_then_bolus(t)
    m = _run(t, y, [("bolus", 300.0)], step_time_s=0.0, step_mmhg=20.0)
    # The ramp never passes 80: no step overshoot; 10 % → 90 % of 20 mmHg is 10.5 s → 94.5 s.
    assert m["step_overshoot_pct"] == 0.0
    assert m["step_rise_time_s"] == pytest.approx(84.0, abs=1e-9)
    # 2 % band = 0.4 mmHg: 60 + 20 t/105 < 79.6 for t < 102.9, so the last sample outside is 102.
    assert m["step_settling_time_s"] == pytest.approx(102.0)
    # Rectangle rule, Ts = 1 s: sum over k = 0..104 of 20(1 - k/105) = 2100 - (20/105)·5460.
    assert m["step_iae_mmhg_s"] == pytest.approx(2100.0 - 20.0 / 105.0 * 5460.0)
    # The whole-run names include the bolus: +10 mmHg over a 20 mmHg step is 50 %, and the last
    # sample above 80.4 mmHg is at 353 s (10 - (t - 310)·10/45 > 0.4 for t < 353.2).
    assert m["overshoot_pct"] == pytest.approx(50.0)
    assert m["settling_time_s"] == pytest.approx(353.0)
    assert m["rise_time_s"] == m["step_rise_time_s"]


def test_bolus_record_has_signed_peak_interpolated_recovery_and_window_iae():
    t = np.arange(0.0, 600.0, 1.0)
    (rec,) = disturbance_metrics(t, _step_then_bolus(t), TARGET, [("bolus", 300.0)])
    assert rec["kind"] == "bolus" and rec["start_s"] == 300.0
    assert rec["end_s"] == pytest.approx(600.0)  # last sample 599 s + one period
    assert rec["peak_deviation_mmhg"] == pytest.approx(10.0)  # at 310 s, above target: positive
    # Back inside +5 mmHg when 10 - (t - 310)·10/45 = 5, t = 332.5 s (between samples 332, 333).
    assert rec["recovery_s"] == pytest.approx(32.5, abs=1e-9)
    # |e| = 0..10 over 300..310 (sum 55), then 10 - 10j/45 for j = 1..44 (440 - 220), then 0.
    assert rec["iae_mmhg_s"] == pytest.approx(55.0 + 220.0)


def _hemorrhage_dip(t: np.ndarray) -> np.ndarray:
    """On target, then a dip: linear to -12 mmHg over 1000..1060 s, exponential recovery with a
    100 s time constant."""
    e = np.zeros_like(t)
    ramp = (t >= 1000.0) & (t < 1060.0)
    e[ramp] = -12.0 * (t[ramp] - 1000.0) / 60.0
    tail = t >= 1060.0
    e[tail] = -12.0 * np.exp(-(t[tail] - 1060.0) / 100.0)
    return TARGET + e


def test_hemorrhage_dip_peak_and_recovery_time_match_the_exponential():
    t = np.arange(0.0, 3000.0, 0.1)
    (rec,) = disturbance_metrics(t, _hemorrhage_dip(t), TARGET, [("hemorrhage", 1000.0)])
    assert rec["peak_deviation_mmhg"] == pytest.approx(-12.0)  # sign kept: a dip is negative
    # 12·exp(-(t - 1060)/100) = 5  ⇔  t = 1060 + 100·ln(12/5); measured from the 1000 s start.
    assert rec["recovery_s"] == pytest.approx(60.0 + 100.0 * math.log(12.0 / 5.0), abs=1e-3)
    # ∫|e| = ramp 12·60/2 + 12·100 (the tail has decayed by e^-19 at the end): 1560 mmHg·s;
    # the rectangle rule at 0.1 s adds well under 1 mmHg·s.
    assert rec["iae_mmhg_s"] == pytest.approx(1560.0, abs=1.0)


def test_an_event_that_never_recovers_has_null_recovery_and_the_next_window_is_judged_alone():
    t = np.arange(0.0, 1000.0, 1.0)
    y = np.full_like(t, TARGET)
    y[(t >= 200.0) & (t < 500.0)] = TARGET - 10.0  # still down when the next event starts
    y[t >= 500.0] = TARGET + 3.0  # inside ±5 from the second event on
    first, second = disturbance_metrics(t, y, TARGET, [("bolus", 500.0), ("hemorrhage", 200.0)])
    assert (first["kind"], first["start_s"], first["end_s"]) == ("hemorrhage", 200.0, 500.0)
    assert first["recovery_s"] is None
    assert first["peak_deviation_mmhg"] == pytest.approx(-10.0)
    assert first["iae_mmhg_s"] == pytest.approx(10.0 * 300)
    assert second["recovery_s"] == 0.0  # never left the band
    assert second["peak_deviation_mmhg"] == pytest.approx(3.0)
    assert second["iae_mmhg_s"] == pytest.approx(3.0 * 500)
    # Stuck outside the band to the end of the run: null as well.
    y_stuck = np.where(t >= 200.0, TARGET - 10.0, TARGET)
    (stuck,) = disturbance_metrics(t, y_stuck, TARGET, [("hemorrhage", 200.0)])
    assert stuck["recovery_s"] is None


def test_iae_counts_only_the_event_window_and_shared_starts_share_it():
    t = np.arange(0.0, 1000.0, 0.1)
    y = np.full_like(t, TARGET - 2.0)  # constant 2 mmHg error everywhere
    recs = disturbance_metrics(
        t, y, TARGET, [("hemorrhage", 400.0), ("bolus", 700.0), ("hemorrhage", 700.0)]
    )
    assert [(r["kind"], r["start_s"], r["end_s"]) for r in recs] == [
        ("hemorrhage", 400.0, 700.0),
        ("bolus", 700.0, pytest.approx(1000.0)),
        ("hemorrhage", 700.0, pytest.approx(1000.0)),
    ]
    assert [r["iae_mmhg_s"] for r in recs] == [pytest.approx(2.0 * 300.0)] * 3


def test_nan_samples_are_skipped_and_recovery_interpolates_across_a_gap():
    t = np.arange(0.0, 400.0, 1.0)
    e = np.where(t < 100.0, 0.0, -10.0 + 0.1 * np.clip(t - 100.0, 0.0, 100.0))  # -10 → 0 by 200 s
    y = TARGET + e
    y[(t > 140.0) & (t < 170.0)] = np.nan  # the -5 mmHg crossing (150 s) falls inside the gap
    y[100] = np.nan  # and so does the deepest sample
    (rec,) = disturbance_metrics(t, y, TARGET, [("hemorrhage", 100.0)])
    # Between the valid samples 140 s (e = -6) and 170 s (e = -3) the line crosses -5 at 150 s.
    assert rec["recovery_s"] == pytest.approx(50.0, abs=1e-9)
    assert rec["peak_deviation_mmhg"] == pytest.approx(-9.9)  # deepest valid sample, 101 s
    # Valid |e| over 101..140 and 170..199: 10 - 0.1j for j = 1..40 and j = 70..99.
    expected = sum(10.0 - 0.1 * j for j in [*range(1, 41), *range(70, 100)])
    assert rec["iae_mmhg_s"] == pytest.approx(expected)
    # A window with no valid sample has no numbers at all.
    y_blind = y.copy()
    y_blind[t >= 100.0] = np.nan
    (blind,) = disturbance_metrics(t, y_blind, TARGET, [("hemorrhage", 100.0)])
    assert [blind[k] for k in ("peak_deviation_mmhg", "recovery_s", "iae_mmhg_s")] == [None] * 3


def test_run_without_a_step_has_null_step_metrics_but_disturbance_records():
    t = np.arange(0.0, 3000.0, 0.1)
    m = _run(t, _hemorrhage_dip(t), [("hemorrhage", 1000.0)])
    assert [m[k] for k in ("step_overshoot_pct", "step_rise_time_s")] == [None, None]
    assert [m[k] for k in ("step_settling_time_s", "step_iae_mmhg_s")] == [None, None]
    (rec,) = m["disturbances"]
    assert rec["peak_deviation_mmhg"] == pytest.approx(-12.0)


def test_no_event_means_the_step_window_is_the_whole_run_and_unknown_events_give_null():
    t = np.arange(0.0, 600.0, 1.0)
    y = _step_then_bolus(t)
    none = _run(t, y, [], step_time_s=0.0, step_mmhg=20.0)
    assert none["disturbances"] == []
    for old in ("overshoot_pct", "rise_time_s", "settling_time_s", "iae_mmhg_s"):
        assert none[f"step_{old}"] == none[old]
    assert none["step_overshoot_pct"] == pytest.approx(50.0)  # nothing says the bump is a bolus
    unknown = _run(t, y, None, step_time_s=0.0, step_mmhg=20.0)
    assert unknown["disturbances"] is None
    assert unknown["step_overshoot_pct"] is None and unknown["step_iae_mmhg_s"] is None
    assert unknown["overshoot_pct"] == pytest.approx(50.0)


def test_an_event_at_the_step_leaves_no_step_window():
    t = np.arange(0.0, 600.0, 1.0)
    y = _step_then_bolus(t)
    m = _run(t, y, [("hemorrhage", 0.0)], step_time_s=0.0, step_mmhg=20.0)
    assert m["step_overshoot_pct"] is None and m["step_settling_time_s"] is None
    # The window functions on their own: ending one sample after the step is too short as well.
    short = step_window_metrics(t, y, TARGET, 0.0, 20.0, end_s=1.0)
    assert set(short.values()) == {None}


def test_events_after_the_run_are_dropped_and_other_kinds_are_refused():
    t = np.arange(0.0, 100.0, 1.0)
    assert event_windows(t, [("bolus", 150.0), ("hemorrhage", 50.0)]) == [
        ("hemorrhage", 50.0, pytest.approx(100.0))
    ]
    with pytest.raises(ValueError, match="'sinusoid' must be one of"):
        event_windows(t, [("sinusoid", 0.0)])
    with pytest.raises(ValueError, match="start_s nan must be finite"):
        event_windows(t, [("bolus", math.nan)])


def test_event_labels_number_repeated_kinds_in_order():
    assert event_labels(["hemorrhage", "bolus", "hemorrhage", "hemorrhage"]) == [
        "hemorrhage",
        "bolus",
        "hemorrhage_2",
        "hemorrhage_3",
    ]


def test_aggregate_summarises_each_event_over_reachable_runs_by_magnitude():
    def run(peak: float, recovery: float | None, reachable: bool = True) -> dict:
        hem = {"kind": "hemorrhage", "start_s": 1200.0, "end_s": 2100.0}
        hem.update(peak_deviation_mmhg=peak, recovery_s=recovery, iae_mmhg_s=-10.0 * peak)
        return {"reachable": reachable, "stable": True, "disturbances": [hem]}

    runs = [run(-float(p), float(10 * p)) for p in range(1, 10)]  # peaks -1..-9 mmHg
    runs += [run(-8.0, None), run(-50.0, None, reachable=False), {"disturbances": None}]
    d = aggregate(runs)["disturbances"]
    assert list(d) == ["hemorrhage"]
    h = d["hemorrhage"]
    assert (h["kind"], h["start_s"]) == ("hemorrhage", 1200.0)
    # |peak| of the 10 reachable runs: 1..9 and 8 → sorted 1..7, 8, 8, 9: median 5.5; p90 at
    # position 0.9·9 = 8.1 between 8 and 9 → 8.1. The unreachable -50 is left out.
    assert h["peak_abs_deviation_mmhg"]["median"] == pytest.approx(5.5)
    assert h["peak_abs_deviation_mmhg"]["p90"] == pytest.approx(8.1)
    assert h["recovery_s"]["median"] == pytest.approx(50.0)  # 10..90, one null
    assert (h["recovery_s"]["n"], h["recovery_s"]["n_null"]) == (9, 1)
    assert h["iae_mmhg_s"]["n"] == 10
