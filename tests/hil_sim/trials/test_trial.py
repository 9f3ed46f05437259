"""`pressor trial` / `pressor scenarios`: outputs, determinism across --jobs, usage errors."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from pressor.hil_sim.cli import main


def _run(tmp: Path, scenario: Path, jobs: int, name: str) -> Path:
    out = tmp / name
    argv = ["--controller", "pi", "--patients", "4", "--seed", "1", "--scenario", str(scenario)]
    assert main("trial", argv + ["--jobs", str(jobs), "--out", str(out)]) == 0
    return out


def test_trial_files_identical_across_runs_and_jobs(tmp_path: Path, short_scenario: Path):
    a = _run(tmp_path, short_scenario, 1, "a")
    b = _run(tmp_path, short_scenario, 2, "b")
    for f in ("patients.json", "patients.csv", "summary.json"):
        assert (a / f).read_bytes() == (b / f).read_bytes(), f


def test_trial_outputs_name_seed_coefficients_and_metrics(tmp_path, short_scenario, capsys):
    out = _run(tmp_path, short_scenario, 1, "a")
    patients = json.loads((out / "patients.json").read_text())
    assert [p["patient_seed"] for p in patients] == [1000000, 1000001, 1000002, 1000003]
    for p in patients:
        assert 0.1 <= p["coefficients"]["k0"] <= 1.0
        k_lo, k_hi = p["schedule_range"]["K_mmhg_per_ml_h"]
        assert (
            0.0 < k_lo <= k_hi <= p["coefficients"]["k0"] * (1 + 1e-6)
        )  # K falls from k0 (float32)
        t_lo, t_hi = p["schedule_range"]["T_s"]
        assert t_lo <= t_hi
        assert isinstance(p["reachable"], bool) and isinstance(p["stable"], bool)
        assert p["reachable"] == (p["required_delta_mmhg"] <= p["max_delta_mmhg"])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_patients"] == 4
    m = summary["metrics"]
    assert m["n_reachable"] + m["n_unreachable"] == 4
    assert set(m["reachable"]["settling_time_s"]) == {"median", "p10", "p90", "n", "n_null"}
    assert summary["coefficient_units"]["k0"] == "mmHg/(ml/h)"
    csv_lines = (out / "patients.csv").read_text().splitlines()
    assert csv_lines[0].startswith("patient_seed,a_k (s),k0 (mmHg/(ml/h))") and len(csv_lines) == 5
    assert "K_mmhg_per_ml_h_min,K_mmhg_per_ml_h_max,T_s_min" in csv_lines[0]
    text = capsys.readouterr()
    assert "settling time (s)" in text.out and "median" in text.out
    assert "settling_time_s" not in text.out  # the JSON's names stay in the JSON
    assert "4/4 patients" in text.err


def test_trial_records_and_csv_carry_step_window_and_disturbance_fields(
    tmp_path, short_scenario, capsys
):
    out = _run(tmp_path, short_scenario, 1, "a")
    patients = json.loads((out / "patients.json").read_text())
    rows = list(csv.DictReader(io.StringIO((out / "patients.csv").read_text())))
    for p, row in zip(patients, rows, strict=True):
        (hem,) = p["disturbances"]  # the scenario's one hemorrhage, at 120 s of a 300 s run
        assert (hem["kind"], hem["start_s"], hem["end_s"]) == ("hemorrhage", 120.0, 300.0)
        assert hem["peak_deviation_mmhg"] < 0.0  # a dip
        # The step window [0, 120) s is part of the run after the step [0, 300) s.
        assert 0.0 < p["step_iae_mmhg_s"] < p["iae_mmhg_s"]
        assert p["step_overshoot_pct"] <= p["overshoot_pct"]
        for key in ("step_overshoot_pct", "step_settling_time_s", "step_iae_mmhg_s"):
            assert row[key] == ("" if p[key] is None else repr(p[key]))
        for key in ("start_s", "peak_deviation_mmhg", "recovery_s", "iae_mmhg_s"):
            assert row[f"hemorrhage_{key}"] == ("" if hem[key] is None else repr(hem[key]))
    summary = json.loads((out / "summary.json").read_text())["metrics"]
    hem_summary = summary["disturbances"]["hemorrhage"]
    assert hem_summary["start_s"] == 120.0
    assert hem_summary["iae_mmhg_s"]["n"] == summary["n_reachable"]
    assert set(summary["reachable"]["step_overshoot_pct"]) == {
        "median",
        "p10",
        "p90",
        "n",
        "n_null",
    }
    text = capsys.readouterr().out
    assert "step: overshoot (%)" in text and "hemorrhage at 120 s" in text
    assert "peak |deviation| (mmHg)" in text


def test_trial_rejects_bad_inputs_with_exit_2_and_one_line(tmp_path, short_scenario, capsys):
    base = ["--seed", "1", "--out", str(tmp_path / "x")]
    assert main("trial", base + ["--patients", "0", "--scenario", str(short_scenario)]) == 2
    assert "--patients = 0: must be an integer in [1, 100000]" in capsys.readouterr().err
    assert main("trial", base + ["--scenario", "no-such-scenario"]) == 2
    assert "must be one of" in capsys.readouterr().err
    bad = tmp_path / "nope.py"
    assert main("trial", base + ["--controller", str(bad), "--scenario", str(short_scenario)]) == 2
    err = capsys.readouterr().err
    assert "not found" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()


def test_scenarios_lists_required_names_one_line_each(capsys):
    assert main("scenarios", []) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    names = [line.split()[0] for line in lines]
    for required in ("nominal-step", "paper-tracking", "paper-disturbance"):
        assert required in names
    assert all("INVALID" not in line for line in lines)


def test_two_controllers_write_their_own_files_a_paired_comparison_and_a_report(
    tmp_path: Path, short_scenario: Path, capsys
):
    out = tmp_path / "cmp"
    argv = ["--controller", "pi,smith", "--patients", "3", "--seed", "1"]
    argv += ["--scenario", str(short_scenario), "--report", "--out", str(out)]
    assert main("trial", argv) == 0
    single = _run(tmp_path, short_scenario, 1, "single")  # the same cohort under the PI alone
    assert (
        json.loads((out / "pi" / "patients.json").read_text())[:3]
        == json.loads((single / "patients.json").read_text())[:3]
    )
    smith = json.loads((out / "smith" / "patients.json").read_text())
    comparison = json.loads((out / "comparison.json").read_text())
    iae = comparison["pi vs smith"]["iae_mmhg_s"]
    assert iae["n"] == sum(r["reachable"] for r in smith)
    assert "pi vs smith" in (out / "report.html").read_text()
    assert (out / "trajectories_pi.npz").is_file() and (out / "trajectories_smith.npz").is_file()
    assert "paired: pi vs smith" in capsys.readouterr().out


def test_a_controller_named_twice_is_refused_with_exit_2(tmp_path, short_scenario, capsys):
    argv = ["--controller", "pi,pi", "--patients", "2", "--scenario", str(short_scenario)]
    assert main("trial", argv + ["--out", str(tmp_path / "o")]) == 2
    assert "name each controller once" in capsys.readouterr().err


def test_a_reused_out_loses_the_earlier_runs_comparison_and_report(
    tmp_path: Path, short_scenario: Path, capsys
):
    out = tmp_path / "o"
    base = ["--patients", "1", "--seed", "1", "--scenario", str(short_scenario), "--out", str(out)]
    assert main("trial", ["--controller", "pi,smith", "--report", *base]) == 0
    assert (out / "comparison.json").is_file() and (out / "report.html").is_file()
    capsys.readouterr()
    assert main("trial", ["--controller", "pi", *base]) == 0  # one controller, no report
    assert not (out / "comparison.json").exists() and not (out / "report.html").exists()
    assert (out / "patients.json").is_file()
    err = capsys.readouterr().err
    assert "removed" in err and "comparison.json" in err and "report.html" in err


def test_the_terminal_explains_each_unreachable_patient_in_words():
    from pressor.hil_sim.trials.table import format_unreachable

    records = [
        {"patient_seed": 7, "reachable": True},
        {
            "patient_seed": 8,
            "reachable": False,
            "required_delta_mmhg": 30.0,
            "max_delta_mmhg": 15.07,
        },
    ]
    text = format_unreachable(records)
    assert text.startswith("unreachable: even at the pump's maximum rate")
    assert text.splitlines()[1] == (
        "  patient 8: the pump's maximum cannot raise this patient's MAP by the step:"
        " 15.1 mmHg reachable of 30.0 asked"
    )
    assert format_unreachable(records[:1]) == ""
