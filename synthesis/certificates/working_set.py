"""Working-set solves: impose an analysis LMI at a few spread points, re-check all, add failures.

Clarabel's cost grows with the number of PSD blocks; on the shipped design the synthesis-node
count (27) of spread points already certifies all 125. The certificate is the floating-point
re-check of every point and rate vertex either way.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = ["Recheck", "first_points", "grow_working_set"]

Array = NDArray[np.float64]


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


Recheck = tuple[bool, Array, Array]


def grow_working_set(
    points: NDArray[np.int64],
    working_set: int | None,
    solve: Callable[[NDArray[np.int64]], tuple[str, Array | None]],
    recheck: Callable[[Array], Recheck],
    notes: list[str],
    progress: Callable[[str], None] | None,
    n_vertices: int,
    stop_if_imposed_fails: bool = False,
) -> tuple[str, Array | None, NDArray[np.int64], Recheck]:
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
