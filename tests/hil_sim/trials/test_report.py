"""The trial's HTML report (pressor.hil_sim.trials.report): self-contained, its data written beside it,
reproducible."""

from __future__ import annotations

import base64
import re

import numpy as np

from pressor.hil_sim.trials.paired import compare_controllers
from pressor.hil_sim.trials.report import (
    distribution_figure,
    envelope_figure,
    write_report,
)


def _cohort(offset: float) -> tuple[list[dict], dict[str, np.ndarray]]:
    t = np.arange(0.0, 600.0, 10.0)
    seeds = [11, 12, 13]
    records = [
        {
            "patient_seed": s,
            "reachable": True,
            "iae_mmhg_s": 100.0 + offset + i,
            "time_in_band_pct": 90.0 - offset,
            "step_overshoot_pct": 0.5,
            "drug_total_ml": 5.0 + i,
            "disturbances": [],
        }
        for i, s in enumerate(seeds)
    ]
    rise = 1.0 - np.exp(-t / (60.0 + offset))
    traj = {
        "t_s": t,
        "map_true_mmhg": np.array([60.0 + 20.0 * rise + i for i in range(3)]),
        "target_mmhg": np.full((3, t.size), 80.0),
        "rate_ml_h": np.array([40.0 * rise + i for i in range(3)]),
        "patient_seed": np.array(seeds),
    }
    return records, traj


def _write(out):
    (ra, ta), (rb, tb) = _cohort(0.0), _cohort(30.0)
    records = {"lpv": ra, "pi": rb}
    return write_report(
        out,
        "paper-tracking, seed 1, 3 patients",
        records,
        {"lpv": ta, "pi": tb},
        compare_controllers(records),
    )


def test_report_embeds_every_figure_and_the_paired_table(tmp_path):
    page = _write(tmp_path / "a").read_text()
    images = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert len(images) == 3  # envelopes, distributions, paired scatter
    assert all(base64.b64decode(png)[:8] == b"\x89PNG\r\n\x1a\n" for png in images)
    assert "lpv vs pi" in page and "IAE (integral of |MAP - target|) (mmHg·s)" in page
    assert "http" not in page  # self-contained: nothing fetched when it opens


def test_trajectories_are_written_beside_the_report_per_controller(tmp_path):
    _write(tmp_path)
    with np.load(tmp_path / "trajectories_pi.npz") as z:
        assert z["map_true_mmhg"].shape == (3, 60)
        assert list(z["patient_seed"]) == [11, 12, 13]
        assert z["rate_ml_h"][0, -1] > z["rate_ml_h"][0, 0]


def test_same_inputs_give_the_same_report_bytes(tmp_path):
    a = _write(tmp_path / "a").read_bytes()
    b = _write(tmp_path / "b").read_bytes()
    assert a == b


def _with_unreachable() -> dict[str, list[dict]]:
    """Five patients per controller, the last two unreachable (12.3 and 17.7 mmHg of 30 asked)."""
    out = {}
    for name, offset in (("lpv", 0.0), ("pi", 30.0)):
        records, _ = _cohort(offset)
        records += [
            {
                "patient_seed": seed,
                "reachable": False,
                "required_delta_mmhg": 30.0,
                "max_delta_mmhg": can,
                "iae_mmhg_s": 9000.0,
                "time_in_band_pct": 20.0,
                "step_overshoot_pct": 0.0,
                "drug_total_ml": 120.0,
                "disturbances": [],
            }
            for seed, can in ((14, 12.31), (15, 17.72))
        ]
        out[name] = records
    return out


def test_every_patient_is_counted_and_each_unreachable_one_explained(tmp_path):
    records = _with_unreachable()
    trajectories = {}
    for name, offset in (("lpv", 0.0), ("pi", 30.0)):
        _, tr = _cohort(offset)
        trajectories[name] = {
            k: (np.concatenate([v, v[:2]]) if k != "t_s" else v) for k, v in tr.items()
        }
        trajectories[name]["patient_seed"] = np.array([11, 12, 13, 14, 15])
    page = write_report(
        tmp_path, "t", records, trajectories, compare_controllers(records)
    ).read_text()
    for name in ("lpv", "pi"):
        assert f"{name}: 5 patients: 3 reachable" in page and "2 unreachable" in page
    assert "unreachable: even at the pump&#x27;s maximum rate" in page  # the word explained
    (listed,) = re.findall(r"<ul class='unreachable'>(.*?)</ul>", page, re.S)  # once: the same
    assert (
        "patient 14: the pump&#x27;s maximum cannot raise this patient&#x27;s MAP by the step:"
        in (listed)
    )
    assert "12.3 mmHg reachable of 30.0 asked" in listed
    assert "17.7 mmHg reachable of 30.0 asked" in listed


def test_the_paired_table_counts_ties_as_ties(tmp_path):
    records = {"lpv": _cohort(0.0)[0], "pi": _cohort(0.0)[0]}  # identical: every pair a tie
    page = write_report(
        tmp_path,
        "t",
        records,
        {"lpv": _cohort(0.0)[1], "pi": _cohort(0.0)[1]},
        compare_controllers(records),
    ).read_text()
    assert "<th>wins / ties / losses</th>" in page
    row = re.search(r"<tr><td>lpv vs pi</td><td>time within[^<]*</td>(.*?)</tr>", page).group(1)
    assert "<td>0 / 3 / 0</td>" in row


def test_time_in_band_axis_spans_0_to_100_whatever_the_spread():
    records, _ = _cohort(0.0)
    for r, band in zip(records, (99.975, 99.99, 100.0), strict=True):
        r["time_in_band_pct"] = band
    fig = distribution_figure({"lpv": records})
    lo, hi = fig.axes[1].get_ylim()
    assert lo <= 0.0 and hi >= 100.0 and hi - lo <= 110.0
    # an IAE spread of 2 mmHg·s is drawn on an axis of at least 500 mmHg·s
    lo, hi = fig.axes[0].get_ylim()
    assert hi - lo >= 500.0


def test_each_controller_median_has_its_own_style_and_is_drawn_over_every_band():
    (ra, ta), (rb, tb) = _cohort(0.0), _cohort(30.0)
    fig = envelope_figure({"lpv": ta, "pi": tb}, {"lpv": ra, "pi": rb})
    for ax in fig.axes:
        medians = [line for line in ax.get_lines() if "median" in str(line.get_label())]
        assert len(medians) == 2
        assert medians[0].get_linestyle() != medians[1].get_linestyle()
        bands = ax.collections
        assert len(bands) == 2 and all(b.get_alpha() < 0.5 for b in bands)
        assert min(m.get_zorder() for m in medians) > max(b.get_zorder() for b in bands)
