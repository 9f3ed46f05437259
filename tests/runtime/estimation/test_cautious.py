"""The cautious start (runtime/estimation/cautious.py) with the generated log-K module it schedules:
safe first commands on the most sensitive patient, K lowered on evidence at the certified rate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pressor.contracts.drug import REFERENCE_WEIGHT_KG, DoseScale
from pressor.runtime.core.scheduling import ScheduleInput
from pressor.runtime.estimation.cautious import CautiousSchedule
from pressor.runtime.estimation.design_envelope import envelope_of
from pressor.runtime.estimation.sources import make_schedule
from pressor.runtime.inputs.config import load_controller

TS = 0.1
STEP = 20.0
BASE = 55.0


def _loop(K: float, T: float, tau: float, seconds: float, dose: DoseScale | None = None):
    """The cautious schedule and lpv:cautious on a first-order patient K e^(-tau s)/(T s + 1)
    (exact discretisation, the command held over each tick, delay by whole ticks); a +20 mmHg
    target from rest at t = 0. Returns (commands ml/h, MAP mmHg, scheduled K) per tick."""
    ctl = load_controller("lpv:cautious", TS)
    sched = make_schedule("cautious", TS, ctl, dose)
    a = math.exp(-TS / T)
    d = int(round(tau / TS))
    pipe = [0.0] * (d + 1)
    y, u = 0.0, 0.0
    us, ys, ks = [], [], []
    for _ in range(int(seconds / TS)):
        mp = BASE + y
        s = sched.update(ScheduleInput(mp, 0, u, math.nan, math.nan, math.nan, False))
        u = ctl.step(mp, BASE + STEP, s.K, s.T_s, s.tau_s)
        pipe.append(u)
        y = a * y + (1.0 - a) * K * pipe.pop(0)
        us.append(u)
        ys.append(y)
        ks.append(s.K)
    return us, ys, ks


def test_the_start_is_twice_the_population_top_in_ml_h_of_the_syringe_and_patient():
    ctl = load_controller("lpv:cautious", TS)
    env = envelope_of(ctl)
    assert env.population == (0.42, 420.0) and env.concentration_ug_ml == 100.0
    assert env.drug == "phenylephrine"
    ref = CautiousSchedule(env, TS)
    # 420 mmHg per ug/kg/min at 100 ug/ml and 70 kg: 420 * 100 / (60 * 70) = 10 mmHg/(ml/h),
    # times phenylephrine's start margin 2
    assert ref.dose == DoseScale(100.0, REFERENCE_WEIGHT_KG)
    assert ref.k_top == pytest.approx(20.0) and ref.K == ref.k_top
    # at 30 kg twice the top (46.7) is beyond the box: the box's top, 25 mmHg/(ml/h)
    light = CautiousSchedule(env, TS, DoseScale(100.0, 30.0))
    assert light.k_top == pytest.approx(25.0)
    # T: phenylephrine's 300 s; tau: the box's longest
    assert ref.T_s == pytest.approx(300.0) and ref.tau_s == pytest.approx(45.0)
    plain = CautiousSchedule(env, TS, start_margin=1.0, T_s=200.0)
    assert plain.k_top == pytest.approx(10.0) and plain.T_s == 200.0
    assert ref.effect_lag_s == 60.0


def test_the_evidence_waits_for_an_effect_site_behind_the_slowest_patient():
    # no response to 10 ml/h: K falls as fast as the slowest patient would have answered. With
    # an effect site (60 s) behind its lag that patient answers later, so at 90 s (45 s after
    # the longest delay) K has fallen less than it would without one
    env = envelope_of(load_controller("lpv:cautious", TS))

    def k_at(seconds: float, sched: CautiousSchedule) -> float:
        inp = ScheduleInput(60.0, 0, 10.0, math.nan, math.nan, math.nan, False)
        for _ in range(int(seconds / TS)):
            k = sched.update(inp).K
        return k

    with_site, without = CautiousSchedule(env, TS), CautiousSchedule(env, TS)
    without._slow.a2 = None  # the same schedule with a first-order slowest patient
    assert k_at(90.0, with_site) > 1.2 * k_at(90.0, without)


def test_norepinephrine_starts_at_its_population_top_on_its_t_of_300_s_without_effect_site():
    ctl = load_controller("lpv:norepinephrine-cautious", TS)
    env = envelope_of(ctl)
    assert env.drug == "norepinephrine"
    sched = CautiousSchedule(env, TS)
    (_, _), (t_lo, t_hi), _ = env.box
    assert sched.k_top == pytest.approx(sched.dose.k_ml_h(env.population[1]))
    assert t_lo < sched.T_s == 300.0 < math.sqrt(t_lo * t_hi)
    assert sched.effect_lag_s is None


def test_norepinephrine_reads_its_evidence_against_a_slowest_patient_of_550_s():
    # no response to 2 ml/h for 300 s: K falls (at the certified rate, then along the bound) to
    # what a slowest patient of 550 s, not the box's 750 s, is compatible with. Hand values: the
    # unit response of e^(-55 s)/(T s + 1) to 2 ml/h at 300 s is s = 2(1 - e^(-245/T)), and with
    # no response the bound settles where K s - m = 0, m = 1 + 0.1 K s: K = 1/(0.9 s)
    env = envelope_of(load_controller("lpv:norepinephrine-cautious", TS))
    sched = CautiousSchedule(env, TS)
    box = CautiousSchedule(env, TS, evidence_T_s=env.box[1][1])
    assert (sched.evidence_T_s, box.evidence_T_s) == (550.0, 750.0)
    inp = ScheduleInput(60.0, 0, 2.0, math.nan, math.nan, math.nan, False)
    for _ in range(int(round(300.0 / TS))):
        k, k_box = sched.update(inp).K, box.update(inp).K
    for T, got in ((550.0, k), (750.0, k_box)):
        assert got == pytest.approx(1.0 / (0.9 * 2.0 * (1.0 - math.exp(-245.0 / T))), rel=0.01)


def _k_after_no_response(sched: CautiousSchedule, target_mmhg: float, seconds: float) -> float:
    """K̂ after ``seconds`` of 2 ml/h and no response (MAP 60 mmHg), ``target_mmhg`` given."""
    inp = ScheduleInput(60.0, 0, 2.0, math.nan, math.nan, math.nan, False, target_mmhg)
    for _ in range(int(round(seconds / TS))):
        k = sched.update(inp).K
    return k


def test_norepinephrine_s_dose_ceiling_stops_k_hat_where_a_hill_curve_of_2_5_could_pass_the_step():
    # no response to 2 ml/h for 3000 s, target 80 from 60 mmHg (step 20): the evidence's slowest
    # patient (550 s, tau 55 s) has answered s = 2 (1 - e^(-2945/550)). A Hill curve of exponent
    # 2.5 from zero that stays under the 1 mmHg margin there reaches 22 mmHg (the step and a
    # tenth) at u_c = s 22^(1/2.5), so K-hat stops at 20/u_c; without the ceiling it falls to
    # where the margin hides the patient, K s - (1 + 0.1 K s) = 0: 1/(0.9 s)
    env = envelope_of(load_controller("lpv:norepinephrine-cautious", TS))
    s = 2.0 * (1.0 - math.exp(-2945.0 / 550.0))
    ceiling = CautiousSchedule(env, TS)
    assert ceiling.hill_ceiling == 2.5
    assert _k_after_no_response(ceiling, 80.0, 3000.0) == pytest.approx(
        20.0 / (s * 22.0**0.4), rel=2e-3
    )
    none = CautiousSchedule(env, TS, hill_ceiling=0.0)
    assert none.hill_ceiling is None
    assert _k_after_no_response(none, 80.0, 3000.0) == pytest.approx(1.0 / (0.9 * s), rel=2e-3)


#: a swing up through the band and back (mmHg, ticks; target 70, band ±5): a tick at 68 mmHg
#: (jumps the sample gate accepts), 120 s at 76 mmHg, a tick at 68 mmHg
_SWING = ((68.0, 1), (76.0, 1200), (68.0, 1))


def _k_through_swings(
    sched: CautiousSchedule, swings: int, ks: list[float] | None = None
) -> tuple[float, list[float]]:
    """2 ml/h throughout, target 70 from 60 mmHg: no response for 300 s, the MAP in the band
    (66 mmHg) for 10 s, below it (60 mmHg, a haemorrhage's reading) for 3000 s, then ``swings``
    times a swing above it (:data:`_SWING`) and 3000 s below it again. Returns (K̂ at the first
    tick in the band, K̂ at the end of each stretch below the band); ``ks`` gets every tick's K̂."""
    ks = [] if ks is None else ks

    def feed(map_mmhg: float, ticks: int) -> float:
        inp = ScheduleInput(map_mmhg, 0, 2.0, math.nan, math.nan, math.nan, False, 70.0)
        for _ in range(ticks):
            ks.append(sched.update(inp).K)
        return ks[-1]

    feed(60.0, 3000)
    at_entry = feed(66.0, 1)
    feed(66.0, 100)
    ends = [feed(60.0, 30000)]
    for _ in range(swings):
        for map_mmhg, ticks in _SWING:
            feed(map_mmhg, ticks)
        ends.append(feed(60.0, 30000))
    return at_entry, ends


def _ticks_to_the_swing() -> int:
    """Ticks of :data:`_SWING` up to the one where the MAP's 30 s low-pass, at 60 mmHg before it,
    first passes 75 mmHg (the band's top): after the tick at 68 it stands at 68 - 8a, then
    76 - (8 + 8a) a^n after n ticks at 76 (a = e^(-0.1/30))."""
    a = math.exp(-TS / 30.0)
    n = 1
    while (8.0 + 8.0 * a) * a**n >= 1.0:
        n += 1
    return 1 + n


def test_after_the_map_first_reaches_the_band_k_hat_falls_at_most_to_half_its_value_then():
    # a drop after the start is read as a less sensitive patient: without the floor K-hat falls to
    # where the margin hides the patient, 1/(0.9 s) with s = 2 (1 - e^(-(3310 - 55)/550)) (hand
    # value); norepinephrine's floor keeps it at half its value when the MAP entered the band
    env = envelope_of(load_controller("lpv:norepinephrine-cautious", TS))
    floored = CautiousSchedule(env, TS, hill_ceiling=0.0)
    assert floored.settle_floor == 0.5
    entry, (end,) = _k_through_swings(floored, 0)
    free_entry, (free_end,) = _k_through_swings(
        CautiousSchedule(env, TS, hill_ceiling=0.0, settle_floor=0.0), 0
    )
    assert entry == free_entry  # the same source until the start ended
    s = 2.0 * (1.0 - math.exp(-(3310.0 - 55.0) / 550.0))
    assert free_end == pytest.approx(1.0 / (0.9 * s), rel=2e-3)
    assert end == pytest.approx(0.5 * entry, rel=1e-12) and end > 1.2 * free_end


def test_a_swing_up_through_the_band_raises_k_hat_by_half_at_the_certified_rise_up_to_its_entry():
    # after the start the drop holds K-hat at its floor, half its value at the entry (K_e). The
    # MAP then swings above the band: on each tick at 68 and 76 mmHg K-hat rises one certified
    # step (more response than it predicts), and on the tick where the MAP's 30 s low-pass passes
    # 75 mmHg the floor becomes 1.5 times K-hat then: 0.75 K_e times those steps. Below the band
    # again K-hat climbs to that floor and stays there, though the evidence would lower it (going
    # out below is no swing). A second swing would make it above K_e: capped at K_e
    env = envelope_of(load_controller("lpv:norepinephrine-cautious", TS))
    assert CautiousSchedule(env, TS).swing_raise == 1.5
    up = math.exp(0.99 * env.rise_per_s * TS)
    entry, ends = _k_through_swings(CautiousSchedule(env, TS, hill_ceiling=0.0), 2)
    assert ends[0] == pytest.approx(0.5 * entry, rel=1e-12)
    assert ends[1] == pytest.approx(0.75 * up ** _ticks_to_the_swing() * entry, rel=1e-12)
    assert ends[2] == pytest.approx(entry, rel=1e-12)
    off_entry, off = _k_through_swings(
        CautiousSchedule(env, TS, hill_ceiling=0.0, swing_raise=0), 2
    )
    assert off_entry == entry and off == pytest.approx([0.5 * entry] * 3, rel=1e-12)


def test_k_hat_never_rises_faster_than_the_certified_rise_through_swings():
    env = envelope_of(load_controller("lpv:norepinephrine-cautious", TS))
    ks: list[float] = []
    _k_through_swings(CautiousSchedule(env, TS, hill_ceiling=0.0), 2, ks)
    step = math.exp(0.99 * env.rise_per_s * TS)  # the certified rise, 1 % short, over a tick
    rises = [b / a for a, b in zip(ks, ks[1:], strict=False)]
    assert max(rises) == pytest.approx(step, rel=1e-12)


def test_monitor_noise_around_the_target_is_no_swing():
    # 2 mmHg of noise at 10 Hz on a MAP at the target leaves the band on both sides many times a
    # minute; its 30 s low-pass never does, so below the band again K-hat falls back to its floor
    env = envelope_of(load_controller("lpv:norepinephrine-cautious", TS))
    sched = CautiousSchedule(env, TS, hill_ceiling=0.0)
    entry, _ = _k_through_swings(sched, 0)
    noisy = 70.0 + 2.0 * np.random.default_rng(7).standard_normal(int(round(600.0 / TS)))
    assert (noisy > 75.0).any() and (noisy < 65.0).any()
    for m in [*noisy, *[60.0] * int(round(3000.0 / TS))]:
        k = sched.update(
            ScheduleInput(float(m), 0, 2.0, math.nan, math.nan, math.nan, False, 70.0)
        ).K
    assert k == pytest.approx(0.5 * entry, rel=1e-12)


@pytest.mark.parametrize("target_mmhg", [math.nan, 60.0, 55.0])
def test_the_dose_ceiling_and_the_floor_act_only_with_a_target_above_the_first_map(target_mmhg):
    # a MAP that starts in the band (60 or 55 mmHg against 60) has no start to end: no floor
    env = envelope_of(load_controller("lpv:norepinephrine-cautious", TS))
    s = 2.0 * (1.0 - math.exp(-2945.0 / 550.0))
    got = _k_after_no_response(CautiousSchedule(env, TS), target_mmhg, 3000.0)
    assert got == pytest.approx(1.0 / (0.9 * s), rel=2e-3)


def test_phenylephrine_has_no_dose_ceiling_and_no_floor_after_the_start_but_a_swing_raises_k():
    sched = CautiousSchedule(envelope_of(load_controller("lpv:cautious", TS)), TS)
    assert sched.hill_ceiling is None and sched.settle_floor is None
    assert sched.swing_raise == 1.5


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"hill_ceiling": 0.5}, "hill_ceiling=0.5 must be finite and >= 1"),
        ({"hill_ceiling": math.inf}, "hill_ceiling=inf must be finite and >= 1"),
        ({"settle_floor": 1.5}, r"settle_floor=1.5 must be in \(0, 1\]"),
        ({"settle_floor": -0.5}, r"settle_floor=-0.5 must be in \(0, 1\]"),
        ({"swing_raise": 1.0}, "swing_raise=1.0 must be finite and > 1"),
        ({"swing_raise": math.nan}, "swing_raise=nan must be finite and > 1"),
        ({"start_margin": 0.5}, "start_margin"),
        ({"T_s": 50.0}, "T box"),
        ({"T_s": 900.0}, "T box"),
        ({"evidence_T_s": 50.0}, "evidence_T_s=50.0 s must lie in the design's T box"),
        ({"evidence_T_s": 900.0}, "evidence_T_s=900.0 s must lie in the design's T box"),
    ],
)
def test_settings_outside_their_range_are_refused_naming_them(kwargs, needle):
    env = envelope_of(load_controller("lpv:cautious", TS))
    with pytest.raises(ValueError, match=needle):
        CautiousSchedule(env, TS, **kwargs)


