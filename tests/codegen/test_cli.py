"""``pressor codegen`` refuses bad input with exit 2 and one line naming the problem."""

from __future__ import annotations

from pathlib import Path

import pytest

from pressor.codegen import pipeline as pl
from pressor.codegen.cli import main


def _run(capsys, argv: list[str]) -> tuple[int, list[str]]:
    rc = main("codegen", argv)
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    return rc, err


def test_missing_artifact_exits_2_naming_the_file(capsys, tmp_path):
    missing = tmp_path / "nope.npz"
    rc, err = _run(capsys, [str(missing), "--target", "python", "--out", str(tmp_path / "o")])
    assert rc == 2 and len(err) == 1 and "nope.npz" in err[0] and "not found" in err[0]


def test_corrupt_artifact_exits_2_naming_the_file(capsys, tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(pl.DEFAULT_ARTIFACT.read_bytes()[:300])
    rc, err = _run(capsys, [str(bad), "--target", "c", "--out", str(tmp_path / "o")])
    assert rc == 2 and len(err) == 1 and "bad.npz" in err[0]
    assert not (tmp_path / "o").exists()


def test_out_dir_under_a_regular_file_exits_2(capsys, tmp_path):
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    out = blocker / "sub"
    rc, err = _run(capsys, ["--target", "python", "--out", str(out)])
    assert rc == 2 and len(err) == 1 and "not a directory" in err[0] and "file.txt" in err[0]


@pytest.mark.parametrize("argv", [["--target", "rust", "--out", "x"], ["--out", "x"]])
def test_bad_usage_exits_2(capsys, argv):
    rc, _ = _run(capsys, argv)
    assert rc == 2


def test_up_to_date_output_is_skipped_without_regenerating(capsys, tmp_path):
    out = tmp_path / "gen"
    out.mkdir()
    committed = Path(pl.REPO_ROOT) / "runtime" / "generated" / "lpv_map_controller.py"
    (out / "lpv_map_controller.py").write_bytes(committed.read_bytes())
    rc = main("codegen", ["--target", "python", "--out", str(out)])
    assert rc == 0 and "unchanged" in capsys.readouterr().out
