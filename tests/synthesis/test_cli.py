"""``pressor synth``: exit codes, one-line errors, a real tiny run that writes a loadable artifact."""

from __future__ import annotations

import shutil

import pytest

from pressor.synthesis import cli
from pressor.synthesis.artifact import load_artifact
from pressor.synthesis.problem.config_toml import theorem3_config_path


def test_bad_config_value_exits_2_with_one_line_naming_file_and_field(tmp_path, capsys):
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[rates]\ntau_s_per_s = 2.0\n")
    assert cli.main("synth", ["--config", str(cfg), "--out", str(tmp_path / "a.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert str(cfg) in err and "rates.tau_s_per_s" in err and "2.0" in err
    assert not (tmp_path / "a.npz").exists()


def test_missing_config_file_exits_2(tmp_path, capsys):
    assert cli.main("synth", ["--config", str(tmp_path / "none.toml")]) == 2
    assert "file not found" in capsys.readouterr().err


@pytest.mark.parametrize("grid", ["3,3", "1,3,3", "a,b,c", "3,3,99"])
def test_bad_grid_exits_2(grid, tmp_path, capsys):
    assert cli.main("synth", ["--grid", grid, "--out", str(tmp_path / "a.npz")]) == 2
    assert "grid" in capsys.readouterr().err


def test_unknown_option_exits_2():
    assert cli.main("synth", ["--no-such-option"]) == 2


def test_backoff_out_of_range_exits_2(tmp_path, capsys):
    assert cli.main("synth", ["--backoff", "3", "--out", str(tmp_path / "a.npz")]) == 2
    assert "--backoff: field 'solver.backoff' = 3.0: must be a finite number in [0, 1]" in (
        capsys.readouterr().err
    )


def test_tiny_theorem3_synthesis_writes_exactly_the_requested_artifact(tmp_path, capsys):
    out = tmp_path / "deep" / "tiny.npz"
    cfg = tmp_path / "theorem3.toml"
    shutil.copy(theorem3_config_path(), cfg)
    argv = ["--config", str(cfg), "--grid", "2,2,2", "--out", str(out), "--no-verify"]
    code = cli.main("synth", argv)
    captured = capsys.readouterr()
    text = captured.out
    assert code == 0, text
    art = load_artifact(out)
    assert art.metadata["solver"]["status"] == "optimal"
    assert art.family.structure == "theorem3" and "controller" not in art.metadata
    assert [g.size for g in art.grid] == [2, 2, 2]
    assert f"{art.gamma:.6g}" in text and "solver status" in text and "optimal" in text
    # progress on stderr: stage lines and one line per solver iteration with gap and residuals
    iters = [ln for ln in captured.err.splitlines() if ln.startswith("[synth") and " iter " in ln]
    assert len(iters) >= 5 and all("gap" in ln and "pres" in ln for ln in iters)
    assert sorted(p.name for p in out.parent.iterdir()) == ["tiny.npz"]
    assert sorted(p.name for p in out.parent.parent.iterdir()) == ["deep", "theorem3.toml"]


def test_wall_clock_entries_are_dropped_but_step_metrics_kept():
    report = {
        "analysis_lmi": {"solve_time_s": 55.4, "gamma": 3.0},
        "nominal_step": {"lpv": {"settling_time_s": 227.0, "rise_time_s": 118.0}},
        "list": [{"build_time_s": 1.0, "x": 1}],
    }
    out = cli._without_wall_times(report)
    assert out == {
        "analysis_lmi": {"gamma": 3.0},
        "nominal_step": {"lpv": {"settling_time_s": 227.0, "rise_time_s": 118.0}},
        "list": [{"x": 1}],
    }
