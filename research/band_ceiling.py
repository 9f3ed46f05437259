"""How much of the time out of the band after the disturbances any vasopressor controller could avoid.

Two replays of a run's patient on the rates its pump delivered, each from a disturbance's start:

* **the haemorrhage, with the pump at its best**: from the haemorrhage's start the rate whose
  steady rise is the largest the pump allows (:func:`pressor.hil_sim.reach.best_rate_ml_h`: the
  pump's maximum for an effect that rises with the dose). For linear kinetics and an effect that
  rises with the level no rate history from there gives a higher MAP (the counter-regulation of
  the PK/PD models takes back less than half of a sustained effect, over minutes, so it cannot
  undo a lead), so its time below target - 5 mmHg until the bolus is a floor;
* **the bolus, with the pump stopped**: a vasopressor can only stop, and the drug already given
  decays on its own, so no rate history from the bolus's start gives a lower MAP, and its time
  above target + 5 mmHg from there is a floor.

Each floor holds for every controller that arrived at that disturbance with the run's history.
``ceiling`` is then the most time in ±5 mmHg after the first entry such a controller could have:
100 % minus the two floors (every other second out of the band counted as avoidable).

Usage::

    python -m research.band_ceiling --patient-model norepinephrine --sensitivity 1 \\
        --patients 20 --seed 3

Printed per patient that entered the band before the bolus: whether the pump's maximum can hold
it at the target for the hour (:func:`pressor.hil_sim.reach.holds`; one it cannot spends the
haemorrhage below the band whatever the controller), the measured time in band after the first
entry, the ceiling, and the two floors; then the medians over the patients the pump holds.
Measured in docs/notes/cautious-start.md, "Time in the band: what the disturbances leave".
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass

import numpy as np

from pressor.api import SimulationResult, simulate
from pressor.contracts.metrics.names import CLINICAL_BAND_MMHG
from pressor.hil_sim.patients.cohort import cohort_seeds
from pressor.hil_sim.patients.sensitivity import with_sensitivity
from pressor.hil_sim.reach import best_rate_ml_h, holds
from pressor.hil_sim.scenarios.scenario import load_scenario
from pressor.hil_sim.world import World

SCENARIO = "paper-disturbance"


@dataclass(frozen=True)
class Ceiling:
    """One patient's figures (% of the time from the first entry into ±5 mmHg to the run's end).

    Attributes
    ----------
    in_band_pct
        Measured time in ±5 mmHg (true MAP).
    ceiling_pct
        The most any controller with the same history to each disturbance could have.
    below_floor_s
        The least time (s) below target - 5 mmHg from the haemorrhage's start to the bolus's.
    above_floor_s
        The least time (s) above target + 5 mmHg after the bolus's start.
    replay_error_mmhg
        Largest difference between a replay and the run's true MAP before its disturbance (0
        when the replay is the run's patient).
    """

    in_band_pct: float
    ceiling_pct: float
    below_floor_s: float
    above_floor_s: float
    replay_error_mmhg: float


def replayed(run: SimulationResult, model: str, from_s: float, rate_ml_h: float) -> np.ndarray:
    """The run's patient replayed on its delivered rates (ml/h) until ``from_s`` (s), then at the
    constant ``rate_ml_h``: true MAP (mmHg) at each tick, disturbances included, no monitor noise."""
    tr = run.trajectory
    t = np.asarray(tr.t_s)
    world = World(run.scenario, run.patient_seed, float(t[1] - t[0]), patient_model=model)
    patient = world.fresh_patient(world.sample_period_s)
    out = np.empty_like(t)
    for i, (now, rate) in enumerate(zip(t, tr.delivered_ml_h, strict=True)):
        out[i] = world.baseline_mmhg + patient.delta_map_mmhg + world.disturbance(now)
        patient.step(float(rate) if now < from_s - 1e-9 else rate_ml_h)
    return out


def best_rate_of(run: SimulationResult, model: str) -> float:
    """The rate (ml/h) whose steady rise is the largest the run's pump allows, for its patient."""
    world = World(run.scenario, run.patient_seed, 1.0, patient_model=model)
    return best_rate_ml_h(world.patient, load_scenario(run.scenario).pump.max_rate_ml_h)


