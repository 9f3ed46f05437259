"""Paired per-patient comparison of two controllers (pressor.hil_sim.trials.paired) on hand-made records."""

from __future__ import annotations

import pytest

from pressor.hil_sim.trials.paired import compare_controllers, compare_pair


def _rec(seed: int, iae: float | None, band: float, reachable: bool = True, peak: float = -4.0):
    return {
        "patient_seed": seed,
        "reachable": reachable,
        "iae_mmhg_s": iae,
        "time_in_band_pct": band,
        "disturbances": [
            {
                "kind": "hemorrhage",
                "peak_deviation_mmhg": peak,
                "recovery_s": 10.0,
                "iae_mmhg_s": 1.0,
            }
        ],
    }


def test_six_pairs_all_better_give_full_win_rate_and_the_exact_signed_rank_p():
    a = [_rec(s, float(s + 1), 90.0) for s in range(6)]
    b = [_rec(s, float(s + 2), 80.0) for s in range(6)]
    iae = compare_pair(a, b)["iae_mmhg_s"]
    assert iae["n"] == 6 and iae["win_rate_pct"] == 100.0
    # ratios 1/2, 2/3, 3/4, 4/5, 5/6, 6/7: median of the middle two
    assert iae["median_ratio"] == pytest.approx((3 / 4 + 4 / 5) / 2)
    assert iae["median_difference"] == -1.0
    # exact two-sided signed-rank p with all 6 differences of one sign: 2 / 2**6
    assert iae["wilcoxon_p"] == pytest.approx(2 / 64)


def test_time_in_band_counts_higher_as_better():
    a = [_rec(s, 1.0, 90.0) for s in range(6)]
    b = [_rec(s, 1.0, 95.0) for s in range(6)]
    band = compare_pair(a, b)["time_in_band_pct"]
    assert band["win_rate_pct"] == 0.0 and band["median_difference"] == -5.0


def test_unreachable_and_null_pairs_are_left_out_and_ties_get_no_p_value():
    a = [_rec(0, 1.0, 90.0), _rec(1, None, 90.0), _rec(2, 5.0, 90.0, reachable=False)]
    b = [_rec(0, 1.0, 90.0), _rec(1, 2.0, 90.0), _rec(2, 1.0, 90.0)]
    iae = compare_pair(a, b)["iae_mmhg_s"]
    assert iae["n"] == 1 and iae["win_rate_pct"] == 0.0 and iae["wilcoxon_p"] is None


def test_disturbance_peaks_compare_by_magnitude_per_event_label():
    a = [_rec(s, 1.0, 90.0, peak=-3.0) for s in range(2)]
    b = [_rec(s, 1.0, 90.0, peak=-6.0) for s in range(2)]
    peak = compare_pair(a, b)["hemorrhage.peak_deviation_mmhg"]
    assert peak["win_rate_pct"] == 100.0 and peak["median_ratio"] == 0.5


def test_different_cohorts_are_refused():
    with pytest.raises(ValueError, match="same patients"):
        compare_pair([_rec(0, 1.0, 90.0)], [_rec(1, 1.0, 90.0)])


def test_the_first_controller_is_compared_with_each_other_one():
    recs = [_rec(0, 1.0, 90.0)]
    out = compare_controllers({"lpv": recs, "pi": recs, "smith": recs})
    assert list(out) == ["lpv vs pi", "lpv vs smith"]


def test_equal_values_are_ties_not_losses():
    # 100 % against 100 % in band (both perfect) and 0 against 0: ties, never losses
    a = [_rec(0, 0.0, 100.0), _rec(1, 1.0, 100.0), _rec(2, 3.0, 90.0), _rec(3, 2.0, 80.0)]
    b = [_rec(0, 0.0, 100.0), _rec(1, 2.0, 100.0), _rec(2, 2.0, 95.0), _rec(3, 2.0, 70.0)]
    cmp = compare_pair(a, b)
    band, iae = cmp["time_in_band_pct"], cmp["iae_mmhg_s"]
    assert (band["wins"], band["ties"], band["losses"]) == (1, 2, 1)
    assert (iae["wins"], iae["ties"], iae["losses"]) == (1, 2, 1)
    assert band["wins"] + band["ties"] + band["losses"] == band["n"]


def test_tables_show_wins_ties_losses_and_metrics_in_words():
    from pressor.hil_sim.trials.paired import format_comparison, stat_cells

    a = [_rec(0, 0.0, 100.0), _rec(1, 1.0, 100.0)]
    b = [_rec(0, 0.0, 100.0), _rec(1, 2.0, 100.0)]
    out = compare_controllers({"lpv": a, "pi": b})
    assert stat_cells(out["lpv vs pi"]["time_in_band_pct"])[1] == "0 / 2 / 0"
    text = format_comparison(out)
    assert "wins / ties / losses" in text
    row = next(x for x in text.splitlines() if "time within ±5 mmHg of the target (%)" in x)
    assert "0 / 2 / 0" in row
    row = next(x for x in text.splitlines() if "hemorrhage: peak |deviation| (mmHg)" in x)
    assert "0 / 2 / 0" in row
    assert "time_in_band_pct" not in text and "iae_mmhg_s" not in text
