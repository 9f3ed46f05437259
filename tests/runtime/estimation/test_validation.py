"""The opt-in ``validated`` scheduling source (slew-limited, on a validated model): its model bank,
its wiring and its closed loop off the FOPDT class (runtime/estimation/validation.py,
runtime/estimation/sources.py: ValidatedSchedule)."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from pressor.hil_sim.episode import simulate
from pressor.hil_sim.world import World
from pressor.link import PumpStatus, TickInputs
from pressor.runtime.core.closed_loop import CLEAN_LINK, ClosedLoopCore
from pressor.runtime.core.scheduling import NominalSchedule, ScheduleInput
from pressor.runtime.core.supervisor import Supervisor
from pressor.runtime.core.supervisor_config import Fault, supervisor_config_for
from pressor.runtime.estimation.settings import DESIGN_BOX, NOMINAL_PLANT
from pressor.runtime.estimation.sources import SOURCES, make_schedule
from pressor.runtime.estimation.validated import DESIGN_RATES, ValidatedSchedule
from pressor.runtime.estimation.validation import ModelBank
from pressor.runtime.inputs.controller_loader import load_controller

TS = 0.1
WINDOW_S = 2.0


def test_validated_is_opt_in_and_starts_on_the_nominal_patient_ignoring_the_device():
    assert "validated" in SOURCES and make_schedule("validated", TS).source == "validated"
    assert type(make_schedule("estimated", TS)).__name__ == "EstimatedSchedule"
    src = ValidatedSchedule(sample_period_s=TS)
    s = src.update(ScheduleInput(60.0, 0, 0.0, 0.9, 180.0, 12.0, True))
    e = s.estimate
    assert e is not None and (e.K, e.T_s, e.tau_s) == NOMINAL_PLANT and e.confidence == 0.0
    assert (s.K, s.T_s, s.tau_s) == NOMINAL_PLANT
    assert s.source == "validated" and s.valid and s.healthy and s.from_prior
    assert s.reason == "prior"


def test_validated_in_the_trial_holds_K_and_moves_T_and_tau_inside_the_box_at_the_rates():
    # the project's own patient through the trial's closed loop (the core pressor run/sil step)
    world = World("paper-tracking", 3, TS)
    traj = simulate(
        world, load_controller("lpv", TS), 900.0, schedule=make_schedule("validated", TS)
    )
    assert np.all(traj.sched_K == NOMINAL_PLANT[0])
    (_, _), (T_lo, T_hi), (d_lo, d_hi) = DESIGN_BOX
    T, tau = traj.sched_T_s, traj.sched_tau_s
    assert np.all((T_lo <= T) & (T <= T_hi) & (d_lo <= tau) & (tau <= d_hi))
    assert np.max(np.abs(np.diff(T))) <= DESIGN_RATES[1] * TS + 1e-9
    assert np.max(np.abs(np.diff(tau))) <= DESIGN_RATES[2] * TS + 1e-9
    assert not np.any(traj.faults & int(Fault.SCHED_RATE | Fault.SCHED_OUT_OF_BOX))


def _feed_fopdt(bank: ModelBank, K: float, T_s: float, tau_s: float, rates: list[float]) -> None:
    """Window means of a FOPDT plant (exact ZOH at the window) plus seeded noise, into ``bank``."""
    rng = random.Random(5)
    a = math.exp(-WINDOW_S / T_s)
    d = round(tau_s / WINDOW_S)
    x = 0.0
    for j, _ in enumerate(rates):
        x = a * x + K * (1.0 - a) * (rates[j - d] if j >= d else 0.0)
        bank.close_window(55.0 + x + rng.gauss(0.0, 0.05), rates[j], 0.05**2)
        for _ in range(20):
            bank.step()


def _staircase(n_windows: int) -> list[float]:
    return [10.0 + 30.0 * ((j // 100) % 2) + 10.0 * ((j // 150) % 2) for j in range(n_windows)]


def test_bank_adopts_the_model_that_generated_the_data():
    bank = ModelBank(WINDOW_S, 20, NOMINAL_PLANT)
    _feed_fopdt(bank, 0.85, 100.0, 15.0, _staircase(900))
    assert bank.target == (0.85, 100.0, 15.0)


def test_bank_keeps_the_nominal_model_when_the_rate_never_moves():
    bank = ModelBank(WINDOW_S, 20, NOMINAL_PLANT)
    _feed_fopdt(bank, 0.85, 100.0, 15.0, [0.0] * 900)
    assert bank.adopted == 0 and bank.target == NOMINAL_PLANT


def test_bank_keeps_the_nominal_model_when_the_data_are_the_nominal_patients():
    bank = ModelBank(WINDOW_S, 20, NOMINAL_PLANT)
    _feed_fopdt(bank, *NOMINAL_PLANT, _staircase(900))
    assert bank.adopted == 0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"window_s": 0.0}, "window_s"),
        ({"ticks_per_window": 0}, "ticks_per_window"),
        ({"horizon_s": 1.0}, "horizon_s"),
        ({"memory_s": 2.0}, "memory_s"),
        ({"margin_rel": 1.0}, "margin_rel"),
        ({"margin_sigma2": 0.0}, "margin_sigma2"),
        ({"near_sigma2": -1.0}, "near_sigma2"),
        ({"K_grid": (0.0,)}, "K of the bank"),
        ({"nominal": (0.5, 150.0)}, "nominal"),
    ],
)
def test_bank_rejects_bad_settings_by_name(kwargs, match):
    args = {"window_s": WINDOW_S, "ticks_per_window": 20, "nominal": NOMINAL_PLANT} | kwargs
    with pytest.raises(ValueError, match=match):
        ModelBank(**args)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"rate_fraction": 0.0}, "rate_fraction"),
        ({"rate_fraction": 1.5}, "rate_fraction"),
        ({"rate_bounds": (2e-4, 0.06)}, "rate_bounds"),
        ({"start": (0.1, 150.0, 40.0)}, "start"),
        ({"sample_period_s": -0.1}, "sample_period_s"),
    ],
)
def test_validated_rejects_bad_settings_by_name(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ValidatedSchedule(**kwargs)


def test_validated_slews_T_and_tau_at_nine_tenths_of_the_certified_rates_and_holds_K():
    # a FOPDT patient (K 0.85, T 100 s, τ 15 s) on a rate staircase: the bank adopts it, and the
    # schedule moves from the nominal (0.55, 150 s, 40 s) toward its T and τ
    src = ValidatedSchedule(sample_period_s=TS)
    a = math.exp(-TS / 100.0)
    x, rates, rng = 0.0, [], random.Random(3)
    sched = []
    for k in range(9000):
        rates.append(10.0 + 30.0 * ((k // 2000) % 2))
        y = 55.0 + x + rng.gauss(0.0, 0.1)
        s = src.update(ScheduleInput(y, 0, rates[k - 1] if k else 0.0, 9.0, 9.0, 9.0, True))
        sched.append((s.K, s.T_s, s.tau_s))
        x = a * x + (1.0 - a) * 0.85 * (rates[k - 150] if k >= 150 else 0.0)
    assert src.bank.target[1:] == (100.0, 15.0)
    assert all(K == NOMINAL_PLANT[0] for K, _, _ in sched)
    dT = [abs(b[1] - a[1]) for a, b in zip(sched, sched[1:], strict=False)]
    dtau = [abs(b[2] - a[2]) for a, b in zip(sched, sched[1:], strict=False)]
    assert max(dT) == pytest.approx(0.9 * 0.06 * TS) and max(dtau) == pytest.approx(0.9 * 0.1 * TS)
    assert sched[-1][2] == 15.0 and sched[-1][1] < 150.0


def _second_order_run(schedule: ValidatedSchedule | NominalSchedule) -> tuple[float, int, list]:
    """The shipped LPV on a second-order-plus-delay patient (outside the FOPDT class): MAP =
    55 mmHg + 0.9 mmHg/(ml/h) · e^(−25 s·s) / ((120 s·s + 1)(40 s·s + 1)) · rate, target 70 mmHg,
    30 min, 0.3 mmHg seeded monitor noise. Returns IAE (mmHg·s), the ticks the supervisor flagged
    SCHED_RATE or SCHED_OUT_OF_BOX, and the schedule of every tick."""
    controller = load_controller("lpv", TS)
    core = ClosedLoopCore(controller, Supervisor(supervisor_config_for(controller, 0.3)), schedule)
    rng = random.Random(2026)
    a1, a2 = math.exp(-TS / 120.0), math.exp(-TS / 40.0)
    x1 = x2 = 0.0
    pipe = [0.0] * 250
    status, iae, flagged, sched = None, 0.0, 0, []
    for k in range(18000):
        y = 55.0 + x2
        iae += abs(70.0 - y) * TS
        inp = TickInputs(k, k * TS, y + rng.gauss(0.0, 0.3), 0, 70.0, math.nan, math.nan,
                         math.nan, False, -1, k)  # fmt: skip
        rec = core.step(inp, k * TS, status, CLEAN_LINK)
        flagged += bool(rec.supervisor.faults & (Fault.SCHED_RATE | Fault.SCHED_OUT_OF_BOX))
        sched.append((rec.schedule.K, rec.schedule.T_s, rec.schedule.tau_s))
        rate = min(max(rec.command_ml_h, 0.0), 120.0)
        pipe.append(rate)
        u = pipe.pop(0)
        x1 = a1 * x1 + (1.0 - a1) * 0.9 * u
        x2 = a2 * x2 + (1.0 - a2) * x1
        status = PumpStatus(k + 1, rate, 0.0, 0)
    return iae, flagged, sched


def test_validated_is_no_worse_than_nominal_off_the_fopdt_class_and_keeps_the_certificate():
    iae_val, flagged, sched = _second_order_run(ValidatedSchedule(sample_period_s=TS))
    iae_nom, _, _ = _second_order_run(NominalSchedule())
    # not strictly <=: here the adopted T, τ cost 2 % (IAE 2136 vs 2093 mmHg·s); the issue's
    # per-patient bound is 1.2x nominal, the cohorts' medians are below 1 (docs/notes/estimation.md)
    assert iae_val <= 1.05 * iae_nom
    assert flagged == 0
    for (K0, T0, d0), (K1, T1, d1) in zip(sched, sched[1:], strict=False):
        assert abs(K1 - K0) <= DESIGN_RATES[0] * TS + 1e-12
        assert abs(T1 - T0) <= DESIGN_RATES[1] * TS + 1e-12
        assert abs(d1 - d0) <= DESIGN_RATES[2] * TS + 1e-12
    (k_lo, k_hi), (t_lo, t_hi), (d_lo, d_hi) = DESIGN_BOX
    assert all(k_lo <= K <= k_hi and t_lo <= T <= t_hi and d_lo <= d <= d_hi for K, T, d in sched)