def ceiling(
    run: SimulationResult, model: str, hemorrhage_s: float, bolus_s: float
) -> Ceiling | None:
    """:class:`Ceiling` of ``run`` (``model``: its patient model, sensitivity included; the
    disturbances start at ``hemorrhage_s`` and ``bolus_s``, s); None when MAP did not enter
    ±5 mmHg before the bolus."""
    # the run's own arrival metrics (docs/METRICS.md, "after arrival"): the time to ±5 mmHg from
    # the step and the time in the band from there
    to_band_s = run.record["time_to_band_s"]
    step_s = load_scenario(run.scenario).step_time_s
    if to_band_s is None or step_s + to_band_s >= bolus_s:
        return None
    tr = run.trajectory
    t = np.asarray(tr.t_s)
    target = np.asarray(tr.target_mmhg)
    y = np.asarray(tr.map_true_mmhg)
    first = int(np.searchsorted(t, step_s + to_band_s - 1e-9))
    after_entry = np.arange(t.size) >= first
    pumped = replayed(run, model, hemorrhage_s, best_rate_of(run, model))
    stopped = replayed(run, model, bolus_s, 0.0)
    before_bleeding, before_bolus = t < hemorrhage_s - 1e-9, t < bolus_s - 1e-9
    below = (pumped - target < -CLINICAL_BAND_MMHG) & ~before_bleeding & before_bolus & after_entry
    above = (stopped - target > CLINICAL_BAND_MMHG) & ~before_bolus
    dt = float(t[1] - t[0])
    error = max(
        np.max(np.abs(pumped - y)[before_bleeding]), np.max(np.abs(stopped - y)[before_bolus])
    )
    return Ceiling(
        in_band_pct=float(run.record["time_in_band_pct"]),
        ceiling_pct=float(100.0 * (1.0 - np.count_nonzero(below | above) / (t.size - first))),
        below_floor_s=float(np.count_nonzero(below) * dt),
        above_floor_s=float(np.count_nonzero(above) * dt),
        replay_error_mmhg=float(error),
    )


def main(argv: list[str] | None = None) -> int:
    """Print each patient's :class:`Ceiling` and the medians (module docstring)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--patient-model", default="norepinephrine", help="default: norepinephrine")
    p.add_argument("--sensitivity", type=float, default=1.0, help="× the model's (default 1)")
    p.add_argument("--controller", default=None, help="default: the drug's cautious design")
    p.add_argument("--patients", type=int, default=20, help="default: 20")
    p.add_argument("--seed", type=int, default=3, help="cohort seed (default 3)")
    a = p.parse_args(argv)
    starts = {d.kind: d.start_s for d in load_scenario(SCENARIO).disturbances}
    model = with_sensitivity(a.patient_model, a.sensitivity)
    pump_max_ml_h = load_scenario(SCENARIO).pump.max_rate_ml_h
    rows = []
    for seed in cohort_seeds(a.seed, a.patients):
        run = simulate(a.controller, SCENARIO, seed, patient_model=a.patient_model,
                       sensitivity=a.sensitivity)  # fmt: skip
        c = ceiling(run, model, starts["hemorrhage"], starts["bolus"])
        if c is None:
            print(f"{seed}: not in the band before the bolus")
            continue
        held = holds(World(SCENARIO, seed, 1.0, patient_model=model), pump_max_ml_h)
        if held:
            rows.append(c)
        print(
            f"{seed}: {'held' if held else 'not held'}, in band {c.in_band_pct:5.1f} %,"
            f" at most {c.ceiling_pct:5.1f} % (below -5 mmHg in the haemorrhage at least"
            f" {c.below_floor_s:.0f} s, above +5 mmHg after the bolus at least"
            f" {c.above_floor_s:.0f} s)",
            flush=True,
        )
    if rows:
        print(
            f"{a.patient_model} {a.sensitivity:g}x, {len(rows)} patients the pump holds: median"
            f" in band {np.median([r.in_band_pct for r in rows]):.1f} %, median ceiling"
            f" {np.median([r.ceiling_pct for r in rows]):.1f} % (lowest"
            f" {min(r.ceiling_pct for r in rows):.1f} %)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
