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


def _lines(text: str) -> dict[str, str]:
    """``name in words -> value`` of the metric lines (two spaces or more between them)."""
    pairs = (line.strip().split("  ", 1) for line in text.splitlines() if line.startswith("  "))
    return {p[0].strip(): p[1].strip() for p in pairs if len(p) == 2}


def test_terminal_summary_rounds_each_metric_to_its_unit():
    out = io.StringIO()
    print_summary(summary(), TIMING, out)
    lines = _lines(out.getvalue())
    assert lines["settling time"] == "465.2 s"
    # the whole run's overshoot says it counts the disturbances, not only the controller's step
    assert lines["overshoot, whole run (disturbances too)"] == "1.8 %"
    assert lines["steady-state deviation (last 10 %)"] == "0.1 mmHg"
    assert lines["IAE (integral of |MAP - target|)"] == "858 mmHg·s"
    assert lines["drug given"] == "6.47 ml"
    assert lines["highest infusion rate"] == "108.0 ml/h"
    # a time above a level named in mmHg is a time, and divergence is a rate per hour
    assert lines["longest time more than 10 mmHg above the target"] == "12.2 s"
    assert lines["divergence (trend of the error; < 0: shrinking)"] == "-2.2 %/h"
    assert lines["target reachable at the pump's maximum"] == "yes"
    assert "hemorrhage at 1200 s: peak deviation 3.1 mmHg, recovery 85.0 s, IAE 100" in (
        out.getvalue()
    )


def test_terminal_summary_names_figures_in_words_never_by_their_json_names():
    from pressor.contracts.metrics import RUN_METRICS

    s = summary()
    s["metrics"] = {k: 1.5 for k in RUN_METRICS} | {"reachable": True, "stable": True}
    out = io.StringIO()
    print_summary(s, TIMING, out)
    for key in RUN_METRICS:
        assert key not in out.getvalue(), key
    assert "  MDPE (median performance error)" in out.getvalue()
    assert "  time within ±5 mmHg of the target" in out.getvalue()


def test_a_figure_that_rounds_to_zero_prints_without_a_minus_sign():
    s = summary()
    s["metrics"] |= {"mdpe_pct": -0.0004, "divergence_pct_per_h": -0.01}
    out = io.StringIO()
    print_summary(s, TIMING, out)
    lines = _lines(out.getvalue())
    assert lines["MDPE (median performance error)"] == "0.0 %"
    assert lines["divergence (trend of the error; < 0: shrinking)"] == "0.0 %/h"
    assert "-0.0" not in out.getvalue()


def test_a_null_figure_says_why_it_is_absent():
    out = io.StringIO()
    print_summary(summary(), TIMING, out)  # rise_time_s is null with a step in the run
    lines = _lines(out.getvalue())
    assert lines["rise time (10 to 90 % of the step)"] == (
        "not measured: 90 % of the step was never reached"
    )
    assert "null" not in out.getvalue() and "None" not in out.getvalue()


def test_a_run_without_a_target_step_says_so_for_each_step_figure():
    s = summary()
    s["metrics"] |= {"overshoot_pct": None, "settling_time_s": None, "step_overshoot_pct": None}
    out = io.StringIO()
    print_summary(s, TIMING, out)
    lines = _lines(out.getvalue())
    for name in (
        "overshoot, whole run (disturbances too)",
        "settling time",
        "rise time (10 to 90 % of the step)",
    ):
        assert lines[name] == "not measured: no target step in this run", name


def test_faults_print_in_words_with_their_count_and_meaning_not_as_a_dict():
    s = summary()
    s["supervisor"]["detections"] = {"SCHED_RATE": 1, "PUMP_ALARM": 3}
    out = io.StringIO()
    print_summary(s, TIMING, out)
    text = out.getvalue()
    assert "{" not in text and "'SCHED_RATE'" not in text
    (sched,) = [line for line in text.splitlines() if "SCHED_RATE" in line]
    assert "raised once" in sched and "faster than the design's certified rates" in sched
    # an advisory the docs call expected says both
    assert "advisory" in sched and "expected" in sched and "DESIGN-CHOICES" in sched
    (pump,) = [line for line in text.splitlines() if "PUMP_ALARM" in line]
    assert "raised 3 times" in pump and "occlusion" in pump and "held the last rate" in pump
    assert "advisory" not in pump


def test_the_supervisor_states_are_named_in_words_with_their_share_of_the_run():
    s = summary()
    s["supervisor"]["ticks_in_state"] = {"AUTO": 8100, "HOLD": 900, "FAILSAFE": 0}
    out = io.StringIO()
    print_summary(s, TIMING, out)
    line = next(x for x in out.getvalue().splitlines() if x.startswith("supervisor:"))
    assert line == (
        "supervisor: automatic control (AUTO) 90.0 % of the run,"
        " rate held on a fault (HOLD) 10.0 % of the run"
    )


def test_the_summary_shows_start_map_target_drug_and_the_infusion_in_ml_h_and_ug_kg_min():
    from types import SimpleNamespace

    import numpy as np

    from pressor.contracts.drug import DrugBinding, dose_ug_kg_min
    from pressor.runtime.summary import run_context

    s = summary() | {"rate_hz": 10.0}
    s["metrics"] |= {"drug_total_ml": 15.0, "max_rate_ml_h": 60.0}  # 900 s: mean 60 ml/h
    trajectory = {
        "map_mmhg": np.array([np.nan, 58.04, 60.0]),
        "target_mmhg": np.array([78.0, 78.0, 78.0]),
    }
    drug = DrugBinding("norepinephrine", 16.0)
    out = io.StringIO()
    context = run_context(s, SimpleNamespace(trajectory=trajectory), drug)
    print_summary(s, TIMING, out, context=context)
    text = out.getvalue()
    assert "patient: start MAP 58.0 mmHg, target 78.0 mmHg (+20.0 mmHg)" in text
    assert (
        "drug: norepinephrine 16 µg/ml; patient weight not known: per-kg doses at a 70 kg" in text
    )
    per_kg = dose_ug_kg_min(60.0, 16.0, 70.0)  # 0.2286 µg/kg/min
    assert f"mean 60.0 ml/h = {per_kg:.3f} µg/kg/min, peak 60.0 ml/h" in text
    assert "total 15.00 ml = 0.24 mg" in text
    # a known weight is used and said
    out = io.StringIO()
    print_summary(s, TIMING, out, context=run_context(s, None, drug, weight_kg=80.0))
    assert "patient weight 80 kg" in out.getvalue()
    assert dose_ug_kg_min(60.0, 16.0, 80.0) == 0.2
    assert "mean 60.0 ml/h = 0.2 µg/kg/min" in out.getvalue()


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


def test_the_replay_hint_is_the_native_viewer_with_a_display_and_the_web_viewer_without():
    from pressor.runtime.summary import replay_command

    assert replay_command("a.rrd", {"DISPLAY": ":0"}) == "rerun a.rrd"
    assert replay_command("a.rrd", {"WAYLAND_DISPLAY": "wayland-0"}) == "rerun a.rrd"
    headless = replay_command("a.rrd", {})
    assert headless.startswith("rerun --web-viewer --bind 127.0.0.1 a.rrd")
