"""pressor.hil_sim.native.dose_guard: the compiled hourly bookkeeping gives the Python guard's commands,
faults, reasons and hour volumes bit for bit, through cuts, tapers, stalls and the hourly exact
re-summing; guards it cannot mirror come back unchanged with the reason."""

from __future__ import annotations

import random

import numpy as np
import pytest

from pressor.hil_sim.native import dose_guard as ndg
from pressor.hil_sim.native.dose_guard import NativeDoseGuard, native_dose_guard
from pressor.plumbing import native_build as nb
from pressor.runtime.core.dose_guard import DoseGuard, DoseLimits

pytestmark = pytest.mark.skipif(nb.compiler() is None, reason="no C compiler")

LIMITS = DoseLimits(
    hard_max_ml_h=120.0, soft_max_ml_h=90.0, max_ml_per_hour=30.0, concentration_ug_ml=100.0
)


@pytest.fixture(autouse=True)
def native_on(monkeypatch):
    monkeypatch.delenv(nb.NATIVE_ENV, raising=False)


def _clock(n: int, period_s: float, seed: int) -> list[float]:
    """The run clock of ``n`` calls one period apart, float32 as the loop's, with stalls and
    jumps."""
    rng, t, out = random.Random(seed), 0.0, []
    for _ in range(n):
        out.append(float(np.float32(t)))
        r = rng.random()
        t += 0.0 if r < 0.002 else (rng.uniform(2.0, 300.0) * period_s if r < 0.004 else period_s)
    return out


@pytest.mark.parametrize(("period_s", "taper_s"), [(1.0, 600.0), (0.1, 60.0)])
def test_twin_cuts_like_the_python_guard_call_for_call_past_the_hourly_resum(period_s, taper_s):
    py = DoseGuard(LIMITS, period_s, taper_s)
    twin = native_dose_guard(DoseGuard(LIMITS, period_s, taper_s))
    assert isinstance(twin, NativeDoseGuard), ndg.last_reason
    rng = random.Random(int(period_s * 10))
    asked, hour_cut = 0.0, 0
    for k, now in enumerate(_clock(40000, period_s, 7)):  # past an exact re-sum (36,000 calls)
        if k % 400 == 0:
            asked = rng.choice((0.0, 120.0, 150.0, rng.uniform(0.0, 120.0)))
        short = rng.choice((float("nan"), 2.0, 8.0))
        a = py.limit(asked, now, short, chosen=k % 5000 < 50)
        b = twin.limit(asked, now, short, chosen=k % 5000 < 50)
        assert a == b and py.reason == twin.reason, k
        assert py.hour_volume_ml == twin.hour_volume_ml, k
        hour_cut += a[0] < min(asked, 90.0)
    assert hour_cut > 10000  # the hourly maximum and its taper cut much of the run


def test_twin_reset_forgets_the_hour_like_the_python_guard():
    py, twin = DoseGuard(LIMITS, 0.1), native_dose_guard(DoseGuard(LIMITS, 0.1))
    for guard in (py, twin):
        for k in range(20000):
            guard.limit(120.0, k * 0.1)
        guard.reset()
    for k in range(3000):
        assert py.limit(120.0, k * 0.1) == twin.limit(120.0, k * 0.1)
    assert twin.hour_volume_ml == py.hour_volume_ml > 0.0


def test_calls_closer_than_the_period_overflow_with_a_clear_error():
    twin = native_dose_guard(DoseGuard(LIMITS, 1.0))  # rings for an hour of calls 1 s apart
    with pytest.raises(RuntimeError, match="rings"):
        for k in range(40000):
            twin.limit(1.0, k * 0.1)


def test_guards_without_a_twin_come_back_unchanged_with_the_reason(monkeypatch):
    called = DoseGuard(LIMITS, 0.1)
    called.limit(10.0, 0.0)
    assert native_dose_guard(called) is called and "already" in ndg.last_reason
    assert native_dose_guard(None) is None

    class Custom(DoseGuard):
        pass

    custom = Custom(LIMITS, 0.1)
    assert native_dose_guard(custom) is custom and "DoseGuard" in ndg.last_reason
    monkeypatch.setenv(nb.NATIVE_ENV, "off")
    fresh = DoseGuard(LIMITS, 0.1)
    assert native_dose_guard(fresh) is fresh and ndg.last_reason == "PRESSOR_NATIVE=off"
