"""The trial's HTML report (pressor.hil_sim.trials.report): self-contained, its data written beside it,
reproducible."""

from __future__ import annotations

import base64
import re

import numpy as np

from pressor.hil_sim.trials.paired import compare_controllers
from pressor.hil_sim.trials.report import write_report


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
    assert "lpv vs pi" in page and "iae_mmhg_s" in page
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
