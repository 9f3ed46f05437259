"""The known-lag ceiling of the cautious start (research/evidence_lag.py)."""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest

from pressor.runtime.estimation.cautious import CautiousSchedule
from research.evidence_lag import KnownLagSchedule, _effect_site, _lag
from tests.support.cautious_envelope import DOSE, ENVELOPE, TS, k_hat_on_a_first_order_patient

K, T, TAU, RATE = 0.5, 120.0, 15.0, 20.0  # the patient (mmHg/(ml/h), s, s) and its rate (ml/h)


def _k_hat(source: CautiousSchedule, device: tuple[float, float], until_s: float) -> np.ndarray:
    """K̂ at each tick of the first-order patient above, infused at RATE from t = 0."""
    return k_hat_on_a_first_order_patient(source, K, T, TAU, RATE, until_s, device)


def test_the_patients_own_lag_brings_k_hat_near_its_gain_where_the_boxs_slowest_is_far_above():
    at = int(round((TAU + 2 * T) / TS)) - 1
    known = _k_hat(KnownLagSchedule(ENVELOPE, TS, DOSE, None), (T, TAU), TAU + 2 * T)
    shipped = _k_hat(CautiousSchedule(ENVELOPE, TS, DOSE), (T, TAU), TAU + 2 * T)
    # hand values at t = tau + 2T, rise K·RATE·(1 - e^-2) = 8.65 mmHg: K̂ settles where the
    # response is K̂·s - m, m = 1 + 0.1·K̂·s; with s the patient's own (17.3) that is 0.62, with
    # the box's slowest (T 400 s, tau 45 s: s = 8.17) it is 1.31
    assert known[at] == pytest.approx((K * 17.29 + 1.0) / (0.9 * 17.29), rel=0.02)
    assert shipped[at] == pytest.approx((K * 17.29 + 1.0) / (0.9 * 8.17), rel=0.02)
    assert known.min() >= K  # never below the patient: the bound holds for its own lag too


def test_without_device_values_the_evidence_is_the_boxs_as_shipped():
    nan = (math.nan, math.nan)
    known = _k_hat(KnownLagSchedule(ENVELOPE, TS, DOSE, None), nan, 300.0)
    shipped = _k_hat(CautiousSchedule(ENVELOPE, TS, DOSE), nan, 300.0)
    assert np.array_equal(known, shipped)


def test_a_given_lag_equal_to_the_boxs_longest_is_the_shipped_evidence_whatever_the_device_sends():
    given = _k_hat(KnownLagSchedule(ENVELOPE, TS, DOSE, None, lag_T_s=400.0), (T, TAU), 300.0)
    shipped = _k_hat(CautiousSchedule(ENVELOPE, TS, DOSE), (T, TAU), 300.0)
    assert np.array_equal(given, shipped)
    faster = _k_hat(KnownLagSchedule(ENVELOPE, TS, DOSE, None, lag_T_s=200.0), (T, TAU), 300.0)
    assert faster[-1] < shipped[-1]  # a faster slowest patient lets K̂ fall further


def test_lag_and_effect_site_arguments_name_what_is_allowed():
    assert _lag("device") is None
    assert _lag("550") == 550.0
    with pytest.raises(argparse.ArgumentTypeError, match="'device' or a lag in s"):
        _lag("0")
    assert _effect_site("keep") == "drug"
    assert _effect_site("none") is None
    assert _effect_site("60") == 60.0
    with pytest.raises(argparse.ArgumentTypeError, match="'none' or 'keep' or a lag in s"):
        _effect_site("-1")
