"""The shipped norepinephrine design (its module's currency: test_shipped_lpv_designs.py):
``--controller lpv:norepinephrine`` loads it bound to norepinephrine at 16 µg/ml, ``pressor sil``
tells the device to announce that syringe, and the design's LPV holds a norepinephrine patient's
target."""

from __future__ import annotations

from pathlib import Path

import pytest

from pressor.codegen import pipeline as pl
from pressor.contracts.drug import DEFAULT_BINDING, DrugBinding, binding_of
from pressor.hil_sim.episode import simulate
from pressor.hil_sim.world import World
from pressor.runtime.inputs.controller_loader import (
    LPV_DESIGNS,
    ControllerSpecError,
    controller_name,
    load_controller,
)
from pressor.sil import device_command, sil_config

ARTIFACT = Path(pl.REPO_ROOT) / "synthesis" / "data" / "norepinephrine_design.npz"
COMMITTED = LPV_DESIGNS["norepinephrine"]
NOREPINEPHRINE = DrugBinding("norepinephrine", 16.0)


def test_lpv_drug_specs_load_each_drugs_module_with_its_binding() -> None:
    c = load_controller("lpv:norepinephrine", artifact_sha256=pl.load_design(ARTIFACT).sha256)
    assert binding_of(c) == NOREPINEPHRINE
    assert binding_of(load_controller("lpv:phenylephrine")) == DEFAULT_BINDING
    assert controller_name("lpv:norepinephrine") == "lpv:norepinephrine"
    with pytest.raises(ControllerSpecError, match="no shipped design named 'dopamine'"):
        load_controller("lpv:dopamine")


def test_sil_tells_the_device_to_announce_the_designs_syringe(tmp_path: Path) -> None:
    argv = ["--patient-model", "norepinephrine", "--rrd", str(tmp_path / "a.rrd")]
    config = sil_config(["--controller", "lpv:norepinephrine", *argv])
    assert config.drug == NOREPINEPHRINE
    cmd = device_command(config, "/dev/null", None, None)
    assert cmd[cmd.index("--drug") + 1] == "norepinephrine"
    assert float(cmd[cmd.index("--concentration-ug-ml") + 1]) == 16.0
    # a baseline runs on the simulated patient's drug: the device announces that syringe
    pi = device_command(sil_config(["--controller", "pi", *argv]), "/dev/null", None, None)
    assert pi[pi.index("--drug") + 1] == "norepinephrine"
    default = device_command(sil_config(["--controller", "pi"]), "/dev/null", None, None)
    assert "--drug" not in default  # phenylephrine at 100 ug/ml: the device's default


def test_the_norepinephrine_lpv_lifts_a_norepinephrine_patient_toward_its_target() -> None:
    world = World("paper-tracking", 2026 * 1_000_000 + 5, 0.1, patient_model="norepinephrine")
    assert world.patient.max_delta_map_mmhg(120.0) > 20.0  # this patient can reach the target
    traj = simulate(world, load_controller("lpv:norepinephrine"), 900.0)  # oracle schedule
    assert traj.map_true_mmhg[-1] == pytest.approx(world.baseline_mmhg + 20.0, abs=1.0)
