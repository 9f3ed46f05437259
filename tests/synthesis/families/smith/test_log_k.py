"""The Smith design on a log-K scale: a relative K rate, the bumpless integral's certificate term,
and a certificate that covers a K box of any width (a real solve on its corners)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pressor.synthesis.certificates.wirtinger.k_scaling import k_scaled_system
from pressor.synthesis.families.smith.design import (
    _k_scaling,
    bumpless_rows,
    design_smith,
    recheck_smith_artifact,
    smith_loops,
)
from pressor.synthesis.families.smith.law import SmithLPV
from pressor.synthesis.problem.config import ConfigError
from pressor.synthesis.problem.config_toml import load_config
from pressor.synthesis.problem.model import I_MAP, I_U, I_XE

#: a 1000x K box, falls of ln K up to 0.02/s, rises up to 0.002/s (docs/notes/cautious-start.md)
LOG_DESIGN = """
[box]
K = [0.01, 10.0]
T_s = [100.0, 400.0]
tau_s = [10.0, 45.0]
[rates]
K_relative_per_s = 0.02
K_relative_up_per_s = 0.002
T_s_per_s = 0.06
tau_s_per_s = 0.1
[controller]
structure = "smith"
loop_gain = 3.0
"""


def _config(tmp_path: Path, text: str = LOG_DESIGN):
    path = tmp_path / "log.toml"
    path.write_text(text)
    return load_config(path)


def test_relative_rates_are_read_and_stored(tmp_path):
    cfg = _config(tmp_path)
    assert cfg.model.k_rate_relative and cfg.model.rate_bounds[0] == 0.02
    assert cfg.model.k_rate_up_per_s == 0.002
    model = cfg.model.to_dict()
    assert model["k_rate_relative"] is True and model["k_rate_up_per_s"] == 0.002
    # an absolute design's model entry is unchanged (its artifacts keep their bytes)
    assert "k_rate_relative" not in load_config().model.to_dict()


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (("K_relative_up_per_s = 0.002", "K_relative_up_per_s = 0.002\nK_per_s = 1e-4"), "K_per_s"),
        (("K_relative_per_s = 0.02", "K_relative_per_s = 0.5"), "K_relative_per_s"),
        (('structure = "smith"', 'structure = "theorem3"'), "K_relative_per_s"),
        (("K_relative_per_s = 0.02\n", ""), "K_relative_up_per_s"),
    ],
)
def test_bad_relative_rates_name_the_field(tmp_path, edit, field):
    text = LOG_DESIGN.replace(*edit)
    if 'structure = "theorem3"' in text:
        text = text.replace("loop_gain = 3.0\n", "")
    with pytest.raises(ConfigError, match=field):
        _config(tmp_path, text)


def test_bumpless_rows_are_the_law_rewritten_as_its_integral(tmp_path):
    # kappa (K T / g) u_a = kappa (T e_p + x_e - tau (yhat + yhat(t - tau)) / 2)
    cfg = _config(tmp_path)
    law = SmithLPV(3.0, cfg.model.omega, cfg.model.lambda_)
    k, t_s, tau = 0.7, 250.0, 30.0
    n_plant = 3
    rows = bumpless_rows(law, cfg.model, np.array([k, t_s, tau]), (I_U, n_plant))
    n = rows.shape[0]
    xe = rows[I_XE]
    assert np.count_nonzero(np.delete(rows, I_XE, axis=0)) == 0
    yhat = n_plant + 1  # the controller's model output
    assert xe[I_XE] == pytest.approx(1.0)
    assert xe[I_MAP] == pytest.approx(-t_s)  # e = r - MAP - d_o
    assert xe[yhat] == pytest.approx(-t_s - tau / 2)
    assert xe[n + yhat] == pytest.approx(t_s - tau / 2)
    assert xe[2 * n : 2 * n + 2] == pytest.approx([t_s, -t_s])  # r, d_o


def test_k_scaled_loops_and_kappa_rows_do_not_depend_on_k(tmp_path):
    cfg = _config(tmp_path)
    law = SmithLPV(3.0, cfg.model.omega, cfg.model.lambda_)
    points = np.array([[0.01, 150.0, 40.0], [10.0, 150.0, 40.0]])
    ks = _k_scaling(points, cfg.model, law)
    lo, hi = (
        k_scaled_system(q, p[0], ks.states)
        for q, p in zip(smith_loops(law, cfg.model, points), points, strict=True)
    )
    for name in ("A", "Ad", "B", "C", "Cd", "D"):
        np.testing.assert_allclose(getattr(lo, name), getattr(hi, name), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(ks.kappa_rows[0], ks.kappa_rows[1], rtol=1e-9, atol=1e-12)


def test_the_certificate_covers_a_1000x_k_box_at_its_ends(tmp_path):
    # the real solve on the design grid (the box's corners, K 0.01 and 10) and its floating-point
    # re-check at every corner and rate vertex
    art = design_smith(_config(tmp_path))
    assert art.model_config.k_rate_relative
    box = art.box
    assert box[0, 1] / box[0, 0] >= 100.0
    certified, margins = recheck_smith_artifact(art)
    assert certified and margins.shape == (8,) and np.all(margins > 0)
    assert 0 < art.gamma < 1e3
