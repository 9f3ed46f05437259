"""``pressor trial`` in clinical units: the drug rule, doses in µg/kg/min beside ml/h, an absolute
target, the duration (issue 40, item 1)."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import pytest

from pressor import api
from pressor.hil_sim.cli import main as cli_main


def _trial(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pressor", "trial", *argv],
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_a_phenylephrine_design_is_refused_on_norepinephrine_patients_in_one_line(tmp_path):
    proc = _trial(
        "--controller", "lpv", "--patient-model", "norepinephrine", "--out", str(tmp_path / "o")
    )
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "phenylephrine design" in lines[0] and "norepinephrine patient" in lines[0]
    assert "--controller lpv" in lines[0] and "--patient-model norepinephrine" in lines[0]
    assert not (tmp_path / "o").exists()  # refused before anything ran or was written


def test_a_norepinephrine_design_is_refused_on_the_paper_phenylephrine_patients(tmp_path):
    proc = _trial("--controller", "lpv:norepinephrine", "--patients", "1", "--out", str(tmp_path))
    assert proc.returncode == 2
    assert "norepinephrine design" in proc.stderr and "phenylephrine patient" in proc.stderr


@pytest.mark.parametrize(
    ("argv", "text"),
    [
        (["--duration", "0.5"], "--duration = 0.5: must be a finite number in [1, 604800] s"),
        (
            ["--target-mmhg", "130"],
            "--target-mmhg '130' = 130.0: must be a finite number in [50, 120] mmHg",
        ),
        (["--weight-kg", "5"], "--weight-kg '5' = 5.0: must be a finite number in [30, 250] kg"),
        (
            ["--drug", "norepinephrine"],
            "--drug norepinephrine: the loaded design (--controller lpv)",
        ),
        (["--concentration-ug-ml", "16"], "--concentration-ug-ml 16: the loaded design"),
    ],
)
def test_bad_clinical_options_are_one_line_naming_option_value_and_range(argv, text, tmp_path):
    proc = _trial("--controller", "lpv", *argv, "--out", str(tmp_path))
    assert proc.returncode == 2
    assert text in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_trial_help_gives_the_duration_range_and_the_clinical_options():
    proc = _trial("--help")
    text = " ".join(proc.stdout.split())
    assert "--duration S simulated time per patient (s, allowed [1, 604800]" in text
    for option in (
        "--target-mmhg MMHG",
        "--drug DRUG",
        "--concentration-ug-ml UG_ML",
        "--weight-kg KG",
    ):
        assert option in text


def test_pi_runs_on_norepinephrine_patients_and_records_their_drug_and_doses_per_kg(
    tmp_path, short_scenario, capsys
):
    out = tmp_path / "o"
    argv = ["--controller", "pi", "--patient-model", "norepinephrine", "--patients", "2"]
    argv += ["--scenario", str(short_scenario), "--weight-kg", "80", "--out", str(out)]
    assert cli_main("trial", argv) == 0
    record = json.loads((out / "patients.json").read_text())[0]
    inf = record["infusion"]
    assert (inf["drug"], inf["concentration_ug_ml"], inf["weight_kg"]) == (
        "norepinephrine",
        16.0,
        80.0,
    )
    assert inf["weight_given"] is True
    assert inf["peak_rate_ml_h"] == record["max_rate_ml_h"]
    assert inf["peak_dose_ug_kg_min"] == pytest.approx(record["max_rate_ml_h"] * 16.0 / (60 * 80))
    assert inf["mean_rate_ml_h"] == pytest.approx(record["drug_total_ml"] * 3600.0 / 300.0)
    assert inf["mean_dose_ug_kg_min"] == pytest.approx(inf["mean_rate_ml_h"] * 16.0 / (60 * 80))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["infusion"]["drug"] == "norepinephrine"
    rows = list(csv.DictReader((out / "patients.csv").open()))
    assert float(rows[0]["peak_dose_ug_kg_min"]) == pytest.approx(inf["peak_dose_ug_kg_min"])
    printed = capsys.readouterr().out
    line = next(x for x in printed.splitlines() if x.startswith("infusion"))
    assert (
        "ml/h = " in line
        and "µg/kg/min" in line
        and "norepinephrine 16 µg/ml, weight 80 kg" in line
    )


def test_without_a_weight_the_doses_are_per_kg_of_the_reference_adult_said_so(
    tmp_path, short_scenario, capsys
):
    argv = ["--controller", "pi", "--patients", "1", "--scenario", str(short_scenario)]
    assert cli_main("trial", argv + ["--out", str(tmp_path)]) == 0
    inf = json.loads((tmp_path / "patients.json").read_text())[0]["infusion"]
    assert (inf["drug"], inf["weight_kg"], inf["weight_given"]) == ("phenylephrine", 70.0, False)
    assert "per kg at a 70 kg reference weight (no --weight-kg)" in capsys.readouterr().out


def test_duration_and_absolute_target_give_the_api_s_records(tmp_path, short_scenario):
    argv = ["--controller", "pi", "--patients", "2", "--scenario", str(short_scenario)]
    argv += ["--duration", "120", "--target-mmhg", "85", "--out", str(tmp_path)]
    assert cli_main("trial", argv) == 0
    via_api = api.trial("pi", short_scenario, 2, 1, duration_s=120.0, target_mmhg=85.0)
    records = json.loads((tmp_path / "patients.json").read_text())
    assert records == json.loads(json.dumps(via_api.records))
    # the target is 85 mmHg for every patient (the haemorrhage starts at the run's end): each
    # one's step is 85 minus its own baseline
    for r in records:
        assert r["required_delta_mmhg"] == pytest.approx(85.0 - r["coefficients"]["baseline_mmhg"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["target_mmhg"] == 85.0


def test_the_report_gives_the_infusion_in_ug_kg_min_beside_ml_h(tmp_path, short_scenario):
    argv = ["--controller", "pi,smith", "--patients", "2", "--scenario", str(short_scenario)]
    assert cli_main("trial", argv + ["--weight-kg", "60", "--report", "--out", str(tmp_path)]) == 0
    page = (tmp_path / "report.html").read_text()
    assert "<h2>Infusion (median over all patients)</h2>" in page
    for head in (
        "mean rate (ml/h)",
        "mean dose (µg/kg/min)",
        "peak dose (µg/kg/min)",
        "weight (kg)",
    ):
        assert f"<th>{head}</th>" in page
    assert "<td>phenylephrine</td><td>100</td><td>60</td>" in page


def _records(out) -> list[dict]:
    return json.loads((out / "patients.json").read_text())


@pytest.mark.parametrize("baseline", ["pi", "smith"])
def test_a_baseline_runs_on_another_library_syringe_of_the_patients_drug_and_names_it(
    baseline, tmp_path, short_scenario, capsys
):
    common = ["--controller", baseline, "--patient-model", "norepinephrine", "--patients", "2"]
    common += ["--scenario", str(short_scenario)]
    usual, strong = tmp_path / "16", tmp_path / "32"
    assert cli_main("trial", [*common, "--out", str(usual)]) == 0
    argv = [*common, "--drug", "norepinephrine", "--concentration-ug-ml", "32"]
    assert cli_main("trial", [*argv, "--out", str(strong)]) == 0
    assert "norepinephrine 32 µg/ml" in capsys.readouterr().out
    summary = json.loads((strong / "summary.json").read_text())
    assert (summary["infusion"]["drug"], summary["infusion"]["concentration_ug_ml"]) == (
        "norepinephrine",
        32.0,
    )
    for at16, at32 in zip(_records(usual), _records(strong), strict=True):
        assert at32["patient_seed"] == at16["patient_seed"]
        # every ml/h of a 32 ug/ml syringe carries twice the drug of the model's 16 ug/ml one
        assert at32["coefficients"]["sensitivity_factor"] == 2.0
        assert "sensitivity_factor" not in at16["coefficients"]
        inf = at32["infusion"]
        assert inf["concentration_ug_ml"] == 32.0
        assert inf["peak_dose_ug_kg_min"] == pytest.approx(inf["peak_rate_ml_h"] * 32 / (60 * 70))
        # the same patients lifted by the same fixed-gain law: fewer ml of the stronger syringe
        assert at32["drug_total_ml"] < at16["drug_total_ml"]


def test_a_baseline_on_a_syringe_the_library_does_not_list_is_refused_naming_the_library(
    tmp_path,
):
    proc = _trial("--controller", "pi", "--concentration-ug-ml", "50", "--out", str(tmp_path))
    assert proc.returncode == 2
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith("pressor trial: --concentration-ug-ml 50: ")
    assert "drug library only (phenylephrine: 100 ug/ml)" in line


def test_the_api_trial_runs_a_baseline_on_another_library_syringe(short_scenario):
    result = api.trial(
        "pi",
        short_scenario,
        n_patients=1,
        patient_model="norepinephrine",
        concentration_ug_ml=64.0,
    )
    (record,) = result.records
    assert record["infusion"]["concentration_ug_ml"] == 64.0
    assert record["coefficients"]["sensitivity_factor"] == 4.0
    assert result.summary["infusion"]["concentration_ug_ml"] == 64.0
