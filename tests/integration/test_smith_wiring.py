"""``--controller smith[:LAMBDA_S]`` end to end: the loader spec, ``pressor trial``, ``pressor sil``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pressor.baselines.smith import SmithController
from pressor.hil_sim.cli import main as sim_main
from pressor.runtime.inputs.controller_loader import ControllerSpecError, load_controller
from tests.support.sil_helpers import assert_recording_equals_simulation, pressor


def test_smith_spec_gives_the_smith_predictor_with_lambda_30_s():
    c = load_controller("smith", 0.1)
    assert isinstance(c, SmithController)
    assert c.lambda_s == 30.0 and c.sample_period_s == 0.1 and c.max_rate_ml_h == 120.0


def test_smith_spec_with_lambda_sets_the_closed_loop_time_constant():
    c = load_controller("smith:45", 0.05)
    assert isinstance(c, SmithController)
    assert c.lambda_s == 45.0 and c.sample_period_s == 0.05


@pytest.mark.parametrize("value", ["2", "601", "abc", "nan", "inf", "", "-30"])
def test_bad_lambda_is_one_error_naming_value_and_range(value):
    with pytest.raises(ControllerSpecError) as exc:
        load_controller(f"smith:{value}", 0.1)
    msg = str(exc.value)
    assert f"{value!r}" in msg and "[5, 600] s" in msg and "\n" not in msg


def test_unknown_spec_lists_smith_among_the_choices():
    with pytest.raises(ControllerSpecError, match=r"smith\[:LAMBDA_S\]"):
        load_controller("smithy", 0.1)


def test_trial_with_smith_beats_the_pi_on_every_patient_of_a_small_cohort(tmp_path: Path):
    """Seed 11, patients 0-2 are reachable; the Smith predictor's IAE is below the PI's on each."""
    iae = {}
    for spec in ("smith", "pi"):
        argv = ["--controller", spec, "--patients", "3", "--seed", "11"]
        argv += ["--scenario", "paper-tracking", "--jobs", "2", "--out", str(tmp_path / spec)]
        assert sim_main("trial", argv) == 0
        patients = json.loads((tmp_path / spec / "patients.json").read_text())
        assert all(p["reachable"] and p["stable"] for p in patients)
        assert all(p["commands_out_of_range"] == 0 for p in patients)
        iae[spec] = [p["iae_mmhg_s"] for p in patients]
        summary = json.loads((tmp_path / spec / "summary.json").read_text())
        assert summary["controller"] == spec
    assert all(s < p for s, p in zip(iae["smith"], iae["pi"], strict=True)), iae


def test_trial_with_bad_lambda_exits_2_with_one_line(tmp_path: Path, capsys):
    argv = ["--controller", "smith:1", "--patients", "1", "--out", str(tmp_path / "x")]
    assert sim_main("trial", argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'1'" in err[0] and "[5, 600] s" in err[0]
    assert not (tmp_path / "x").exists()


def test_sil_with_smith_over_the_pty_equals_the_in_process_simulator(tmp_path: Path):
    from pressor.hil_sim.episode import simulate
    from pressor.hil_sim.world import World

    rrd, summary = tmp_path / "s.rrd", tmp_path / "s.json"
    proc = pressor(
        "sil",
        *("--controller", "smith:45", "--scenario", "paper-tracking", "--patient-seed", "3"),
        *("--schedule", "oracle"),
        *("--duration", "300", "--rrd", str(rrd), "--summary", str(summary)),
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    s = json.loads(summary.read_text())
    assert s["controller"] == "smith:45" and s["metrics"]["commands_out_of_range"] == 0
    ref = simulate(World("paper-tracking", 3, 0.1), SmithController(0.1, lambda_s=45.0), 300.0)
    sil_cmd = assert_recording_equals_simulation(rrd, ref)
    assert sil_cmd.max() == pytest.approx(120.0)  # the step drove the pump to its limit
