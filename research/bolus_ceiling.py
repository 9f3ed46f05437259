"""How much of the time out of the band after a fluid bolus any vasopressor controller could avoid.

A vasopressor can only stop. Replaying a run's patient with the rates the pump delivered up to the
bolus's start, then with the pump stopped, gives the lowest MAP any rate history from there could
give (the shipped models' effect rises with the drug, and the drug already given decays on its
own), so its time above target + 5 mmHg after the bolus is a floor for every controller that
arrived at the bolus with the same history. ``ceiling`` is then the most time in ±5 mmHg after the
first entry such a controller could have: 100 % minus that floor (every other minute out of the
band counted as avoidable).

Usage::

    python -m research.bolus_ceiling --patient-model norepinephrine --sensitivity 1 \\
        --patients 20 --seed 3

Printed per patient that entered the band before the bolus: the measured time in band after the
first entry, the ceiling, and the floor of the time above + 5 mmHg; then the medians. Measured in
docs/notes/cautious-start.md, "Time in the band: what the bolus leaves".
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
        The most any controller with the same history to the bolus could have.
    above_floor_s
        The least time (s) above target + 5 mmHg after the bolus's start.
    replay_error_mmhg
        Largest difference between the replay and the run's true MAP before the bolus (0 when
        the replay is the run's patient).
    """

    in_band_pct: float
    ceiling_pct: float
    above_floor_s: float
    replay_error_mmhg: float


def stopped_at(run: SimulationResult, model: str, stop_s: float) -> np.ndarray:
    """The run's patient replayed on its delivered rates (ml/h) until ``stop_s`` (s), then with the
    pump stopped: true MAP (mmHg) at each tick, disturbances included, no monitor noise."""
    tr = run.trajectory
    t = np.asarray(tr.t_s)
    world = World(run.scenario, run.patient_seed, float(t[1] - t[0]), patient_model=model)
    patient = world.fresh_patient(world.sample_period_s)
    out = np.empty_like(t)
    for i, (now, rate) in enumerate(zip(t, tr.delivered_ml_h, strict=True)):
        out[i] = world.baseline_mmhg + patient.delta_map_mmhg + world.disturbance(now)
        patient.step(float(rate) if now < stop_s - 1e-9 else 0.0)
    return out


def ceiling(run: SimulationResult, model: str, bolus_s: float) -> Ceiling | None:
    """:class:`Ceiling` of ``run`` (``model``: its patient model, sensitivity included); None when
    MAP did not enter ±5 mmHg before ``bolus_s`` (s)."""
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
    replay = stopped_at(run, model, bolus_s)
    before = t < bolus_s - 1e-9
    above = (replay - target > CLINICAL_BAND_MMHG) & ~before
    return Ceiling(
        in_band_pct=float(run.record["time_in_band_pct"]),
        ceiling_pct=float(100.0 * (1.0 - np.count_nonzero(above) / (t.size - first))),
        above_floor_s=float(np.count_nonzero(above) * (t[1] - t[0])),
        replay_error_mmhg=float(np.max(np.abs(replay[before] - y[before]))),
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
    bolus = [d.start_s for d in load_scenario(SCENARIO).disturbances if d.kind == "bolus"][0]
    model = with_sensitivity(a.patient_model, a.sensitivity)
    rows = []
    for seed in cohort_seeds(a.seed, a.patients):
        run = simulate(a.controller, SCENARIO, seed, patient_model=a.patient_model,
                       sensitivity=a.sensitivity)  # fmt: skip
        c = ceiling(run, model, bolus)
        if c is None:
            print(f"{seed}: not in the band before the bolus")
            continue
        rows.append(c)
        print(
            f"{seed}: in band {c.in_band_pct:5.1f} %, at most {c.ceiling_pct:5.1f} %"
            f" (above +5 mmHg after the bolus at least {c.above_floor_s:.0f} s)",
            flush=True,
        )
    if rows:
        print(
            f"{a.patient_model} {a.sensitivity:g}x, {len(rows)} patients: median in band"
            f" {np.median([r.in_band_pct for r in rows]):.1f} %, median ceiling"
            f" {np.median([r.ceiling_pct for r in rows]):.1f} %"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
