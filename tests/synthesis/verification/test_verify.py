"""Independent verification: dense grid, CLI input errors, and (slow) the shipped design end to end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pressor.synthesis.problem.closed_loop import close_loop
from pressor.synthesis.verification.delay_stability import spectral_abscissa
from pressor.synthesis.verification.pi_baseline import PIBaseline
from pressor.synthesis.verification.verify import dense_axes
from pressor.synthesis.verify_cli import DEFAULT_ARTIFACT, main

STEP_NAMES = ("overshoot_pct", "rise_time_s", "settling_time_s", "steady_state_dev_mmhg")


def test_dense_grid_doubles_each_axis_and_contains_every_cell_midpoint() -> None:
    grid = (np.array([0.25, 0.625, 1.0]), np.array([100.0, 200.0]), np.array([10.0, 27.5, 45.0]))
    axes = dense_axes(grid, 2)
    assert [len(a) for a in axes] == [5, 3, 5]
    for g, a in zip(grid, axes, strict=True):
        mids = 0.5 * (g[:-1] + g[1:])
        assert np.all(np.isin(np.round(mids, 9), np.round(a, 9)))
        assert np.all(np.isin(np.round(g, 9), np.round(a, 9)))


def test_odd_density_still_includes_the_midpoints() -> None:
    (axis,) = dense_axes((np.array([0.0, 1.0]),), 3)
    assert np.allclose(axis, [0.0, 1 / 3, 0.5, 2 / 3, 1.0])


def test_density_below_two_is_rejected() -> None:
    with pytest.raises(ValueError, match="density"):
        dense_axes((np.array([0.0, 1.0]),), 1)


def test_pi_written_as_output_feedback_closes_the_same_loop_as_the_plain_pi() -> None:
    # the LPV closed-loop builder with the PI in the controller interface, on a filter-free plant
    class Plant:
        A = np.array([[-1 / 150.0, 0.0], [-1.0, 0.0]])
        Ad = np.array([[0.0, 0.0], [0.0, 0.0]])
        B1 = np.array([[1 / 150.0], [0.0]])
        B2 = np.array([[0.0], [0.0]])
        C1 = np.array([[1.0, 0.0]])
        C1d = np.zeros((1, 2))
        C2 = np.array([[-1.0, 0.0], [0.0, 1.0]])
        C2d = np.zeros((2, 2))
        D11 = np.zeros((1, 1))
        D12 = np.zeros((1, 1))
        D21 = np.zeros((2, 1))

    # the plant input is delayed: write K/T u(t - tau) as a delayed state feedback
    plant = Plant()
    plant.C2d = np.array([[-1.0, 0.0], [0.0, 1.0]])
    plant.C2 = np.zeros((2, 2))
    plant.B2 = np.array([[0.55 / 150.0], [0.0]])
    cl = close_loop(plant, PIBaseline().as_output_feedback(), 40.0)
    ref = PIBaseline().closed_loop(0.55, 150.0, 40.0)
    assert np.allclose(cl.A, ref.A) and np.allclose(cl.Ad, ref.Ad)
    assert spectral_abscissa(cl.A, cl.Ad, cl.tau) < 0.0


def test_cli_missing_artifact_exits_2_naming_the_file(tmp_path: Path, capsys) -> None:
    missing = tmp_path / "nope.npz"
    assert main("verify", [str(missing)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope.npz" in err[0]


def test_cli_corrupt_artifact_exits_2(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"this is not an npz archive")
    assert main("verify", [str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.npz" in err[0]


def test_cli_truncated_shipped_artifact_exits_2(tmp_path: Path, capsys) -> None:
    data = DEFAULT_ARTIFACT.read_bytes()
    cut = tmp_path / "cut.npz"
    cut.write_bytes(data[: len(data) // 2])
    assert main("verify", [str(cut)]) == 2
    assert "cut.npz" in capsys.readouterr().err


def test_cli_density_out_of_range_exits_2(capsys) -> None:
    assert main("verify", ["--density", "1"]) == 2
    assert "--density" in capsys.readouterr().err


@pytest.mark.slow
def test_shipped_design_report_has_step_metrics_for_lpv_pi_and_smith(tmp_path: Path) -> None:
    out = tmp_path / "verify.json"
    code = main("verify", ["--json", str(out), "--p-dependence", "constant"])
    report = json.loads(out.read_text())
    assert code == (0 if report["passed"] else 1)
    for name in ("lpv", "pi", "smith"):
        for key in STEP_NAMES:
            assert key in report["nominal_step"][name]
    assert report["nominal_step"]["smith"]["settling_time_s"] == pytest.approx(277.0, abs=1.0)
    # the shipped two-degree-of-freedom structure: the paper's claim and the Smith bar both hold
    lpv = report["nominal_step"]["lpv"]
    assert lpv["overshoot_pct"] < 1.0 and lpv["settling_time_s"] < 200.0
    assert report["paper_claim"]["holds"] is True
    assert report["paper_claim"]["settles_before_smith"] is True
    pi = report["nominal_step"]["pi"]
    assert pi["rise_time_s"] == pytest.approx(109.5, abs=1.0)
    assert pi["settling_time_s"] == pytest.approx(418.8, abs=1.0)
    assert report["grid"]["n_points_unseen_by_synthesis"] > 0
    assert report["delay_stability"]["stable"] is True


def test_shipped_artifact_embeds_a_passing_report_with_quadratic_p_on_unseen_points() -> None:
    from pressor.synthesis.artifact import default_artifact_path, load_artifact

    art = load_artifact(default_artifact_path())
    rep = art.metadata["verification"]
    assert rep["passed"] is True
    lmi = rep["analysis_lmi"]
    assert lmi["certified"] is True and lmi["n_failed_points"] == 0 and lmi["min_margin"] > 0
    assert lmi["p_dependence"] == "quadratic"
    assert rep["grid"]["n_points_unseen_by_synthesis"] > 0
    assert rep["delay_stability"]["stable"] is True


@pytest.mark.slow
def test_shipped_design_passes_the_default_verification_from_scratch(
    tmp_path: Path, capsys
) -> None:
    out = tmp_path / "verify.json"
    assert main("verify", ["--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["analysis_lmi"]["certified"] is True
    assert report["analysis_lmi"]["n_failed_points"] == 0
    # every dense point at every vertex was re-checked: the K, T, tau rate vertices (8) times both
    # ends of the delay ratio K(t)/K(t - tau) of the K-scaled certificate (2)
    assert report["analysis_lmi"]["n_lmis"] == report["grid"]["n_points"] * 16
    # the analysis solve reports its iterations on stderr while it runs
    err = capsys.readouterr().err.splitlines()
    assert sum("LMI" in ln and " iter " in ln and "gap" in ln for ln in err) >= 5


@pytest.mark.parametrize("name", ["cautious", "norepinephrine_cautious"])
def test_each_log_k_design_embeds_a_passing_verification_of_its_whole_box(name: str) -> None:
    from pressor.synthesis.artifact import default_artifact_path, load_artifact

    art = load_artifact(default_artifact_path().parent / f"{name}_design.npz")
    rep = art.metadata["verification"]
    assert rep["passed"] is True and rep["delay_stability"]["stable"] is True
    lmi = rep["analysis_lmi"]
    assert lmi["certified"] is True and lmi["n_failed_points"] == 0 and lmi["min_margin"] > 0
    # the dense grid reaches the box's ends: its K spans the whole certified range, >= 100x
    (k_lo, k_hi) = (float(v) for v in art.box[0])
    k_axis = rep["grid"]["axes"][0]
    assert (k_axis[0], k_axis[-1]) == (k_lo, k_hi) and k_hi / k_lo >= 100.0
    assert art.model_config.k_rate_relative is True
