"""Design config: the shipped default is valid; malformed values name file, field, value, range."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pressor.synthesis.problem.config import NOMINAL_RHO, ConfigError
from pressor.synthesis.problem.config_toml import load_config


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "design.toml"
    p.write_text(text)
    return p


def test_default_design_box_contains_the_nominal_plant():
    cfg = load_config()
    box = cfg.model.box
    for i, v in enumerate(NOMINAL_RHO):
        assert box[i, 0] <= v <= box[i, 1]
    assert cfg.model.rate_bounds[2] < 1.0


def test_missing_keys_take_the_shipped_defaults(tmp_path):
    cfg = load_config(_write(tmp_path, "[weights]\nphi = 0.5\n"))
    default = load_config()
    assert cfg.model.phi == 0.5
    assert cfg.model.xi == default.model.xi
    np.testing.assert_array_equal(cfg.model.box, default.model.box)


def test_delay_rate_of_one_or_more_is_rejected_with_field_value_and_range(tmp_path):
    p = _write(tmp_path, "[rates]\ntau_s_per_s = 1.5\n")
    with pytest.raises(ConfigError) as exc:
        load_config(p)
    msg = str(exc.value)
    assert str(p) in msg and "rates.tau_s_per_s" in msg and "1.5" in msg and "0.999" in msg


@pytest.mark.parametrize(
    ("toml", "field"),
    [
        pytest.param("[box]\nT_s = [200.0, 100.0]\n", r"box\.T_s", id="box-lower-not-below-upper"),
        pytest.param("[weights]\nphii = 0.5\n", r"weights\.phii", id="unknown-key-not-default"),
        pytest.param('[weights]\nxi = "abc"\n', r"weights\.xi.*'abc'", id="non-numeric-weight"),
        pytest.param("[filter]\nlambda = -0.1\n", r"filter\.lambda.*-0\.1", id="negative-filter"),
        pytest.param("[grid]\npoints = [3, 1, 3]\n", r"grid\.points", id="grid-point-below-two"),
        pytest.param("[grid]\npoints = [3, 3]\n", r"grid\.points", id="grid-not-three-axes"),
        pytest.param(
            '[solver]\nxy_dependence = "neither"\n', r"solver\.xy_dependence", id="unknown-xy"
        ),
    ],
)
def test_malformed_value_is_rejected_naming_the_field(tmp_path, toml, field):
    with pytest.raises(ConfigError, match=field):
        load_config(_write(tmp_path, toml))


def test_invalid_toml_names_the_file(tmp_path):
    p = _write(tmp_path, "[box\nK = [")
    with pytest.raises(ConfigError, match="not valid TOML") as exc:
        load_config(p)
    assert str(p) in str(exc.value)


def test_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="file not found"):
        load_config(tmp_path / "nope.toml")


def test_grid_nodes_span_the_box_edges():
    cfg = load_config().with_grid((2, 3, 4))
    g = cfg.grid()
    assert [a.size for a in g] == [2, 3, 4]
    for i in range(3):
        assert g[i][0] == cfg.model.box[i, 0] and g[i][-1] == cfg.model.box[i, 1]
