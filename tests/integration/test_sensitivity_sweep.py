"""The responsiveness sweep (benchmarks/sensitivity_sweep.py) on a tiny cohort: each level in the
table, the 10× records scaled, the 1× records ``pressor trial``'s bytes, a second run reusing the
first's files; its per-row figures against hand-computed values."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.sensitivity_sweep import figures, level_rows, main
from pressor.hil_sim.cli import main as pressor_main


def _record(reachable: bool, stable: bool, mdpe: float, in_band: float | None, os_: float) -> dict:
    return {
        "reachable": reachable,
        "stable": stable,
        "mdpe_pct": mdpe,
        "mdape_pct": abs(mdpe),
        "wobble_pct": 1.0,
        "time_in_band_pct": in_band,
        "step_overshoot_pct": os_,
    }


def test_a_level_has_a_row_for_its_reachable_and_one_for_its_unreachable_patients():
    records = [
        _record(True, True, -2.0, None, 0.0),
        _record(True, False, 4.0, 90.0, 10.0),
        _record(True, True, 10.0, 100.0, 20.0),
        _record(False, False, -30.0, None, 0.0),
    ]
    fig = figures(records[:3])
    assert (fig["patients"], fig["unstable"]) == (3, 1)
    assert fig["mdpe_pct"] == 4.0 and fig["mdape_pct"] == 4.0 and fig["wobble_pct"] == 1.0
    assert fig["time_in_band_pct"] == 90.0  # 0 (never within 5 mmHg), 90, 100
    assert fig["overshoot_pct"] == 10.0
    assert fig["overshoot_p90_pct"] == pytest.approx(18.0)  # 10 + 0.8 × 10, linear
    assert level_rows(0.5, "pi", records) == [
        "| 0.5× | pi | 3 reachable | 1 | 4.00 | 4.00 | 1.00 | 90.0 | 10.0 / 18.0 |",
        "| 0.5× | pi | 1 unreachable | 1 | -30.00 | 30.00 | 1.00 | 0.0 | 0.0 / 0.0 |",
    ]
    assert level_rows(2.0, "lpv", records[:1]) == [
        "| 2× | lpv | 1 reachable | 0 | -2.00 | 2.00 | 1.00 | 0.0 | 0.0 / 0.0 |"
    ]


def test_the_sweep_prints_each_level_scales_k_at_10x_and_reuses_what_it_wrote(
    tmp_path: Path, short_scenario: Path, capsys
):
    scenario = short_scenario
    out = tmp_path / "sweep"
    argv = ["--patients", "2", "--seed", "1", "--levels", "1,10", "--controllers", "pi"]
    argv += ["--scenario", str(scenario), "--out", str(out)]
    assert main(argv) == 0
    first = capsys.readouterr()
    rows = [line.split(" | ")[:3] for line in first.out.splitlines() if line.startswith("| 1")]
    # Patient 1000000 (k0 0.288, k1 0.00472) holds at most k0/(k1·e) = 22.4 mmHg at any rate,
    # short of the 20 + 10 mmHg (step, haemorrhage) asked, at every level; 1000001 (k0 0.978)
    # holds 76.8 mmHg at 120 ml/h.
    assert rows == [
        ["| 1×", "pi", "1 reachable"],
        ["| 1×", "pi", "1 unreachable"],
        ["| 10×", "pi", "1 reachable"],
        ["| 10×", "pi", "1 unreachable"],
    ]
    assert "x10 pi: 2/2 patients" in first.err

    for r in json.loads((out / "x10" / "pi" / "patients.json").read_text()):
        assert r["coefficients"]["sensitivity_factor"] == 10.0
        k0 = r["coefficients"]["k0"]  # K starts at the model's k0 and only falls
        assert r["schedule_range"]["K_mmhg_per_ml_h"][1] == pytest.approx(10.0 * k0, rel=1e-6)

    plain = tmp_path / "plain"
    trial = ["--controller", "pi", "--patients", "2", "--seed", "1", "--scenario", str(scenario)]
    assert pressor_main("trial", [*trial, "--schedule", "estimated", "--out", str(plain)]) == 0
    capsys.readouterr()
    for f in ("patients.json", "patients.csv", "summary.json"):
        assert (out / "x1" / "pi" / f).read_bytes() == (plain / f).read_bytes(), f

    assert main(argv) == 0
    again = capsys.readouterr()
    assert "x1 pi: reused" in again.err and "x10 pi: reused" in again.err
    assert "/2 patients" not in again.err  # nothing ran again
    assert again.out == first.out


def test_the_sweep_refuses_a_level_outside_the_range(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--levels", "0.1,30"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "'30'" in err and "[0.05, 20]" in err
