"""The sil/run summary on a terminal: metrics rounded to their resolution with units; the JSON
summary keeps full precision."""

from __future__ import annotations

import io
import json

from pressor.runtime.summary import print_summary, write_json

TIMING = {
    k: 1.0
    for k in (
        "exec_p50_us",
        "exec_p99_us",
        "exec_max_us",
        "lateness_p50_us",
        "lateness_p99_us",
        "lateness_max_us",
    )
} | {"overruns": 0, "skipped_periods": 0}


def summary() -> dict:
    return {
        "controller": "lpv",
        "scenario": "paper-disturbance",
        "patient_seed": 7,
        "ticks": 9000,
        "ended": "completed",
        "metrics": {
            "settling_time_s": 465.15000000000003,
            "overshoot_pct": 1.8163,
            "steady_state_dev_mmhg": 0.080491,
            "iae_mmhg_s": 857.61,
            "drug_total_ml": 6.4651,
            "max_rate_ml_h": 108,
            "longest_above_10_mmhg_s": 12.25,
            "divergence_pct_per_h": -2.2271,
            "rise_time_s": None,
            "reachable": True,
            "disturbances": [
                {
                    "kind": "hemorrhage",
                    "start_s": 1200.0,
                    "peak_deviation_mmhg": 3.14159,
                    "recovery_s": 85.04,
                    "iae_mmhg_s": 100.26,
                }
            ],
        },
        "supervisor": {"detections": {}, "ticks_in_state": {"AUTO": 9000}},
        "link_errors": {},
        "link_dropped": {"duplicates": 0, "incomplete_sched": 0},
    }


def test_terminal_summary_rounds_each_metric_to_its_unit():
    out = io.StringIO()
    print_summary(summary(), TIMING, out)
    lines = {line.split()[0]: line.split(maxsplit=1)[1] for line in out.getvalue().splitlines()}
    assert lines["settling_time_s"] == "465.2 s"
    assert lines["overshoot_pct"] == "1.82 %"
    assert lines["steady_state_dev_mmhg"] == "0.08 mmHg"
    assert lines["iae_mmhg_s"] == "857.6 mmHg·s"
    assert lines["drug_total_ml"] == "6.47 ml"
    assert lines["max_rate_ml_h"] == "108.0 ml/h"
    # a time above a level named in mmHg is a time, and divergence is a rate per hour
    assert lines["longest_above_10_mmhg_s"] == "12.2 s"
    assert lines["divergence_pct_per_h"] == "-2.23 %/h"
    assert lines["rise_time_s"] == "null" and lines["reachable"] == "True"
    assert "hemorrhage at 1200 s: peak deviation 3.14 mmHg, recovery 85.0 s, IAE 100.3" in (
        out.getvalue()
    )


def test_json_summary_keeps_full_precision(tmp_path):
    write_json(tmp_path / "s.json", summary())
    data = json.loads((tmp_path / "s.json").read_text())
    assert data["metrics"]["settling_time_s"] == 465.15000000000003


def test_terminal_summary_names_each_cause_of_dropped_link_frames_only_when_any():
    clean = io.StringIO()
    print_summary(summary(), TIMING, clean)
    assert "link: clean" in clean.getvalue() and "dropped" not in clean.getvalue()
    lossy = summary() | {"link_dropped": {"duplicates": 3, "old_ticks": 0, "incomplete_sched": 1}}
    out = io.StringIO()
    print_summary(lossy, TIMING, out)
    assert "link dropped: duplicates 3, incomplete_sched 1\n" in out.getvalue()
