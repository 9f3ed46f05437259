"""What a dose limit can hold: the patient's best MAP over the scenario against what the target asks.

:meth:`pressor.hil_sim.world.World.reachable` compares the largest rise the target asks with the
*steady state* of the largest rate. That is what the paper's first-order patients reach within
minutes, but not what an hour gives a patient whose response keeps drifting: a peripheral
compartment that fills for hours (the PK/PD phenylephrine models: the plasma level at a constant
rate reaches about half its steady state in minutes and creeps up over hours) or tolerance that
builds with exposure (the ``pkpd`` model's tachyphylaxis). Counted on the steady state, such a
patient is "reachable" at a rate the hour never lets them settle at, reaches the target and falls
out of it again at the limit: measured on the sweep's ``pkpd`` 0.5x patients, 84 of the 102 the
steady state counted as reachable had their dose cut by the hourly limit, and their time in
the band after the first entry was 54 % (docs/notes/cautious-start.md, "Who the library's
limits can hold").

This module asks the question by simulation instead: a fresh copy of the patient, infused from
the first second at the constant rate that holds the largest steady rise the limit allows
(:func:`best_rate_ml_h`; the limit itself for a model whose effect rises with the rate), gives the
largest rise the limit can hold at each moment, :func:`capacity_mmhg`. For linear kinetics and an
effect that rises with the level, no rate history under the limit raises the level above that
run's. The patient is held when that capacity, once it first reaches the target's ask (within
the band), stays there for the rest of the scenario (:func:`hold_shortfall_mmhg`). The run uses
:data:`CAPACITY_STEP_S` steps, a tenth or less of the shipped models' lags (the shortest,
norepinephrine's effect site at 10 s, that model integrates exactly over a held step), so a 1 h
scenario costs about 20 ms per patient.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pressor.hil_sim.patients.patient_model import PatientModel
    from pressor.hil_sim.world import World

__all__ = [
    "CAPACITY_STEP_S",
    "best_rate_ml_h",
    "capacity_mmhg",
    "hold_shortfall_mmhg",
    "holds",
]

#: step (s) of the capacity run: the shipped models' lags are 10 s or more (docs/PATIENTS.md)
CAPACITY_STEP_S = 1.0
#: bisection steps of :func:`best_rate_ml_h` (the rate to 2^-40 of the limit)
_BISECTIONS = 40


def best_rate_ml_h(patient: PatientModel, max_rate_ml_h: float) -> float:
    """The smallest rate (ml/h) in [0, ``max_rate_ml_h``] whose steady state is the largest the
    limit allows: ``max_rate_ml_h`` for an effect that rises with the rate; below it for the
    paper model, whose gain falls with the rate (k0·i·e^(−k1·i) peaks at i = 1/k1).

    :meth:`~pressor.hil_sim.patients.patient_model.PatientModel.max_delta_map_mmhg` is the largest
    steady rise over [0, r], so it rises with r and the bisection finds where it stops rising.
    """
    best = patient.max_delta_map_mmhg(max_rate_ml_h)
    lo, hi = 0.0, float(max_rate_ml_h)
    if patient.max_delta_map_mmhg(hi * (1.0 - 1e-9)) < best:
        return hi
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if patient.max_delta_map_mmhg(mid) < best else (lo, mid)
    return hi


def capacity_mmhg(world: World, rate_ml_h: float) -> tuple[np.ndarray, np.ndarray]:
    """``(t_s, rise_mmhg)``: the drug's MAP rise at each second of ``world``'s scenario on a fresh
    copy of its patient infused at ``rate_ml_h`` (ml/h) from t = 0 (no noise, no disturbance)."""
    patient = world.fresh_patient(CAPACITY_STEP_S)
    t = np.arange(0.0, world.scenario.duration_s + CAPACITY_STEP_S, CAPACITY_STEP_S)
    rise = np.empty_like(t)
    for i in range(t.size):
        rise[i] = patient.delta_map_mmhg
        patient.step(rate_ml_h)
    return t, rise


def hold_shortfall_mmhg(world: World, max_rate_ml_h: float) -> float:
    """How far (mmHg) the best the limit can do falls short of the target's ask, at worst.

    From the first moment the capacity (:func:`capacity_mmhg` at :func:`best_rate_ml_h`) comes
    within the band of the ask (or, if it never does, from its peak) to the scenario's end: the
    largest ask minus capacity. At most the band for a patient the limit holds (it is close to the
    band then: the capacity enters it from outside), more for one it does not.
    """
    band = world.band_mmhg()
    t, rise = capacity_mmhg(world, best_rate_ml_h(world.patient, max_rate_ml_h))
    gap = world.need_mmhg(t) - rise
    inside = gap <= band
    start = int(np.argmax(inside)) if inside.any() else int(np.argmax(rise))
    return float(gap[start:].max())


def holds(world: World, max_rate_ml_h: float) -> bool:
    """Whether ``max_rate_ml_h`` (ml/h) holds ``world``'s patient within the metrics' band of the
    target for the rest of the scenario once it got there (:func:`hold_shortfall_mmhg`)."""
    return hold_shortfall_mmhg(world, max_rate_ml_h) <= world.band_mmhg()