def test_first_commands_on_the_most_sensitive_patient_stay_below_the_hand_computed_bound():
    # K starts at 2 x 10 = 20 mmHg/(ml/h). The feedforward's opening push is T_lag dr /
    # (lambda K) = 100 * 20 / (10 * 20) = 10 ml/h and the feedback starts from 0, so no command
    # of the first 10 s (the box's shortest delay: nothing can be known before) exceeds 10 ml/h,
    # and the dose of the first 60 s stays below what holds the step on the box's fastest patient
    # with K 20 (T 100 s) for that long plus its opening push: dr/K * 60 s + T_lag dr/K.
    for K in (10.0, 20.0):  # the population's 10x top, and twice it (the start)
        for T, tau in ((100.0, 10.0), (200.0, 27.5), (400.0, 45.0)):
            us, ys, _ = _loop(K, T, tau, 60.0)
            assert max(us[:100]) <= 10.0 + 1e-9
            assert sum(us) * TS <= STEP / 20.0 * 60.0 + 100.0 * STEP / 20.0
    # on the box's fastest patients at the top and at twice the top, MAP stays within 10 % of
    # the step above the target (the figure), and K is never lowered far below theirs
    for K in (10.0, 20.0):
        for T, tau in ((100.0, 10.0), (100.0, 45.0), (200.0, 27.5)):
            us, ys, ks = _loop(K, T, tau, 1200.0)
            assert max(ys) <= 1.10 * STEP, (K, T, tau, max(ys))
            assert min(ks) >= K / 1.25


