"""The solve-and-recheck driver: back-off, formulations tried in order, the notes it leaves."""

from __future__ import annotations

import numpy as np

from pressor.synthesis.certificates.working_set import (
    BackOff,
    Formulation,
    Steps,
    solve_and_recheck,
)


def _recheck(x: np.ndarray) -> tuple[bool, np.ndarray, np.ndarray]:
    # a one-number "certificate": every one of the 3 points has margin x[0]
    return bool(x[0] > 0), np.full(3, x[0]), np.ones(3)


def _steps(*formulations: Formulation, closing: tuple[str, ...] = ()) -> Steps:
    return Steps(
        formulations, _recheck, lambda x: (float(x[0]), np.eye(1), None), 2, closing_notes=closing
    )


def test_failed_back_off_keeps_the_first_solution_and_says_so() -> None:
    notes: list[str] = []
    back = BackOff(lambda _p, _x: True, lambda _p, _x: ("infeasible", None, "unused"))
    steps = _steps(Formulation(lambda _p: ("optimal", np.array([0.5])), back), closing=("end",))
    res = solve_and_recheck(steps, np.arange(3), None, 3, "affine", 0.0, notes, None)
    assert res.certified and res.status == "optimal" and res.gamma == 0.5
    assert res.n_lmis == 6
    assert notes == ["back-off solve ended infeasible; kept the first solution", "end"]


def test_successful_back_off_replaces_the_solution_with_its_note() -> None:
    notes: list[str] = []
    back = BackOff(lambda _p, x: x[0] < 1.0, lambda _p, _x: ("solved", np.array([2.0]), "moved"))
    steps = _steps(Formulation(lambda _p: ("optimal", np.array([0.5])), back))
    res = solve_and_recheck(steps, np.arange(3), None, 3, "affine", 0.0, notes, None)
    assert res.status == "solved" and res.gamma == 2.0 and notes == ["moved"]


def test_next_formulation_is_solved_only_when_the_first_does_not_certify() -> None:
    notes: list[str] = []
    calls: list[str] = []
    first = Formulation(
        lambda _p: ("optimal", np.array([-1.0])),
        if_not_certified=lambda status: calls.append(status),
        note_if_certified="first certified",
    )
    second = Formulation(lambda _p: ("optimal", np.array([1.0])), note_if_certified="never")
    res = solve_and_recheck(
        _steps(first, second), np.arange(3), None, 3, "affine", 0.0, notes, None
    )
    assert res.certified and res.gamma == 1.0
    assert calls == ["optimal"]
    assert notes == []  # the last formulation has no later one to name


def test_no_solution_reports_nan_margins_and_no_gamma() -> None:
    notes: list[str] = []
    steps = _steps(Formulation(lambda _p: ("infeasible", None)), closing=("end",))
    res = solve_and_recheck(steps, np.array([0]), 1, 3, "constant", 0.0, notes, None)
    assert not res.certified and res.gamma is None and res.status == "infeasible"
    assert np.all(np.isnan(res.margins)) and res.margins.shape == (3,)
    assert notes == []  # neither the working-set nor the closing notes without a solution


def test_working_set_grows_to_the_failing_points_and_is_noted() -> None:
    notes: list[str] = []
    # certified only once every point is imposed
    steps = _steps(Formulation(lambda p: ("optimal", np.array([len(p) - 2.5]))))
    res = solve_and_recheck(steps, np.array([1]), 1, 3, "affine", 0.0, notes, None)
    assert res.certified
    assert notes[-1] == "working set: LMI imposed at 3 of 3 points"
