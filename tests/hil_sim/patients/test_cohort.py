"""Seeded Table 1 coefficient generator."""

from __future__ import annotations

import numpy as np
import pytest

from pressor.hil_sim.patients.cohort import (
    BASELINE_MMHG,
    TABLE_1,
    cohort_seeds,
    draw_cohort,
    draw_patient,
)


def test_same_seed_same_patient_and_seeds_differ():
    assert draw_patient(7) == draw_patient(7)
    assert draw_patient(7) != draw_patient(8)


def test_cohort_patient_is_the_patient_of_its_seed():
    cohort = draw_cohort(3, 5)
    assert [s for s, _ in cohort] == cohort_seeds(3, 5) == [3000000 + j for j in range(5)]
    assert cohort[2][1] == draw_patient(3000002)


def test_coefficients_stay_inside_table_1_and_fill_it_uniformly():
    patients = [p for _, p in draw_cohort(11, 2000)]
    for name, (lo, hi) in list(TABLE_1.items()) + [("baseline_mmhg", BASELINE_MMHG)]:
        x = np.array([getattr(p, name) for p in patients])
        assert x.min() >= lo and x.max() <= hi, name
        # Uniform: mean at the midpoint, std (hi-lo)/sqrt(12), each quarter holds ~1/4.
        assert np.mean(x) == pytest.approx((lo + hi) / 2, abs=0.03 * (hi - lo)), name
        assert np.std(x) == pytest.approx((hi - lo) / np.sqrt(12), rel=0.08), name
        quarters = np.histogram(x, bins=4, range=(lo, hi))[0]
        assert quarters.min() > 400, name


def test_bad_seeds_and_sizes_are_rejected():
    with pytest.raises(ValueError, match="patient_seed"):
        draw_patient(-1)
    with pytest.raises(ValueError, match="n=0"):
        cohort_seeds(1, 0)
