"""Seeded patient coefficients from the paper's Table 1 (uniform distributions).

``patient_seed`` → one patient: ``numpy.random.Generator(PCG64(SeedSequence([patient_seed, 0])))``
draws, in this order, a_k, k0, k1, b_T, a_τ1, a_τ2, b_τ1 from Table 1 and then the baseline MAP from
U(45, 60) mmHg (a hypotensive range; the paper gives none). ``(cohort_seed, n)`` → the n patients
with seeds ``cohort_seed·1_000_000 + j`` (j = 0 … n−1): readable, distinct, and each patient can be
re-run on its own from the seed printed in the trial's ``patients.json``.
"""

from __future__ import annotations

import numpy as np

from pressor.hil_sim.patients.patient import PatientParams

#: Table 1 of the paper: coefficient -> (low, high) of a uniform distribution (units in PatientParams)
TABLE_1: dict[str, tuple[float, float]] = {
    "a_k": (500.0, 600.0),
    "k0": (0.1, 1.0),
    "k1": (0.002, 0.007),
    "b_T": (1e-4, 3e-4),
    "a_tau1": (5.0, 15.0),
    "a_tau2": (5.0, 15.0),
    "b_tau1": (80.0, 120.0),
}
BASELINE_MMHG = (45.0, 60.0)
COHORT_STRIDE = 1_000_000
MAX_SEED = 2**63 - 1


def _check_seed(name: str, seed: int) -> int:
    if (
        isinstance(seed, bool)
        or not isinstance(seed, (int, np.integer))
        or not 0 <= seed <= MAX_SEED
    ):
        raise ValueError(f"{name}={seed!r} must be an integer in [0, {MAX_SEED}]")
    return int(seed)


def patient_rng(patient_seed: int, stream: int) -> np.random.Generator:
    """The explicit PCG64 stream ``stream`` of a patient (0 coefficients, 1 sensor noise, ...)."""
    seed = _check_seed("patient_seed", patient_seed)
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, stream])))


def draw_patient(patient_seed: int) -> PatientParams:
    """The patient of ``patient_seed`` (see module docstring for the draw order)."""
    rng = patient_rng(patient_seed, 0)
    values = {name: float(rng.uniform(lo, hi)) for name, (lo, hi) in TABLE_1.items()}
    values["baseline_mmhg"] = float(rng.uniform(*BASELINE_MMHG))
    return PatientParams(**values)


def cohort_seeds(cohort_seed: int, n: int) -> list[int]:
    """Patient seeds of the cohort ``(cohort_seed, n)``; n in [1, 1_000_000]."""
    base = _check_seed("cohort_seed", cohort_seed)
    if not 1 <= n <= COHORT_STRIDE:
        raise ValueError(f"n={n!r} patients outside [1, {COHORT_STRIDE}]")
    if base * COHORT_STRIDE + n - 1 > MAX_SEED:
        raise ValueError(f"cohort_seed={cohort_seed!r} too large (max {MAX_SEED // COHORT_STRIDE})")
    return [base * COHORT_STRIDE + j for j in range(n)]


def draw_cohort(cohort_seed: int, n: int) -> list[tuple[int, PatientParams]]:
    """``(patient_seed, params)`` for each of the n patients of the cohort."""
    return [(s, draw_patient(s)) for s in cohort_seeds(cohort_seed, n)]
