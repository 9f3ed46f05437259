"""The least-squares lag bank (research/lag_bank.py)."""

from __future__ import annotations

from pressor.runtime.estimation.cautious import CautiousSchedule
from research.lag_bank import BankSettings, LagBankSchedule
from tests.support.cautious_envelope import DOSE, ENVELOPE, TS, k_hat_on_a_first_order_patient


def _run(source: CautiousSchedule, T: float, tau: float, until_s: float) -> float:
    """K̂ after ``until_s`` s of a first-order patient (K 0.5, closed form) at 20 ml/h."""
    return float(k_hat_on_a_first_order_patient(source, 0.5, T, tau, 20.0, until_s)[-1])


def test_a_fast_patient_drops_the_slow_lags_and_k_hat_falls_below_the_shipped_sources():
    bank = LagBankSchedule(ENVELOPE, TS, DOSE, BankSettings(lags=4, delays=2))
    k_bank = _run(bank, 100.0, 10.0, 400.0)  # the box's fastest patient
    k_shipped = _run(CautiousSchedule(ENVELOPE, TS, DOSE), 100.0, 10.0, 400.0)
    T, tau = bank.hypotheses[bank.chosen]
    assert T < 400.0 and bank.drops  # the box's slowest lag no longer read
    assert 0.5 <= k_bank < k_shipped  # never below the patient, below the box's bound


def test_the_slowest_patient_keeps_the_slowest_lag_and_the_shipped_evidence():
    bank = LagBankSchedule(ENVELOPE, TS, DOSE, BankSettings(lags=4, delays=2))
    k_bank = _run(bank, 400.0, 45.0, 400.0)
    k_shipped = _run(CautiousSchedule(ENVELOPE, TS, DOSE), 400.0, 45.0, 400.0)
    assert bank.hypotheses[bank.chosen] == (400.0, 45.0) and not bank.drops
    assert k_bank == k_shipped


def test_before_the_rise_passes_its_threshold_no_lag_is_dropped():
    bank = LagBankSchedule(ENVELOPE, TS, DOSE, BankSettings(lags=4, delays=2, rise_mmhg=50.0))
    _run(bank, 100.0, 10.0, 400.0)  # the rise stays below 10 mmHg
    assert all(bank.alive) and not bank.drops
