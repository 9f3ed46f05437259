"""`pressor patients` and `pressor designs`: what ships, a line each, read from the registries;
the trial's help and the controller-spec error name every design; plugin output folders read."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pressor.hil_sim.patients.patient_model import PATIENT_MODEL_NOTES, PATIENT_MODELS
from pressor.runtime.inputs.controller_loader import (
    BASELINES,
    LPV_DESIGNS,
    ControllerSpecError,
    design_header,
    design_specs,
    load_controller,
    shipped_specs,
)
from tests.support.sil_helpers import pressor

ROOT = Path(__file__).resolve().parents[2]


def test_designs_lists_every_design_of_the_loaders_table_and_the_baselines(tmp_path):
    proc = pressor("designs", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == len(LPV_DESIGNS) + len(BASELINES)
    specs = [line.split()[0] for line in lines]
    assert specs == [*design_specs(), *BASELINES]
    assert {"lpv", "lpv:norepinephrine", "lpv:wide-delay", "pi", "smith[:LAMBDA_S]"} <= set(specs)
    for line, path in zip(lines, LPV_DESIGNS.values(), strict=False):
        h = design_header(path)
        assert f"{h['DRUG']} {h['DRUG_CONCENTRATION_UG_ML']:g} µg/ml" in line, line
        assert f"K {h['GRID_LO'][0]:g}-{h['GRID_HI'][0]:g} mmHg/(ml/h)" in line, line
        assert ".npz" in line, line
    assert "norepinephrine 16 µg/ml" in lines[specs.index("lpv:norepinephrine")]
    assert "tau 10-200 s" in lines[specs.index("lpv:wide-delay")]


def test_a_design_added_to_the_loaders_table_is_listed_and_named_in_errors(monkeypatch, tmp_path):
    from pressor.listing import design_lines

    copy = tmp_path / "lpv_copy.py"
    copy.write_bytes(LPV_DESIGNS["wide-delay"].read_bytes())
    monkeypatch.setitem(LPV_DESIGNS, "test-copy", copy)
    assert "lpv:test-copy" in shipped_specs()
    assert any(line.startswith("lpv:test-copy ") for line in design_lines())
    with pytest.raises(ControllerSpecError, match="lpv:test-copy"):
        load_controller("no-such-controller")


def test_the_controller_spec_error_names_every_shipped_controller():
    with pytest.raises(ControllerSpecError) as err:
        load_controller("lqr")
    for spec in ("lpv", "lpv:norepinephrine", "lpv:wide-delay", "pi", "smith[:LAMBDA_S]"):
        assert spec in str(err.value)
    assert "pressor designs" in str(err.value)


def test_trial_help_and_its_bad_controller_error_name_every_design(tmp_path):
    # argparse may wrap a long name at its hyphen (lpv:norepinephrine-⏎cautious)
    help_text = " ".join(pressor("trial", "--help", cwd=tmp_path).stdout.split()).replace("- ", "-")
    bad = pressor("trial", "--controller", "lqr", "--out", str(tmp_path / "o"), cwd=tmp_path)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
    for spec in shipped_specs():
        assert spec in help_text, spec
        assert spec in bad.stderr, spec


def test_patients_lists_every_registry_model_with_its_drug_and_source(tmp_path):
    proc = pressor("patients", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert [line.split()[0] for line in lines] == list(PATIENT_MODELS)
    assert all("; source: " in line for line in lines)
    assert lines[0].startswith("paper (default)")
    nor = lines[list(PATIENT_MODELS).index("norepinephrine")]
    assert "norepinephrine 16 µg/ml" in nor and "Beloeil" in nor


def test_every_shipped_patient_model_has_its_line():
    assert set(PATIENT_MODEL_NOTES) == set(PATIENT_MODELS)


@pytest.mark.parametrize(
    ("spec", "folder"),
    [
        ("lpv", "lpv"),
        ("smith:45", "smith_45"),
        ("lpv:wide-delay", "lpv_wide-delay"),
        ("/tmp/some/where/gspi.py:GSPI:kp0=3.0", "gspi_GSPI_kp0_3.0"),
        ("pkg.ctrl:Gain", "ctrl_Gain"),
        ("runtime/generated/lpv_wide_delay.py", "lpv_wide_delay"),
    ],
)
def test_output_folder_names_are_readable(spec, folder):
    from pressor.hil_sim.trials.trial import controller_dir_name

    assert controller_dir_name(spec) == folder


def test_a_plugin_trial_writes_into_a_folder_named_by_file_and_class(tmp_path, short_scenario):
    from pressor.hil_sim.cli import main

    plugin = f"{ROOT / 'examples' / 'custom_controller.py'}:ScheduledPI:lambda_s=60"
    out = tmp_path / "o"
    argv = ["--controller", f"pi,{plugin}", "--patients", "1", "--scenario", str(short_scenario)]
    assert main("trial", [*argv, "--out", str(out)]) == 0
    folders = sorted(p.name for p in out.iterdir() if p.is_dir())
    assert folders == ["custom_controller_ScheduledPI_lambda_s_60", "pi"]
    assert json.loads((out / folders[0] / "summary.json").read_text())["n_patients"] == 1


def test_two_controllers_that_would_share_a_folder_are_refused(tmp_path, short_scenario, capsys):
    from pressor.hil_sim.cli import main

    source = (ROOT / "examples" / "custom_controller.py").read_text()
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "ctrl.py").write_text(source)
    specs = ",".join(f"{tmp_path / d / 'ctrl.py'}:ScheduledPI" for d in ("a", "b"))
    argv = ["--controller", specs, "--patients", "1", "--scenario", str(short_scenario)]
    assert main("trial", [*argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "would write the same folder 'ctrl_ScheduledPI'" in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()
