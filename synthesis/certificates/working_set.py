"""The solve-and-recheck driver of every analysis LMI, and its working set.

An analysis (:mod:`pressor.synthesis.certificates.jensen.analysis`,
:mod:`pressor.synthesis.certificates.wirtinger.analysis`) supplies its own steps (:class:`Steps`: how to
build and solve its conic problem at a set of points, optionally back off from the boundary, and
re-check a solution at every point and rate vertex in floating point); :func:`solve_and_recheck`
runs them: solve, back off if asked, re-check, grow the working set, try the next formulation if
one is left and this one did not certify, and return the :class:`AnalysisResult`.

Working set: impose the LMI at a few spread points, re-check all, add failures. Clarabel's cost
grows with the number of PSD blocks; on the shipped design the synthesis-node count (27) of spread
points already certifies all 125. The certificate is the floating-point re-check of every point and
rate vertex either way.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pressor.synthesis.certificates.interface import AnalysisResult

__all__ = [
    "BackOff",
    "Formulation",
    "Recheck",
    "Solution",
    "Steps",
    "first_points",
    "grow_working_set",
    "solve_and_recheck",
]

Array = NDArray[np.float64]
Points = NDArray[np.int64]
#: (certified, margins (m,), smallest eigenvalue of each P(rho_k) (m,)) at EVERY point and vertex
Recheck = tuple[bool, Array, Array]
#: what a certified-or-not solution reports: (gamma, P0 in the original coordinates, the
#: certificate's matrices or None)
Solution = tuple[float, Array, dict[str, Any] | None]


@dataclass(frozen=True)
class BackOff:
    """A second solve that moves a boundary optimum inward (a few percent more gamma).

    Attributes
    ----------
    needed
        ``needed(points, x)``: whether the optimum ``x`` at the imposed ``points`` needs it.
    solve
        ``solve(points, x)`` -> (status, decision vector or None, the note that records it).
    """

    needed: Callable[[Points, Array], bool]
    solve: Callable[[Points, Array], tuple[str, Array | None, str]]


@dataclass(frozen=True)
class Formulation:
    """One conic form of a certificate's LMIs, solved on a working set.

    Attributes
    ----------
    solve
        ``solve(points)`` -> (status, decision vector or None) with the LMI imposed at ``points``:
        the first solve of a round (minimum gamma, or feasibility at a gamma cap).
    back_off
        Applied after ``solve`` when set (None: the first solution is the round's).
    if_not_certified
        Called with the final status when this form did not certify and another one follows.
    note_if_certified
        Appended to the notes when this form certified and another one would have followed.
    """

    solve: Callable[[Points], tuple[str, Array | None]]
    back_off: BackOff | None = None
    if_not_certified: Callable[[str], None] | None = None
    note_if_certified: str | None = None


@dataclass(frozen=True)
class Steps:
    """What one certificate supplies to :func:`solve_and_recheck`.

    Attributes
    ----------
    formulations
        Tried in order until one certifies (the last one's outcome is kept otherwise).
    recheck
        ``recheck(x)``: the verdict at EVERY point and rate vertex (:data:`Recheck`).
    solution
        ``solution(x)``: what the solved certificate reports (:data:`Solution`).
    n_vertices
        Rate vertices per point (re-checked LMIs = points x vertices).
    stop_if_imposed_fails
        Stop growing the working set when an imposed point fails the re-check (see
        :func:`grow_working_set`).
    closing_notes
        Appended after the working-set note when a solution was found.
    """

    formulations: Sequence[Formulation]
    recheck: Callable[[Array], Recheck]
    solution: Callable[[Array], Solution]
    n_vertices: int
    stop_if_imposed_fails: bool = False
    closing_notes: tuple[str, ...] = ()


def solve_and_recheck(
    steps: Steps,
    points: Points,
    working_set: int | None,
    n_points: int,
    p_dependence: str,
    t_start: float,
    notes: list[str],
    progress: Callable[[str], None] | None,
) -> AnalysisResult:
    """Solve a certificate's LMIs on a growing working set until its re-check passes.

    Each formulation of ``steps`` in turn: per round, solve at the imposed points, back off if
    the formulation asks for it (keeping the first solution, with a note, if the back-off solve
    fails), re-check every point and vertex, add failing points (:func:`grow_working_set`); stop
    at the first formulation that certifies.

    Parameters
    ----------
    steps
        The certificate's own build, solve, re-check and report steps.
    points
        The first working set (:func:`first_points`).
    working_set
        As for :func:`grow_working_set`.
    n_points
        Number m of grid points.
    p_dependence
        Reported in the result.
    t_start
        ``time.perf_counter()`` at the start of the analysis (``solve_time_s`` counts from it).
    notes
        The analysis' notes, appended to here and returned in the result.
    progress
        Called with a short message per round.

    Returns
    -------
    AnalysisResult
        ``certified`` is the last re-check's verdict; without any solution gamma is None and the
        margins and P eigenvalues are NaN.
    """

    def solve_round(formulation: Formulation, pts: Points) -> tuple[str, Array | None]:
        status, xv = formulation.solve(pts)
        back_off = formulation.back_off
        if xv is None or back_off is None or not back_off.needed(pts, xv):
            return status, xv
        status2, xb, note = back_off.solve(pts, xv)
        if xb is None:
            notes.append(f"back-off solve ended {status2}; kept the first solution")
            return status, xv
        notes.append(note)
        return status2, xb

    last = len(steps.formulations) - 1
    for k, formulation in enumerate(steps.formulations):
        status, xv, points, (certified, margins, p_min) = grow_working_set(
            points,
            working_set,
            lambda pts, f=formulation: solve_round(f, pts),
            steps.recheck,
            notes,
            progress,
            steps.n_vertices,
            steps.stop_if_imposed_fails,
        )
        if certified:
            if k < last and formulation.note_if_certified:
                notes.append(formulation.note_if_certified)
            break
        if k < last and formulation.if_not_certified:
            formulation.if_not_certified(status)
    elapsed = time.perf_counter() - t_start
    n_lmis = n_points * steps.n_vertices
    if xv is None:
        nan = np.full(n_points, np.nan)
        return AnalysisResult(False, status, None, nan, nan, n_lmis, elapsed, p_dependence, notes)
    if working_set is not None:
        notes.append(f"working set: LMI imposed at {len(points)} of {n_points} points")
    notes.extend(steps.closing_notes)
    gamma, p0_phys, certificate = steps.solution(xv)
    return AnalysisResult(
        certified,
        status,
        gamma,
        margins,
        p_min,
        n_lmis,
        elapsed,
        p_dependence,
        notes,
        p0_phys,
        certificate,
    )


def first_points(rho_hat: Array, working_set: int | None) -> NDArray[np.int64]:
    """The points of the first solve: every point (``working_set=None``) or the first k of
    :func:`_spread_order`, sorted.

    Raises
    ------
    ValueError
        ``working_set`` not None and below 1.
    """
    if working_set is not None and int(working_set) < 1:
        raise ValueError(f"working_set={working_set!r} must be None or an integer >= 1")
    m = rho_hat.shape[0]
    return (
        np.arange(m) if working_set is None else np.sort(_spread_order(rho_hat)[: int(working_set)])
    )


def grow_working_set(
    points: Points,
    working_set: int | None,
    solve: Callable[[Points], tuple[str, Array | None]],
    recheck: Callable[[Array], Recheck],
    notes: list[str],
    progress: Callable[[str], None] | None,
    n_vertices: int,
    stop_if_imposed_fails: bool = False,
) -> tuple[str, Array | None, Points, Recheck]:
    """Solve with the LMI imposed at ``points``, re-check every point, add failing ones, repeat.

    ``solve(points)`` returns (status, decision vector or None); ``recheck(x)`` returns
    (certified, margins (m,), P eigenvalue minima) at EVERY point and rate vertex. Up to
    ``working_set`` failing points (the worst first; all of them when None) are added per round,
    until the re-check passes, every point is imposed, or no failing point is left to add.
    ``stop_if_imposed_fails``: also stop when an imposed point fails (sound for a feasibility
    form with a fixed gamma cap: a larger set of points cannot be feasible when a subset is not).

    Returns
    -------
    tuple
        (status, x or None, the points imposed last, the last re-check (False, nan, nan if none)).
    """
    checked: Recheck = (False, np.array([np.nan]), np.array([np.nan]))
    while True:
        status, xv = solve(points)
        if xv is None:
            return status, xv, points, checked
        checked = recheck(xv)
        certified, margins, _ = checked
        m = len(margins)
        failing = np.flatnonzero(~(margins > 0))
        new = np.setdiff1d(failing[np.argsort(margins[failing], kind="stable")], points)
        imposed_fail = np.intersect1d(failing, points)
        if certified or len(points) == m or len(new) == 0:
            return status, xv, points, checked
        if stop_if_imposed_fails and len(imposed_fail):
            notes.append(
                f"{len(imposed_fail)} of the {len(points)} imposed points failed the re-check: "
                "not certifiable at this gamma cap, no points added"
            )
            return status, xv, points, checked
        add = new if working_set is None else new[: int(working_set)]
        if progress:
            progress(
                f"analysis LMI: re-check of all {m} points x {n_vertices} vertices: "
                f"{len(failing)} fail; adding {len(add)} points"
            )
        notes.append(f"working set {len(points)} points: {len(failing)} failed the re-check")
        points = np.union1d(points, add)


def _spread_order(rho_hat: Array) -> NDArray[np.int64]:
    """Points in farthest-point order, starting from the one nearest the centre (deterministic):
    any prefix is spread evenly over the grid."""
    m = rho_hat.shape[0]
    first = int(np.argmin(np.sum(rho_hat**2, axis=1)))
    order = [first]
    dist = np.sum((rho_hat - rho_hat[first]) ** 2, axis=1)
    for _ in range(m - 1):
        nxt = int(np.argmax(dist))  # ties: lowest index
        order.append(nxt)
        dist = np.minimum(dist, np.sum((rho_hat - rho_hat[nxt]) ** 2, axis=1))
    return np.array(order, dtype=np.int64)
