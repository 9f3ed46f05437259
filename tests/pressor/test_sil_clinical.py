"""``pressor sil`` in clinical units: the drug rule, an absolute target, the weight, the syringe
the simulated device announces (issue 40, item 1)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from pressor.plumbing.usage import UsageError
from pressor.sil import device_command, sil_config


def _sil(*argv: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pressor", "sil", *argv],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=120,
    )


def test_a_phenylephrine_design_on_norepinephrine_patients_is_one_line_exit_2(tmp_path):
    proc = _sil("--controller", "lpv", "--patient-model", "norepinephrine", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert "a phenylephrine design" in line and "a norepinephrine patient" in line, line
    assert not list(tmp_path.iterdir())  # refused before a device, a recording or a summary


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--controller", "lpv:norepinephrine"], "a norepinephrine design"),
        (["--drug", "norepinephrine"], "--drug norepinephrine: the loaded controller"),
        (["--concentration-ug-ml", "200"], "--concentration-ug-ml 200: the loaded controller"),
        (
            ["--target-mmhg", "40"],
            "--target-mmhg '40' = 40.0: must be a finite number in [50, 120]",
        ),
        (["--weight-kg", "300"], "--weight-kg '300' = 300.0: must be a finite number in [30, 250]"),
    ],
)
def test_bad_clinical_input_is_a_usage_error_before_any_device_starts(argv, needle):
    with pytest.raises(UsageError) as info:
        sil_config(argv)
    assert needle in str(info.value)


def test_sil_help_offers_run_s_clinical_options_with_their_ranges(tmp_path):
    text = " ".join(_sil("--help", cwd=tmp_path).stdout.split())
    assert "--target-mmhg MMHG an absolute MAP target (mmHg, allowed [50, 120])" in text
    assert "--weight-kg KG the patient's weight (kg, allowed [30, 250])" in text
    assert "--drug DRUG" in text and "--concentration-ug-ml UG_ML" in text


def test_the_device_is_told_the_absolute_target_and_the_design_s_syringe():
    cfg = sil_config(
        ["--controller", "lpv:norepinephrine", "--patient-model", "norepinephrine"]
        + ["--target-mmhg", "75", "--drug", "norepinephrine", "--concentration-ug-ml", "16"]
    )
    cmd = device_command(cfg, "/dev/pts/9", None, None)
    assert cmd[cmd.index("--target-mmhg") + 1] == "75.0"
    assert cmd[cmd.index("--drug") + 1] == "norepinephrine"
    assert float(cmd[cmd.index("--concentration-ug-ml") + 1]) == 16.0
    plain = device_command(sil_config(["--controller", "pi"]), "/dev/pts/9", None, None)
    assert "--target-mmhg" not in plain


def test_a_sil_run_holds_the_absolute_target_and_gives_doses_per_kg_of_the_weight(tmp_path):
    proc = _sil(
        "--controller", "pi", "--duration", "30", "--target-mmhg", "80", "--weight-kg", "60",
        "--summary", "s.json", "--no-signing", cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "target 80.0 mmHg" in proc.stdout
    assert "patient weight 60 kg" in proc.stdout
    infusion = next(x for x in proc.stdout.splitlines() if x.startswith("infusion:"))
    peak_ml_h = float(infusion.split("peak ")[1].split(" ml/h")[0])
    peak_dose = float(infusion.split("peak ")[1].split("= ")[1].split(" µg/kg/min")[0])
    assert peak_dose == pytest.approx(peak_ml_h * 100.0 / (60 * 60), abs=0.01)
    summary = json.loads((tmp_path / "s.json").read_text())
    assert (summary["target_mmhg"], summary["weight_kg"]) == (80.0, 60.0)


def test_the_recording_shows_the_delivered_dose_per_kg_beside_the_infusion(tmp_path):
    from tests.runtime.record.test_blueprint import blueprint_rows, views
    from tests.support.sil_helpers import rrd_columns

    proc = _sil(
        "--controller", "pi", "--duration", "20", "--weight-kg", "50", "--rrd", "r.rrd",
        "--no-signing", cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    cols = rrd_columns(tmp_path / "r.rrd")
    rate, per_kg = cols["/pump/rate_ml_h"], cols["/dose/delivered_ug_kg_min"]
    assert max(per_kg.values()) > 0.0
    # the dose at each tick is the rate the pump reported at that tick, in the syringe's units
    for k in range(1, 200, 37):
        assert per_kg[k] == pytest.approx(rate[k] * 100.0 / (60.0 * 50.0), rel=1e-6)
        assert cols["/dose/delivered_ug_min"][k] == pytest.approx(rate[k] * 100.0 / 60.0, rel=1e-6)
    v = views(blueprint_rows(tmp_path / "r.rrd"))
    # per kg only: the µg/min, ~70 times larger, flattened it to the bottom of a shared axis
    assert v["Dose delivered (ug/kg/min)"]["contents"] == ["/dose/delivered_ug_kg_min"]
    assert any(name.startswith("Infusion (ml/h)") for name in v)


def test_a_baseline_runs_on_the_simulated_patients_drug_and_says_so(tmp_path):
    cfg = sil_config(["--controller", "pi", "--patient-model", "norepinephrine"])
    # the device announces the patient's syringe and the runtime end binds the PI to it
    assert (cfg.drug.name, cfg.drug.concentration_ug_ml) == ("norepinephrine", 16.0)
    assert cfg.run.syringe == cfg.drug
    pairs = device_command(cfg, "/dev/pts/9", None, None)
    assert pairs[pairs.index("--drug") + 1] == "norepinephrine"
    argv = ["--controller", "smith", "--patient-model", "norepinephrine", "--duration", "20"]
    proc = _sil(*argv, "--rrd", "r.rrd", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "drug: norepinephrine 16 µg/ml" in proc.stdout
