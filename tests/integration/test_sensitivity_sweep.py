"""The responsiveness sweep (benchmarks/sensitivity_sweep.py): its per-row figures against values
worked out by hand, the syringe a clinician switches to, who counts as a non-responder, and the
sweep on a tiny cohort (every column, every group, the same bytes again, reuse of what it wrote)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.sensitivity_sweep import main
from benchmarks.sweep_figures import (
    HEADER,
    HEADLINE_HEADER,
    format_headline_row,
    format_row,
    row_figures,
)
from benchmarks.sweep_plan import reach_plan, syringes
from benchmarks.sweep_profile import main as profile_main
from pressor.hil_sim.patients.cohort import cohort_seeds
from pressor.hil_sim.scenarios.scenario import load_scenario
from pressor.runtime.inputs.drug_library import DrugEntry, load_library
from tests.support.patient_plugin import FirstOrderPatient


def _record(**overrides: Any) -> dict[str, Any]:
    base = {
        "stable": True,
        "step_overshoot_pct": 0.0,
        "step_overshoot_mmhg": 0.0,
        "longest_above_10_mmhg_s": 0.0,
        "time_to_band_s": 100.0,
        "time_below_pct": 0.0,
        "time_in_band_pct": 100.0,
        "mdpe_pct": 0.0,
        "mdape_pct": 1.0,
        "wobble_pct": 1.0,
        "divergence_pct_per_h": -1.0,
        "iae_mmhg_s": 1000.0,
    }
    return base | overrides


def test_row_figures_rank_harm_as_counted_by_hand():
    records = [
        _record(step_overshoot_pct=0.0, step_overshoot_mmhg=0.0, longest_above_10_mmhg_s=0.0,
                time_to_band_s=300.0, time_below_pct=2.0, time_in_band_pct=98.0),
        _record(step_overshoot_pct=10.0, step_overshoot_mmhg=2.0, longest_above_10_mmhg_s=12.0,
                time_to_band_s=200.0, time_below_pct=0.0, time_in_band_pct=100.0, stable=False,
                held_s=0.1),
        _record(step_overshoot_pct=50.0, step_overshoot_mmhg=10.0, longest_above_10_mmhg_s=31.0,
                time_to_band_s=100.0, time_below_pct=4.0, time_in_band_pct=90.0,
                dose={"hour_limited_s": 12.5}),
        _record(step_overshoot_pct=200.0, step_overshoot_mmhg=40.0, longest_above_10_mmhg_s=400.0,
                time_to_band_s=None, time_below_pct=None, time_in_band_pct=None),
    ]  # fmt: skip
    fig = row_figures(records)
    assert (fig["patients"], fig["unstable"], fig["hour_limited"], fig["held"]) == (4, 1, 1, 1)
    # overshoot 0, 10, 50, 200 %: median (10 + 50)/2; p90 at position 2.7 = 50 + 0.7·150
    assert fig["step_overshoot_pct"] == {"median": 30.0, "p90": pytest.approx(155.0), "worst": 200}
    assert fig["step_overshoot_mmhg"] == {"median": 6.0, "p90": pytest.approx(31.0), "worst": 40}
    # stretches 0, 12, 31, 400 s: two of four last longer than 30 s; p90 = 31 + 0.7·369
    assert fig["longest_above_10_mmhg_s"] == {
        "median": 21.5,
        "p90": pytest.approx(289.3),
        "worst": 400,
    }
    assert (fig["above_10_mmhg_over_30_s"], fig["above_10_mmhg_over_30_s_pct"]) == (2, 50.0)
    # to the band: 100, 200, 300, never: median (200 + 300)/2; p90 (position 2.7) reaches never
    assert fig["time_to_band_s"] == {"p50": 250.0, "p90": None, "n_never": 1}
    # below: the never-arrived patient has no "after entry" and is left out: 0, 2, 4 %
    assert fig["time_below_pct"] == {"median": 2.0, "p90": pytest.approx(3.6), "worst": 4.0}
    # in band: the never-arrived patient counts 0 %: 0, 90, 98, 100 -> median 94, p10 at 0.3
    assert fig["time_in_band_pct"] == {"median": 94.0, "p10": pytest.approx(27.0), "worst": 0.0}
    assert (fig["mdape_pct"], fig["divergence_pct_per_h"], fig["iae_mmhg_s"]) == (1.0, -1.0, 1000)
    row = format_row(2.0, "pi", "100", fig)
    assert row == (
        "| 2× | pi | 100 | 4 | 1 | 30.0 / 155.0 / 200.0 | 6.0 / 31.0 / 40.0 | 22 / 289 / 400"
        " | 2 (50.0 %) | 250 / never (1 never) | 2.0 / 3.6 / 4.0 | 94.0 / 27.0 / 0.0 | 0.00"
        " | 1.00 | 1.00 | -1.00 | 1000 | 1 | 1 |"
    )
    assert row.count("|") == HEADER.splitlines()[0].count("|")
    headline = format_headline_row(2.0, "pi", fig)
    assert headline == (
        "| 2× | pi | 4 | 1 | 155.0 / 200.0 | 50.0 | 250 / never (1 never) | 94.0 | 1000 |"
    )
    assert headline.count("|") == HEADLINE_HEADER.splitlines()[0].count("|")


#: the library's norepinephrine with the soft and hourly limits at the hard one (1 µg/kg/min):
#: the rate a syringe holds for the hour is then the pump's or the hard limit's
NE_HARD_ONLY = DrugEntry("norepinephrine", (16.0, 32.0, 64.0), "ug/kg/min", 1.0, 1.0, 60.0)


def test_a_syringe_holds_the_smallest_of_the_pump_and_the_dose_limits_for_the_hour():
    library = load_library()
    standard, stronger = syringes(library["phenylephrine"], 120.0)
    assert stronger is None  # one syringe in the library
    # hard 200 µg/min = 120 ml/h, but the soft 100 µg/min (nobody confirms above it) and the
    # hourly 6000 µg spread over the hour both hold 60 ml/h
    assert (standard.concentration_ug_ml, standard.max_rate_ml_h) == (100.0, 60.0)
    standard, stronger = syringes(library["norepinephrine"], 120.0)
    # 70 kg: soft 0.5 µg/kg/min = 35 µg/min, hourly 30 µg/kg = 35 µg/min over the hour; 16 µg/ml
    # at 120 ml/h gives 32 µg/min, 32 µg/ml reaches 35 µg/min at 35·60/32 = 65.625 ml/h
    assert (standard.concentration_ug_ml, standard.max_rate_ml_h) == (16.0, 120.0)
    assert stronger is not None and stronger.concentration_ug_ml == 32.0
    assert stronger.max_rate_ml_h == pytest.approx(65.625)


def test_the_stronger_syringe_is_the_weakest_that_reaches_the_limit():
    standard, stronger = syringes(NE_HARD_ONLY, 120.0)
    # 70 kg, hard 1 µg/kg/min = 70 µg/min: 16 µg/ml at 120 ml/h gives 32 µg/min, 32 µg/ml 64,
    # only 64 µg/ml reaches 70 µg/min (at 70·60/64 = 65.625 ml/h)
    assert (standard.concentration_ug_ml, standard.max_rate_ml_h) == (16.0, 120.0)
    assert stronger is not None and stronger.concentration_ug_ml == 64.0
    assert stronger.max_rate_ml_h == pytest.approx(65.625)
    # with a hard limit of 0.9 µg/kg/min (63 µg/min) 32 µg/ml already reaches it (at 118.1 ml/h)
    entry = DrugEntry("norepinephrine", (16.0, 32.0, 64.0), "ug/kg/min", 0.9, 0.9, 54.0)
    assert syringes(entry, 120.0)[1].concentration_ug_ml == 32.0  # type: ignore[union-attr]


def _held_shortfall_mmhg(patient: FirstOrderPatient, rate_ml_h: float) -> float:
    """By hand, for the 5 min short scenario: a first-order patient infused at ``rate_ml_h`` from
    t = 0 rises K·r·(1 − e^(−(t − n)/T)) after its whole-second delay n (the plugin's delay at the
    capacity run's 1 s step); the scenario asks 20 mmHg, then 10 more over 120-180 s. The
    shortfall: the largest ask minus rise from the first second the rise is within 5 mmHg of the
    ask (or from the end, if never)."""
    t = np.arange(0.0, 301.0)
    n = max(1, round(patient.tau_s))
    rise = np.where(t >= n, patient.K * rate_ml_h * (1.0 - np.exp(-(t - n) / patient.T_s)), 0.0)
    ask = 20.0 + 10.0 * np.clip((t - 120.0) / 60.0, 0.0, 1.0)
    gap = ask - rise
    start = int(np.argmax(gap <= 5.0)) if (gap <= 5.0).any() else t.size - 1
    return float(gap[start:].max())


def test_patients_are_sorted_by_the_syringe_that_holds_them_at_the_target(short_scenario: Path):
    scenario = load_scenario(short_scenario)
    standard, stronger = syringes(NE_HARD_ONLY, 120.0)
    model = "tests.support.patient_plugin:FirstOrderPatient"
    seeds = cohort_seeds(3, 12)
    plan = reach_plan(scenario, model, 0.4, seeds, standard, stronger)
    # at 0.4x the patient answers 0.4 of the rate; the 64 ug/ml syringe's 65.625 ml/h are 262.5 ml/h
    # of 16 ug/ml
    expected: dict[str, list[Any]] = {"standard": [], "switched": [], "non_responders": []}
    shortfalls = []
    for seed in seeds:
        patient = FirstOrderPatient.from_seed(seed, 1.0)
        patient.K *= 0.4
        if _held_shortfall_mmhg(patient, 120.0) <= 5.0:
            expected["standard"].append(seed)
        elif _held_shortfall_mmhg(patient, 262.5) <= 5.0:
            expected["switched"].append(seed)
        else:
            expected["non_responders"].append(seed)
            shortfalls.append(_held_shortfall_mmhg(patient, 262.5))
    assert all(expected.values()), "the cohort must hold each group for the test to mean anything"
    assert {k: plan[k] for k in expected} == expected
    assert plan["shortfall_mmhg"] == pytest.approx(shortfalls, abs=1e-9)
    # a steady-state verdict would have put some of them a group higher: the 5 min do not settle
    steady = [s for s in seeds if 0.4 * FirstOrderPatient.from_seed(s, 1.0).K >= 25.0 / 120.0]
    assert set(steady) > set(expected["standard"])
    # sorted on two worker processes, the plan is the same
    assert reach_plan(scenario, model, 0.4, seeds, standard, stronger, jobs=2) == plan


def _sweep(out: Path, scenario: Path, jobs: int, capsys) -> tuple[str, str]:
    argv = ["--patients", "6", "--seed", "1", "--levels", "0.2", "--controllers", "pi"]
    argv += ["--models", "paper,norepinephrine", "--scenario", str(scenario), "--out", str(out)]
    assert main([*argv, "--jobs", str(jobs)]) == 0
    captured = capsys.readouterr()
    return captured.out, captured.err


def test_the_sweep_reports_every_column_counts_non_responders_and_repeats_itself(
    tmp_path: Path, short_scenario: Path, capsys
):
    out, err = _sweep(tmp_path / "a", short_scenario, 1, capsys)
    doc = json.loads((tmp_path / "a" / "sweep.json").read_text())
    scenario = load_scenario(short_scenario)
    seeds = cohort_seeds(1, 6)
    for model in ("paper", "norepinephrine"):
        standard, stronger = syringes(load_library()[doc["models"][model]["drug"]], 120.0)
        plan = reach_plan(scenario, model, 0.2, seeds, standard, stronger)
        (level,) = doc["models"][model]["levels"]
        reach = level["reach"]
        assert (reach["standard"], reach["switched"], reach["non_responders"]) == (
            len(plan["standard"]), len(plan["switched"]), len(plan["non_responders"]),
        )  # fmt: skip
        groups = {row["group"]: row["figures"]["patients"] for row in level["rows"]}
        assert groups == {
            g: len(plan[k])
            for g, k in (
                ("standard", "standard"), ("switched", "switched"),
                ("non-responders", "non_responders"),
            )
            if plan[k]
        }  # fmt: skip
        # the headline counts every patient brought to the target, with either syringe
        reached = len(plan["standard"]) + len(plan["switched"])
        assert [h["figures"]["patients"] for h in level["responders"]] == (
            [reached] if reached else []
        )
    # norepinephrine at 0.2× on this cohort has all three groups (the test needs them)
    ne = doc["models"]["norepinephrine"]["levels"][0]
    assert {r["group"] for r in ne["rows"]} == {"standard", "switched", "non-responders"}
    assert ne["reach"]["stronger_syringe_ug_ml"] == 32.0
    switched = next(r for r in ne["rows"] if r["group"] == "switched")
    assert switched["syringe_ug_ml"] == 32.0
    # every table row has every column, and names the switched and the non-responders
    n_cols = HEADER.splitlines()[0].count("|")
    lines = [line for line in out.splitlines() if line.startswith("| 0.2× | pi |")]
    rows = [line for line in lines if line.count("|") == n_cols]
    headlines = [line for line in lines if line not in rows]
    assert len(rows) == sum(len(m["levels"][0]["rows"]) for m in doc["models"].values())
    assert len(headlines) == sum(len(m["levels"][0]["responders"]) for m in doc["models"].values())
    assert all(h.count("|") == HEADLINE_HEADER.splitlines()[0].count("|") for h in headlines)
    assert any("32 (switched)" in line for line in rows)
    assert any("(non-responders)" in line for line in rows)
    assert "throughput:" in err and "per CPU minute" in err
    # per model too, naming what ran without its compiled twin (the PI has none)
    assert "\n  paper: " in err and "\n  norepinephrine: " in err
    assert "without compiled twin: controller (" in err
    # the same arguments give the same bytes with two workers, and a rerun reuses every cohort
    again, _ = _sweep(tmp_path / "b", short_scenario, 2, capsys)
    assert again == out
    assert (tmp_path / "b" / "sweep.json").read_bytes() == (
        tmp_path / "a" / "sweep.json"
    ).read_bytes()
    reused, err = _sweep(tmp_path / "a", short_scenario, 1, capsys)
    assert reused == out and "runs" not in err and "nothing ran" in err


def test_a_cohort_written_by_another_build_of_the_same_lpv_design_is_run_again(
    tmp_path: Path, short_scenario: Path, capsys
):
    argv = ["--patients", "2", "--seed", "1", "--levels", "10", "--controllers", "lpv"]
    argv += ["--models", "paper", "--scenario", str(short_scenario), "--out", str(tmp_path)]
    assert main(argv) == 0
    first = capsys.readouterr().out
    (run_json,) = tmp_path.glob("paper/x10/*/*/run.json")
    identity = json.loads(run_json.read_text())
    assert len(identity["controller_module_sha256"]) == 64
    assert main(argv) == 0
    assert "nothing ran" in capsys.readouterr().err
    # the same name, another module (a redesign): the cohort runs again, and gives today's figures
    run_json.write_text(json.dumps(identity | {"controller_module_sha256": "0" * 64}))
    assert main(argv) == 0
    out, err = capsys.readouterr()
    assert "nothing ran" not in err and out == first
    assert json.loads(run_json.read_text()) == identity


def test_the_sweep_refuses_a_level_outside_the_range(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--levels", "0.1,30"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "'30'" in err and "[0.05, 20]" in err


def test_the_sweep_refuses_an_unknown_model(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--models", "paper,nonesuch"])
    assert exc.value.code == 2
    assert "nonesuch" in capsys.readouterr().err


def test_the_profile_splits_a_sweep_tick_into_parts_that_add_up(short_scenario: Path, capsys):
    argv = ["--model", "norepinephrine", "--level", "0.5", "--patients", "1"]
    assert profile_main([*argv, "--scenario", str(short_scenario)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "CPU s per patient-hour" in lines[0] and "lpv:norepinephrine-cautious" in lines[0]
    shares = {line[:48].strip(): float(line[48:].rstrip(" %")) for line in lines[1:]}
    assert {"supervisor (input checks, flatline, states)", "dose guard (hourly limit)"} <= set(
        shares
    )
    assert sum(shares.values()) == pytest.approx(100.0, abs=0.5)
    assert shares["supervisor (input checks, flatline, states)"] > 5.0