def test_a_less_sensitive_patient_lowers_k_at_the_certified_rate_and_reaches_the_target():
    us, ys, ks = _loop(0.5, 150.0, 30.0, 1800.0)
    ctl = load_controller("lpv:cautious", TS)
    fall = envelope_of(ctl).fall_per_s
    # K never falls faster than the certified rate, and it does fall while the MAP lags
    ratios = [b / a for a, b in zip(ks[:-1], ks[1:], strict=True)]
    assert min(ratios) >= math.exp(-fall * TS) - 1e-12
    assert ks[3000] < 0.25 * ks[0]
    # the patient reaches the band without overshooting it
    first = next(i for i, y in enumerate(ys) if abs(y - STEP) <= 5.0)
    # within 12 min: K falls only as fast as the slowest patient, with an effect site behind it,
    # would have answered (the price of no overshoot on the PK/PD patients, the module docstring)
    assert first * TS < 720.0
    assert max(ys) <= 1.10 * STEP


def test_no_response_lowers_k_to_what_the_margin_can_hide():
    # a patient who does not respond to 10 ml/h: after the slowest delay K falls until the
    # response it predicts is the margin, K * 10 = 1 + 0.1 K * 10, K = 1/9 mmHg/(ml/h)
    ctl = load_controller("lpv:cautious", TS)
    sched = CautiousSchedule(envelope_of(ctl), TS)
    ks = []
    for _ in range(int(1500 / TS)):
        ks.append(sched.update(ScheduleInput(60.0, 0, 10.0, math.nan, math.nan, math.nan, False)).K)
    assert ks[100] == pytest.approx(sched.k_top)  # nothing yet within the shortest delay
    assert ks[-1] == pytest.approx(1.0 / 9.0, rel=0.05)
    assert sched.k_floor == pytest.approx(0.42 * 100.0 / (60.0 * 70.0))


