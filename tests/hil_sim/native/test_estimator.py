"""pressor.hil_sim.native.estimator: the compiled estimator gives the Python estimator's reports, bit for bit,
tick by tick, through learning, gate rejections, restarts and health-check rejections."""

from __future__ import annotations

import dataclasses
import math
import random

import pytest

from pressor.hil_sim.native import estimator as ne
from pressor.hil_sim.native.estimator import (
    NativeDelayBankEstimator,
    native_estimator,
    native_schedule,
)
from pressor.plumbing import native_build as nb
from pressor.runtime.estimation.estimator import DelayBankEstimator
from pressor.runtime.estimation.gate import SampleGate
from pressor.runtime.estimation.sources import EstimatedSchedule, make_schedule

pytestmark = pytest.mark.skipif(nb.compiler() is None, reason="no C compiler")


@pytest.fixture(autouse=True)
def native_on(monkeypatch):
    monkeypatch.delenv(nb.NATIVE_ENV, raising=False)


def _ticks(seed: int, n: int):
    """(MAP mmHg, quality, delivered ml/h) of a first-order-plus-delay plant whose gain jumps
    tenfold and back (health-check rejections and restarts), under a stepping rate, with monitor
    noise, NaN samples, quality bits, spikes, a flatline and missing pump reports."""
    rng = random.Random(seed)
    delay = [0.0] * 300
    x = 0.0
    for k in range(n):
        rate = (20.0, 60.0, 5.0, 90.0)[(k // 1500) % 4] + 3.0 * math.sin(k / 97.0)
        gain = 5.0 if 9000 <= k < 12000 else 0.5
        delay.append(rate)
        x += 0.1 / 150.0 * (gain * delay.pop(0) - x)
        mp = 70.0 + x + rng.gauss(0.0, 0.3)
        quality = 0
        roll = rng.random()
        if roll < 0.003:
            mp = math.nan
        elif roll < 0.006:
            quality = 1
        elif roll < 0.008:
            mp += 40.0
        if 4000 <= k < 4200:
            mp = 81.25  # a frozen monitor
        delivered = rate if rng.random() > 0.01 else math.nan
        yield mp, quality, delivered


def _fields(est):
    values = (getattr(est, f.name) for f in dataclasses.fields(est))
    return tuple("nan" if isinstance(v, float) and v != v else v for v in values)


def test_reports_equal_the_python_estimators_tick_by_tick():
    py = DelayBankEstimator(0.1)
    twin = native_estimator(DelayBankEstimator(0.1))
    assert isinstance(twin, NativeDelayBankEstimator), ne.last_reason
    reasons = set()
    for k, (mp, q, dl) in enumerate(_ticks(5, 16000)):
        a, b = py.update(mp, q, dl), twin.update(mp, q, dl)
        assert _fields(a) == _fields(b), k
        reasons.add((a.reason, a.healthy))
    assert (py.updates, py.windows_closed) == (twin.updates, twin.windows_closed)
    assert {("learning", True), ("ok", True)} <= reasons
    assert any(not healthy for _, healthy in reasons)  # a health-check rejection was compared too


def test_estimated_source_gets_the_twin_other_sources_and_used_estimators_do_not(monkeypatch):
    source = native_schedule(make_schedule("estimated", 0.1))
    assert isinstance(source, EstimatedSchedule)
    assert isinstance(source.estimator, NativeDelayBankEstimator)
    for name in ("oracle", "nominal", "validated"):
        s = make_schedule(name, 0.1)
        assert native_schedule(s) is s and not isinstance(
            getattr(s, "estimator", None), NativeDelayBankEstimator
        )
    used = DelayBankEstimator(0.1)
    used.update(80.0, 0, 10.0)
    assert native_estimator(used) is used and "already" in ne.last_reason
    custom = DelayBankEstimator(0.1, gate=type("Gate", (SampleGate,), {})(0.1))
    assert native_estimator(custom) is custom and "customised" in ne.last_reason
    monkeypatch.setenv(nb.NATIVE_ENV, "off")
    fresh = DelayBankEstimator(0.1)
    assert native_estimator(fresh) is fresh and ne.last_reason == "PRESSOR_NATIVE=off"
