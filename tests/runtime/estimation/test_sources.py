"""The sample gate and the three scheduling sources (oracle, nominal, estimated)."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

from pressor.contracts.faults import QUALITY_INVALID, QUALITY_WAVEFORM
from pressor.runtime.core.estimate import Estimate
from pressor.runtime.core.scheduling import NominalSchedule, OracleSchedule, ScheduleInput
from pressor.runtime.estimation.estimator import DelayBankEstimator
from pressor.runtime.estimation.gate import SampleGate
from pressor.runtime.estimation.settings import NOMINAL_PLANT, EstimatorSettings
from pressor.runtime.estimation.sources import SOURCES, EstimatedSchedule, make_schedule

#: MAP 60 mmHg, good quality, nothing delivered, no scheduling parameters from the device
NO_DEVICE_AT_60 = ScheduleInput(60.0, 0, 0.0, math.nan, math.nan, math.nan, False)


def test_gate_names_the_reason_of_each_rejection():
    gate = SampleGate(0.1)
    cases = [
        (70.0, 0, "ok"),
        (math.nan, 0, "nonfinite"),
        (70.1, QUALITY_INVALID, "quality"),
        (70.1, QUALITY_WAVEFORM, "quality"),
        (300.0, 0, "range"),
        (0.0, 0, "range"),
        (95.0, 0, "spike"),
        (70.2, 0, "ok"),
    ]
    for value, quality, reason in cases:
        assert gate.accept(value, quality) is (reason == "ok")
        assert gate.reason == reason
    assert gate.rejected == 6


def test_gate_accepts_a_real_level_shift_once_the_allowance_has_grown():
    gate = SampleGate(0.1, max_jump_mmhg=8.0, slew_mmhg_per_s=2.0)
    assert gate.accept(60.0, 0)
    verdicts = [gate.accept(80.0 + 0.01 * (k % 2), 0) for k in range(100)]
    first = verdicts.index(True)
    assert not any(verdicts[:first]) and all(verdicts[first:])
    assert 50 <= first <= 70  # (20 − 8) mmHg / 2 mmHg/s ≈ 6 s


def test_gate_rejects_a_flatline_after_its_run_length():
    gate = SampleGate(0.1, flatline_s=10.0)
    verdicts = [gate.accept(72.5, 0) for _ in range(150)]
    assert all(verdicts[:99]) and not any(verdicts[99:])
    assert gate.reason == "flatline"
    assert gate.accept(72.6, 0)  # the line moves again


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"sample_period_s": -0.1}, "sample_period_s"),
        ({"map_min_mmhg": 200.0, "map_max_mmhg": 20.0}, "map_min_mmhg"),
        ({"max_jump_mmhg": 0.0}, "max_jump_mmhg"),
        ({"slew_mmhg_per_s": -1.0}, "slew_mmhg_per_s"),
        ({"flatline_s": math.inf}, "flatline_s"),
    ],
)
def test_gate_rejects_bad_parameters_with_a_clear_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SampleGate(**kwargs)


def test_oracle_passes_the_device_values_and_flags_missing_ones():
    src = OracleSchedule()
    s = src.update(ScheduleInput(70.0, 0, 20.0, 0.4, 120.0, 25.0, True))
    assert (s.K, s.T_s, s.tau_s, s.source, s.valid, s.reason) == (
        0.4, 120.0, 25.0, "oracle", True, "ok",
    )  # fmt: skip
    for args in ((0.4, 120.0, 25.0, False), (math.nan, 120.0, 25.0, True)):
        s = src.update(ScheduleInput(70.0, 0, 20.0, *args))
        assert not s.valid and s.reason == "no device values"
        assert (s.K, s.T_s, s.tau_s)[1:] == args[1:3]  # passed through as sent, as before


def test_nominal_is_the_prior_whatever_the_device_sends():
    src = NominalSchedule()
    a = src.update(ScheduleInput(70.0, 0, 20.0, 0.4, 120.0, 25.0, True))
    b = src.update(ScheduleInput(math.nan, 1, math.nan, math.nan, math.nan, math.nan, False))
    assert a is b
    assert (a.K, a.T_s, a.tau_s) == NOMINAL_PLANT
    assert a.valid and a.from_prior and a.source == "nominal"
    custom = NominalSchedule(0.3, 110.0, 20.0).update(
        ScheduleInput(70.0, 0, 20.0, 1.0, 1.0, 1.0, True)
    )
    assert (custom.K, custom.T_s, custom.tau_s) == (0.3, 110.0, 20.0)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((0.0, 150.0, 40.0), "K = 0.0: .* > 0 mmHg"),
        ((0.5, math.inf, 40.0), "T_s = inf: .* > 0 s"),
        ((0.5, 150.0, -1.0), "tau_s = -1.0: .* >= 0 s"),
    ],
)
def test_nominal_rejects_bad_constants(args, match):
    with pytest.raises(ValueError, match=match):
        NominalSchedule(*args)


def test_estimated_starts_on_the_low_gain_side_of_the_prior_and_ignores_the_device():
    src = EstimatedSchedule(sample_period_s=0.1)
    s = src.update(ScheduleInput(60.0, 0, 0.0, 0.9, 180.0, 12.0, True))
    e = s.estimate
    assert e is not None and (e.K, e.T_s, e.tau_s) == NOMINAL_PLANT and e.confidence == 0.0
    # K 0.75 σ above the prior's 0.55, T 0.75 σ below 150 s but not below the box's 100 s
    assert s.K == pytest.approx(0.55 + 0.75 * 0.6 * 0.55) and s.T_s == 100.0
    assert s.tau_s == NOMINAL_PLANT[2]
    assert s.source == "estimated" and s.valid and s.healthy and s.from_prior
    assert s.reason == "learning"


def _estimate(K: float, K_std: float, T_s: float, T_std_s: float) -> Estimate:
    return Estimate(K, T_s, 20.0, K_std, T_std_s, 15.0, 25.0, 0.5, True, False, "ok", True)


@pytest.mark.parametrize(
    ("est", "K", "T_s"),
    [
        (_estimate(0.5, 0.35, 200.0, 130.0), 0.5 + 0.75 * 0.35, 200.0 - 0.75 * 130.0),  # full
        (_estimate(0.5, 0.15, 150.0, 45.0), 0.5 + 0.375 * 0.15, 150.0 - 0.375 * 45.0),  # 30 %
        (_estimate(0.5, 0.015, 150.0, 4.5), 0.5 + 0.0375 * 0.015, 150.0 - 0.0375 * 4.5),  # 3 %
        (_estimate(0.9, 0.3, 110.0, 40.0), 1.0, 100.0),  # stops at the box's K high, T low
        (_estimate(1.5, 0.3, 90.0, 40.0), 1.5, 90.0),  # already beyond: the estimate as is
    ],
)
def test_cautious_shift_is_on_the_low_gain_side_and_shrinks_with_the_uncertainty(est, K, T_s):
    assert EstimatedSchedule().cautious(est) == pytest.approx((K, T_s))
    assert EstimatedSchedule(caution_sigma=0.0).cautious(est) == (est.K, est.T_s)


@pytest.mark.parametrize(
    ("K", "T_s", "expected"),
    [
        (0.3, 60.0, (0.5, 100.0)),  # below the box's T low edge: onto it, K/T = 0.005 kept
        (0.6, 25.0, (2.4, 100.0)),  # far below: K rises by the same factor, beyond the box's K
        (0.3, 100.0, (0.3, 100.0)),  # on the edge: unchanged
        (0.3, 150.0, (0.3, 150.0)),  # inside: unchanged
        (0.3, 400.0, (0.3, 400.0)),  # above the box: the controller clamps T, K as is
    ],
)
def test_keep_slope_moves_a_lag_below_the_box_onto_its_edge_at_the_same_K_over_T(K, T_s, expected):
    assert EstimatedSchedule().keep_slope(K, T_s) == pytest.approx(expected)
    assert EstimatedSchedule(keep_slope=False).keep_slope(K, T_s) == (K, T_s)


def test_a_prior_lag_below_the_box_is_scheduled_on_the_box_edge_with_the_sensitivity_raised():
    # prior T 60 s is below the design box (100-200 s): caution leaves it there, keep_slope moves it
    est = DelayBankEstimator(0.1, EstimatorSettings(prior=(0.3, 60.0, 20.0)))
    s = EstimatedSchedule(est).update(NO_DEVICE_AT_60)
    cautious_K = 0.3 + 0.75 * 0.6 * 0.3
    assert s.from_prior and s.T_s == 100.0
    assert s.K == pytest.approx(cautious_K * 100.0 / 60.0)
    off = EstimatedSchedule(
        DelayBankEstimator(0.1, EstimatorSettings(prior=(0.3, 60.0, 20.0))), keep_slope=False
    )
    s_off = off.update(NO_DEVICE_AT_60)
    assert s_off.T_s == 60.0 and s_off.K == pytest.approx(cautious_K)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"caution_sigma": -1.0}, "caution_sigma"), ({"caution_rel_std": math.nan}, "caution_rel")],
)
def test_estimated_rejects_bad_caution_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        EstimatedSchedule(**kwargs)


def test_estimated_schedules_on_the_estimate_once_learned():
    est = DelayBankEstimator(0.1)
    src = EstimatedSchedule(est)
    # a first-order lag, K 0.5, T 120 s, τ 20 s, driven by rate steps every 200 s
    x, d, rates = 0.0, math.exp(-0.1 / 120.0), []
    s = None
    for k in range(24000):
        rate = 10.0 + 40.0 * ((k // 2000) % 2) + 15.0 * ((k // 3000) % 2)
        rates.append(rate)
        noise = 0.05 * math.sin(1.7 * k)  # deterministic jitter: not a flatline
        s = src.update(
            ScheduleInput(55.0 + x + noise, 0, rates[k - 1] if k else 0.0, 9.0, 9.0, 9.0, True)
        )
        x = d * x + (1.0 - d) * 0.5 * (rates[k - 200] if k >= 200 else 0.0)
    assert s is not None and not s.from_prior and s.reason == "ok" and s.healthy
    assert abs(s.K - 0.5) / 0.5 < 0.15 and abs(s.T_s - 120.0) / 120.0 < 0.25
    assert abs(s.tau_s - 20.0) < 5.0
    assert s.estimate is est.estimate


def test_make_schedule_builds_each_named_source():
    from pressor.runtime.inputs.config import load_controller

    assert SOURCES == ("oracle", "estimated", "nominal", "validated", "cautious")
    cautious = load_controller("lpv:cautious", 0.1)
    assert [make_schedule(name, 0.1, cautious).source for name in SOURCES] == list(SOURCES)
    with pytest.raises(ValueError, match="not one of"):
        make_schedule("truth")
    with pytest.raises(ValueError, match="needs the controller"):
        make_schedule("cautious")
    with pytest.raises(ValueError, match="log-K"):
        make_schedule("cautious", 0.1, load_controller("lpv", 0.1))


def test_estimation_imports_no_numpy_solver_or_simulator():
    code = (
        "import sys, pressor.runtime.estimation.sources\n"
        "print(sorted(m for m in ('numpy', 'scipy', 'cvxpy', 'pressor.hil_sim', 'pressor.synthesis', 'pressor.link')"
        " if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_another_drugs_design_schedules_inside_its_own_box_from_the_first_tick():
    # lpv:norepinephrine (K 0.1-3.2, T 150-750 s, tau 20-55 s): the estimated and validated sources
    # take its box, not phenylephrine's (whose caution put T at 100 s, outside it, at tick 0)
    import math

    from pressor.runtime.core.scheduling import ScheduleInput
    from pressor.runtime.core.supervisor_config import sched_limits_of
    from pressor.runtime.estimation.settings import DESIGN_BOX
    from pressor.runtime.inputs.config import load_controller

    ne = load_controller("lpv:norepinephrine", 0.1)
    box, _ = sched_limits_of(ne)
    for name in ("estimated", "validated", "nominal"):
        source = make_schedule(name, 0.1, ne)
        if name == "nominal":
            continue
        for tick in range(600):
            mp = 55.0 + 0.01 * tick
            s = source.update(ScheduleInput(mp, 0, 5.0, math.nan, math.nan, math.nan, False))
            assert all(
                lo <= v <= hi for v, (lo, hi) in zip((s.K, s.T_s, s.tau_s), box, strict=True)
            )
    # the shipped phenylephrine design keeps its tuned sources
    ph = make_schedule("estimated", 0.1, load_controller("lpv", 0.1))
    assert ph.estimator.box == make_schedule("estimated", 0.1).estimator.box
    assert make_schedule("estimated", 0.1, ne).estimator.box == tuple(box)
    assert tuple(box) != tuple(DESIGN_BOX)