def test_a_larger_response_than_k_hat_predicts_raises_k_at_most_at_the_certified_rise():
    ctl = load_controller("lpv:cautious", TS)
    env = envelope_of(ctl)
    sched = CautiousSchedule(env, TS)
    sched.K = 1.0  # as if evidence had lowered it; the patient then answers as a K = 5 one
    a = math.exp(-TS / 100.0)
    y = 0.0
    ks = []
    for _ in range(3000):
        y = a * y + (1 - a) * 5.0 * 2.0
        ks.append(sched.update(ScheduleInput(60.0 + y, 0, 2.0, math.nan, math.nan, math.nan, 0)).K)
    assert ks[-1] > 1.5
    ratios = [b / a for a, b in zip(ks[:-1], ks[1:], strict=True)]
    assert max(ratios) <= math.exp(env.rise_per_s * TS) + 1e-12


def test_a_falling_map_after_the_rate_is_cut_does_not_lower_k_below_the_patient():
    # the box's fastest patient (K 1 mmHg/(ml/h), T 100 s, tau 10 s) given 10 ml/h for 600 s,
    # then nothing: its MAP falls back sooner than the slowest patient's would. Read against the
    # slowest patient that fall is a less sensitive patient; after the cut it is no evidence, and
    # K stays above the patient's 1 (the trough of an oscillation, docstring "Not after a cut")
    ctl = load_controller("lpv:cautious", TS)
    sched = CautiousSchedule(envelope_of(ctl), TS)
    a = math.exp(-TS / 100.0)
    rates = [10.0] * int(600 / TS) + [0.0] * int(1200 / TS)
    pipe = [0.0] * int(10.0 / TS)
    y, ks, inverted = 0.0, [], 0
    for u in rates:
        pipe.append(u)
        y = a * y + (1.0 - a) * 1.0 * pipe.pop(0)
        ks.append(sched.update(ScheduleInput(60.0 + y, 0, u, math.nan, math.nan, math.nan, 0)).K)
        inverted += sched._fast.response < sched._slow.response
    assert inverted > 1000  # the cut turned the ordering for minutes
    assert ks[int(600 / TS)] > 1.0  # what the running rate left
    assert min(ks) > 1.0
