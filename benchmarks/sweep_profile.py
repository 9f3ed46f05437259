"""Where a sensitivity-sweep tick goes: cProfile shares by part for one model and level.

Usage::

    python -m benchmarks.sweep_profile --model phenylephrine-2c --level 1
    python -m benchmarks.sweep_profile --model norepinephrine --level 0.2 --patients 3

Runs the sweep's task (:mod:`benchmarks.sensitivity_sweep`: the scenario, the drug library's
standard syringe and dose limits, the schedule and the model's drug's LPV) for the first
``--patients`` patients of the cohort, once unprofiled (the CPU seconds per patient-hour, the
compiled twins included) and once under cProfile, and prints the profiled time by part: each
function's own time goes to the part its module belongs to (:data:`PARTS`), a builtin's to its
heaviest caller's part (so a compiled twin's ctypes call counts where it is called from: the
patient's in the world's). The profiler inflates Python calls against C ones, so read the shares
as proportions, not as times.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

from benchmarks.sensitivity_sweep import SAMPLE_PERIOD_S
from benchmarks.sweep_plan import DRUG_LPV, MODEL_DRUG, syringes
from pressor.hil_sim.patients.cohort import cohort_seeds
from pressor.hil_sim.patients.patient_model import PatientModelError
from pressor.hil_sim.scenarios.scenario import load_scenario
from pressor.hil_sim.trials.trial import _simulate_patient
from pressor.runtime.estimation.sources import SOURCES
from pressor.runtime.inputs.defaults import DESIGN_FOR_DRUG
from pressor.runtime.inputs.drug_library import load_library

#: part -> fragments of the module paths that belong to it (the first part that matches wins)
PARTS = (
    ("patient model", ("hil_sim/patients/", "native/patient.py", "native/drug_patient.py")),
    ("dose guard (hourly limit)", ("dose_guard",)),
    (
        "supervisor (input checks, flatline, states)",
        ("core/supervisor", "input_checks", "flatline"),
    ),
    ("schedule and its evidence", ("runtime/estimation/", "native/estimator.py")),
    ("controller", ("native/controller.py", "runtime/generated/", "baselines/")),
    ("closed-loop core", ("core/closed_loop.py",)),
    ("world, monitor and pump", ("hil_sim/world.py", "hil_sim/devices/")),
    (
        "simulate's recording, metrics",
        ("hil_sim/episode.py", "contracts/metrics", "trials/trial.py"),
    ),
)


def part_of(filename: str) -> str | None:
    """The part (:data:`PARTS`) of the module at ``filename``, or ``None``."""
    return next((part for part, keys in PARTS if any(k in filename for k in keys)), None)


def shares(stats: pstats.Stats) -> dict[str, float]:
    """Own time per part, as fractions of the profiled total (builtins to their caller's part)."""
    out: dict[str, float] = {}
    total = 0.0
    for (filename, _, _), (_, _, own, _, callers) in stats.stats.items():  # type: ignore[attr-defined]
        total += own
        part = part_of(filename)
        if part is None and callers:
            heaviest = max(callers.items(), key=lambda kv: kv[1][2])[0][0]
            part = part_of(heaviest)
        out[part or "other"] = out.get(part or "other", 0.0) + own
    return {part: t / total for part, t in out.items()} if total > 0.0 else {}


def main(argv: list[str] | None = None) -> int:
    """Print the CPU per patient-hour and the shares; 0."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", choices=tuple(MODEL_DRUG), default="phenylephrine-2c")
    p.add_argument("--level", type=float, default=1.0, help="sensitivity factor (default 1)")
    p.add_argument("--patients", type=int, default=2, help="patients (default 2)")
    p.add_argument("--seed", type=int, default=2026, help="cohort seed (default 2026)")
    p.add_argument("--scenario", default="paper-disturbance", help="(default %(default)s)")
    p.add_argument("--schedule", choices=SOURCES, default="cautious", help="(default %(default)s)")
    args = p.parse_args(argv)
    if args.patients < 1:
        p.error(f"--patients {args.patients}: allowed 1 or more")
    scenario = load_scenario(args.scenario)
    drug = MODEL_DRUG[args.model]
    standard, _ = syringes(load_library()[drug], scenario.pump.max_rate_ml_h)
    controller = (DESIGN_FOR_DRUG if args.schedule == "cautious" else DRUG_LPV)[drug]
    try:
        spec = standard.patient_model(args.model, args.level)
    except PatientModelError as exc:
        p.error(str(exc))
    tasks = [
        (scenario, controller, s, SAMPLE_PERIOD_S, args.schedule, spec, standard.limits)
        for s in cohort_seeds(args.seed, args.patients)
    ]
    _simulate_patient(*tasks[0])  # warm-up: imports, compiled twins
    t0 = time.process_time()
    for task in tasks:
        _simulate_patient(*task)
    hours = len(tasks) * scenario.duration_s / 3600.0
    cpu = time.process_time() - t0
    print(
        f"{args.model} x{args.level:g} {controller} ({args.schedule}): {cpu / hours:.3f} CPU s"
        f" per patient-hour, {hours / (cpu / 60.0):.1f} patient-hours per CPU minute"
    )
    prof = cProfile.Profile()
    prof.enable()
    for task in tasks:
        _simulate_patient(*task)
    prof.disable()
    for part, share in sorted(shares(pstats.Stats(prof)).items(), key=lambda kv: -kv[1]):
        print(f"  {part:46s} {100.0 * share:5.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
