"""The "smith" controller family: config, artifact, reconstruction, synth and verify (real solves)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pressor.synthesis import cli
from pressor.synthesis.artifact import (
    ArtifactError,
    default_artifact_path,
    load_artifact,
    make_artifact,
    save_artifact,
)
from pressor.synthesis.families.registry import ControllerFamily
from pressor.synthesis.families.smith.design import SmithDesignError, design_smith
from pressor.synthesis.families.smith.family import smith_coef_shapes
from pressor.synthesis.families.smith.law import SmithLPV
from pressor.synthesis.problem.config import ConfigError
from pressor.synthesis.problem.config_toml import load_config, parse_config
from pressor.synthesis.problem.reconstruct import controller_at
from pressor.synthesis.verify_cli import main as verify_main

SMITH_2 = '[controller]\nstructure = "smith"\nloop_gain = 2.0\n[grid]\npoints = [2, 2, 2]\n'


def _write(tmp_path: Path, text: str, name: str = "design.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.fixture(scope="module")
def smith_artifact():
    """Loop gain 2 certified on a 2x2x2 grid (one real Wirtinger solve, ~15 s CPU)."""
    return design_smith(
        parse_config(
            {"controller": {"structure": "smith", "loop_gain": 2.0}, "grid": {"points": [2, 2, 2]}}
        )
    )


def test_design_file_without_controller_section_is_theorem3(tmp_path):
    cfg = load_config(_write(tmp_path, "[weights]\nphi = 0.5\n"))
    assert cfg.controller == ControllerFamily()
    assert "controller" not in cfg.to_dict()  # theorem3 artifacts keep their bytes


def test_smith_section_is_read_with_its_loop_gain(tmp_path):
    cfg = load_config(_write(tmp_path, SMITH_2))
    assert cfg.controller == ControllerFamily("smith", 2.0)
    assert cfg.to_dict()["controller"] == {"structure": "smith", "loop_gain": 2.0}


@pytest.mark.parametrize(
    ("section", "field", "allowed"),
    [
        pytest.param({"structure": "pid"}, "controller.structure", "'smith'", id="structure"),
        pytest.param({"structure": "smith"}, "controller.loop_gain", "(0, 10]", id="missing"),
        pytest.param(
            {"structure": "smith", "loop_gain": 0.0}, "controller.loop_gain", "(0, 10]", id="zero"
        ),
        pytest.param(
            {"structure": "smith", "loop_gain": 12.5}, "controller.loop_gain", "(0, 10]", id="big"
        ),
        pytest.param(
            {"structure": "smith", "loop_gain": "2"}, "controller.loop_gain", "number", id="text"
        ),
        pytest.param(
            {"structure": "theorem3", "loop_gain": 2.0},
            "controller.loop_gain",
            "absent for structure 'theorem3'",
            id="theorem3-gain",
        ),
        pytest.param({"gain": 2.0}, "controller.gain", "loop_gain", id="unknown-key"),
    ],
)
def test_bad_controller_values_name_file_field_value_and_range(section, field, allowed):
    with pytest.raises(ConfigError) as exc:
        parse_config({"controller": section}, source="x.toml")
    msg = str(exc.value)
    assert msg.startswith("x.toml: field ") and field in msg and allowed in msg


def test_shipped_design_is_the_smith_family_and_its_artifact_says_so():
    cfg = load_config()
    art = load_artifact(default_artifact_path())
    assert cfg.controller.structure == "smith" and art.family == cfg.controller
    assert art.metadata["controller"] == cfg.controller.to_dict()
    assert cfg.controller.loop_gain is not None and 2.5 <= cfg.controller.loop_gain <= 3.0
    assert art.metadata["verification"]["passed"] is True
    assert art.nodes["Ak"].shape[-2:] == (2, 2)


def test_smith_artifact_round_trip_keeps_hash_family_and_certificate(smith_artifact, tmp_path):
    art = smith_artifact
    assert art.family == ControllerFamily("smith", 2.0)
    assert art.metadata["lambda2"] is None and art.gamma > 0
    shapes = smith_coef_shapes(3)
    assert {k: v.shape for k, v in art.coefficients.items()} == shapes
    back = load_artifact(save_artifact(art, tmp_path / "s.npz"))
    assert back.sha256 == art.sha256 and back.family == art.family
    for k, v in art.coefficients.items():
        np.testing.assert_array_equal(back.coefficients[k], v)


def test_smith_design_is_certified_by_its_first_solve_without_a_back_off_solve(smith_artifact):
    # the design's strictness (DESIGN_EPSILON) keeps the minimum-gamma point inside the LMIs
    shipped = load_artifact(default_artifact_path())
    for art in (smith_artifact, shipped):
        solver = art.metadata["solver"]
        assert solver["analysis"].endswith("rate_form bound")
        assert not any("back-off" in note for note in solver["notes"]), solver["notes"]


def test_older_artifact_without_controller_entry_reads_as_theorem3():
    assert ControllerFamily.from_metadata({"gamma": 1.0}) == ControllerFamily()


@pytest.mark.parametrize(
    "entry",
    [
        {"structure": "smith", "loop_gain": -1.0},
        {"structure": "smith"},
        {"structure": "lqr", "loop_gain": None},
    ],
)
def test_loading_rejects_a_bad_family_entry_naming_the_field(smith_artifact, entry):
    meta = {**smith_artifact.metadata, "controller": entry}
    with pytest.raises(ArtifactError, match="metadata.controller"):
        make_artifact(meta, smith_artifact.coefficients, smith_artifact.nodes)


def test_smith_artifact_with_theorem3_coefficients_is_rejected(smith_artifact):
    coefs = {**smith_artifact.coefficients, "X": np.eye(3)[None]}
    with pytest.raises(ArtifactError, match="coef_X"):
        make_artifact(smith_artifact.metadata, coefs, smith_artifact.nodes)


@pytest.mark.parametrize("rho", [(0.31, 117.0, 12.3), (0.55, 150.0, 40.0), (0.97, 188.8, 44.1)])
def test_controller_at_is_the_smith_law_exactly_off_the_grid(smith_artifact, rho):
    got = controller_at(smith_artifact, rho)
    want = SmithLPV(2.0, smith_artifact.omega, smith_artifact.lambda_).at(rho)
    for name in ("Ak", "Adk", "Bk", "Ck", "Cdk", "Dk"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name))
    assert got.tau_s == rho[2]


def test_nodes_are_the_law_at_the_grid_nodes(smith_artifact):
    law = SmithLPV(2.0, smith_artifact.omega, smith_artifact.lambda_)
    grid = smith_artifact.grid
    k = law.at((grid[0][1], grid[1][0], grid[2][1]))
    np.testing.assert_array_equal(smith_artifact.nodes["Cdk"][1, 0, 1], k.Cdk)


def test_uncertifiable_loop_gain_is_an_error_without_artifact():
    cfg = parse_config(
        {"controller": {"structure": "smith", "loop_gain": 10.0}, "grid": {"points": [2, 2, 2]}}
    )
    with pytest.raises(SmithDesignError, match="loop gain 10 not certified"):
        design_smith(cfg)


def test_theorem3_options_are_usage_errors_for_smith(tmp_path, capsys):
    out = tmp_path / "a.npz"
    code = cli.main(
        "synth", ["--config", str(_write(tmp_path, SMITH_2)), "--lambda2", "1", "--out", str(out)]
    )
    assert code == 2 and "--lambda2" in capsys.readouterr().err and not out.exists()


@pytest.mark.slow
def test_synth_then_verify_passes_and_an_uncertifiable_gain_exits_1_writing_nothing(
    tmp_path, capsys
):
    out = tmp_path / "s.npz"
    assert cli.main("synth", ["--config", str(_write(tmp_path, SMITH_2)), "--out", str(out)]) == 0
    art = load_artifact(out)
    rep = art.metadata["verification"]
    assert rep["passed"] is True and rep["grid"]["n_points_unseen_by_synthesis"] == 19
    assert rep["analysis_lmi"]["certified"] is True
    json_out = tmp_path / "v.json"
    assert verify_main("verify", [str(out), "--json", str(json_out)]) == 0
    report = json.loads(json_out.read_text())
    assert report["artifact"]["controller"] == {"structure": "smith", "loop_gain": 2.0}
    assert report["nominal_step"]["lpv_feedback_only"]["overshoot_pct"] < 1.0
    bad = _write(tmp_path, SMITH_2.replace("2.0", "10.0"), "bad.toml")
    out_bad = tmp_path / "bad.npz"
    capsys.readouterr()
    assert cli.main("synth", ["--config", str(bad), "--out", str(out_bad)]) == 1
    assert "not certified" in capsys.readouterr().err and not out_bad.exists()
