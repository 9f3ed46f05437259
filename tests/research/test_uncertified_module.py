"""The research build of the shipped law on boxes no certificate covers (research/uncertified_module.py,
research/designs/wide_delay.toml, delay60.toml)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pressor.codegen.pipeline import command_line
from pressor.runtime.inputs.controller_loader import UNCERTIFIED_MARK
from pressor.synthesis.artifact import default_artifact_path, load_artifact
from pressor.synthesis.problem.config_toml import load_config
from pressor.synthesis.problem.reconstruct import controller_at
from research.uncertified_module import uncertified_design

ROOT = Path(__file__).parents[2]
DESIGNS = ROOT / "research" / "designs"


def test_research_build_is_the_shipped_law_at_a_point_both_boxes_hold():
    design = uncertified_design(DESIGNS / "wide_delay.toml")
    rho = np.array([0.8, 250.0, 40.0])
    mine = design.controller_fn(rho)
    shipped = controller_at(load_artifact(default_artifact_path()), rho)
    for name in ("Ak", "Adk", "Bk", "Ck", "Cdk", "Dk"):
        np.testing.assert_array_equal(getattr(mine, name), getattr(shipped, name))


def test_research_build_carries_the_mark_the_runtime_loader_refuses():
    design = uncertified_design(DESIGNS / "wide_delay.toml")
    command = command_line(design.display_path, "python", "q31")
    assert command.startswith(UNCERTIFIED_MARK + "research/designs/wide_delay.toml")
    assert design.box.tolist() == [[0.15, 3.0], [100.0, 700.0], [10.0, 200.0]]


def test_research_build_refuses_a_design_of_another_family():
    with pytest.raises(ValueError, match="controller.structure' must be 'smith'"):
        uncertified_design(ROOT / "synthesis" / "data" / "theorem3_design.toml")


def test_delay_designs_widen_only_the_delay_box_and_their_own_rates():
    shipped = load_config(None)
    wide = load_config(DESIGNS / "wide_delay.toml")
    d60 = load_config(DESIGNS / "delay60.toml")
    assert wide.model.box[2].tolist() == [10.0, 200.0]
    assert d60.model.box[2].tolist() == [10.0, 60.0]
    assert wide.model.rate_bounds.tolist() == shipped.model.rate_bounds.tolist()
    assert d60.model.rate_bounds.tolist() == [2e-4, 0.03, 0.05]
    for cfg in (wide, d60):
        assert cfg.model.box[0].tolist() == shipped.model.box[0].tolist()
        assert cfg.controller == shipped.controller
        assert cfg.reference == shipped.reference
