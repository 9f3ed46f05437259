"""Responsiveness sweep: what harms, per patient model, drug-sensitivity level and controller.

Usage::

    python -m benchmarks.sensitivity_sweep                        # 250 patients, 7 levels, 4 models
    python -m benchmarks.sensitivity_sweep --patients 20 --out sweep/ --jobs 2
    python -m benchmarks.sensitivity_sweep --models norepinephrine --levels 0.1,10 --seed 7

Every patient of the cohort ``(--seed, --patients)`` runs the scenario (default
``paper-disturbance``) at each sensitivity level f (default 0.1, 0.2, 0.5, 1, 2, 5, 10 × the
model's: the seven levels of published robustness tests of closed-loop vasopressor systems) under
each controller, for each patient model (default ``paper``, ``pkpd``, ``phenylephrine-2c``,
``norepinephrine``; docs/PATIENTS.md). A level is the model ``MODEL@sensitivity=f``
(:mod:`pressor.hil_sim.patients.sensitivity`: each delivered ml/h acts as f ml/h). Each model is played with
its drug (:data:`MODEL_DRUG`); ``lpv`` in ``--controllers`` is that drug's shipped design
(:data:`DRUG_LPV`: ``lpv`` for phenylephrine, ``lpv:norepinephrine``; under ``--schedule
cautious`` its design on a log-K scale, the runtime's default: :data:`pressor.runtime.inputs.defaults.DESIGN_FOR_DRUG`), the others run as named
(the PI and the Smith predictor have no drug: their gains are in ml/h of phenylephrine's 100 µg/ml
syringe, and ``pressor run`` refuses a norepinephrine device for them, docs/DRUGS.md; here, in
process, they run unretuned). Each controller runs on the scheduling source ``pressor run`` gives
it (``--schedule default``: ``cautious`` for the LPV, ``estimated`` for the Smith predictor; the PI
ignores it), or on the one ``--schedule`` names for all.

**Syringe and dose limits.** A clinician picks them before knowing the patient's sensitivity, so
every level uses the drug library's (``runtime/inputs/drug_library.toml``) standard syringe (its
first concentration), the scenario's pump and the library's limits, which the supervisor enforces
as under ``pressor run`` (hard, soft and hourly; :mod:`pressor.runtime.core.dose_guard`), per-kg limits at
:data:`REFERENCE_WEIGHT_KG`. A patient the standard syringe cannot bring to the target within the
rate it can hold for the hour (the smallest of the pump's maximum, the hard and soft dose limits
and the hourly maximum spread over the hour: :attr:`Syringe.max_rate_ml_h`) runs with the
library's stronger syringe (:func:`syringes`) when that one can, as a clinician would switch to
it; the controllers are not told (the simulated patient counts ml/h of the standard syringe). A
patient no syringe of the library can bring to the target within those limits
is a **non-responder**: it runs with the standard syringe, is reported in its own row and counted
with its shortfall, never dropped. *Bring to the target* means hold there for the hour
(:func:`pressor.hil_sim.reach.holds`): a fresh copy of the patient infused from the first second at
the best rate the limits allow stays within the metrics' band of what the scenario asks from the
moment it gets there, which a patient whose kinetics or tolerance keep drifting for the hour may
not, though the steady state of that rate would (the trial's ``reachable``, docs/METRICS.md).

**Figures** (:mod:`benchmarks.sweep_figures`, docs/METRICS.md): every metric judges the *true* MAP,
as ``pressor trial`` does (what the patient experiences; the monitor's noise is not the device's
harm). Per row: unstable patients; step overshoot (% of the step and mmHg: median / p90 / max); the
longest stretch above target + 10 mmHg (s) and the patients with one longer than 30 s; time to
first enter ±5 mmHg (median / p90, never-arrived patients ranked last); time below target − 5 mmHg
and time within ±5 mmHg after that entry (%); MDPE, MDAPE, wobble (%) and divergence (%/h) over
the whole period after the step; IAE; patients the hourly dose limit cut; patients the supervisor
put in HOLD or FAILSAFE (a clean run should have none).

Printed (stdout), as each model finishes: per model a table of who reaches the target per level,
a headline table of issue 41's figures over every patient brought to the target (the standard
syringe's and the switched together: the README's results table), and the full table with every
group apart; the JSON (``--json``, and ``OUT/sweep.json`` with ``--out``) holds every
figure. Both are deterministic: the same arguments give the same bytes whatever ``--jobs``. The
throughput (patient-hours per wall minute, and per CPU minute of the workers: per busy core, in
total, per model and per model and controller, with the parts that ran without their compiled
twin, :mod:`pressor.hil_sim.native`) goes to stderr with the progress.

With ``--out DIR`` each (model, level, controller, syringe) cohort writes
``DIR/MODEL/xF/CONTROLLER/SYRINGE/`` (``patients.json``, ``patients.csv``, ``summary.json``,
``run.json``) and a run started again reuses those whose ``run.json`` matches: the names, the
seeds, the limits, and the LPV module's bytes and the drug's caution, so a redesign under the same
name runs again (delete a directory to run it again anyway).
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.sweep_figures import Throughput, model_tables, row_figures, shortfall_figures
from benchmarks.sweep_plan import (
    DRUG_LPV,
    MODEL_DRUG,
    REFERENCE_WEIGHT_KG,
    Syringe,
    reach_plan,
    syringes,
)
from pressor.hil_sim.native import controller as native_controller
from pressor.hil_sim.native import dose_guard as native_dose_guard
from pressor.hil_sim.native import patient as native_patient
from pressor.hil_sim.patients.cohort import cohort_seeds
from pressor.hil_sim.patients.patient_model import PatientModelError
from pressor.hil_sim.patients.sensitivity import check_factor
from pressor.hil_sim.scenarios.scenario import Scenario, load_scenario
from pressor.hil_sim.trials.outputs import summarize, write_outputs
from pressor.hil_sim.trials.trial import _simulate_patient, controller_dir_name
from pressor.plumbing import native_call
from pressor.plumbing.files import write_atomic
from pressor.plumbing.parallel import run_ordered
from pressor.runtime.core.dose_guard import DoseLimits
from pressor.runtime.core.supervisor_config import State
from pressor.runtime.estimation.caution import CAUTION_FOR_DRUG, Caution
from pressor.runtime.estimation.sources import SOURCES
from pressor.runtime.inputs.controller_loader import load_controller, lpv_design_module
from pressor.runtime.inputs.defaults import DESIGN_FOR_DRUG, default_schedule
from pressor.runtime.inputs.drug_library import load_library

#: sensitivity levels (× the model's; dimensionless)
LEVELS = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0)
CONTROLLERS = ("lpv", "pi", "smith")
#: the loop period every cohort runs at (s), ``pressor trial``'s
SAMPLE_PERIOD_S = 0.1

Task = tuple[Scenario, str, int, float, str, str, DoseLimits]


def _run_one(task: Task) -> tuple[dict[str, Any], float, tuple[tuple[str, str], ...]]:
    """One patient's record, with ``held_s`` (s the supervisor spent in HOLD or FAILSAFE, where
    the controller does not act), the CPU time (s) its worker spent on it, and the parts that ran
    without their compiled twin (``(part, why)``; :mod:`pressor.hil_sim.native`)."""
    t0 = time.process_time()
    record, traj = _simulate_patient(*task)
    held = np.count_nonzero((traj.state == State.HOLD) | (traj.state == State.FAILSAFE))
    record["held_s"] = float(held * SAMPLE_PERIOD_S)
    cpu = time.process_time() - t0
    reasons = (
        ("patient", native_patient.last_reason),
        ("controller", native_controller.last_reason),
        ("dose guard", native_dose_guard.last_reason),
        ("twin callers", native_call.reason()),  # else each twin is called through ctypes
    )
    return record, cpu, tuple((part, why) for part, why in reasons if why)


def run_dir(out: Path, model: str, level: float, controller: str, syringe: Syringe) -> Path:
    """Where one cohort is written: ``OUT/MODEL/xF/CONTROLLER/SYRINGE``."""
    name = controller_dir_name(model)
    return out / name / f"x{level:g}" / controller_dir_name(controller) / syringe.dir_name


#: ``--schedule`` value: every controller on the source ``pressor run`` gives it
DEFAULT = "default"


@functools.cache  # one load per spec, not one per model and level
def schedule_of(schedule: str, controller: str) -> str:
    """The scheduling source ``controller`` (a spec) runs on: ``schedule``, or for :data:`DEFAULT`
    the runtime's default for it (:func:`pressor.runtime.inputs.defaults.default_schedule`)."""
    if schedule != DEFAULT:
        return schedule
    return default_schedule(load_controller(controller, SAMPLE_PERIOD_S))


def _identity(args: argparse.Namespace, scenario: Scenario, job: dict[str, Any]) -> dict[str, Any]:
    """What a written cohort must match to be reused (``run.json``): besides the names, the LPV
    module's bytes and the drug's caution, so a redesigned controller under the same name is run
    again instead of read back."""
    module = lpv_design_module(job["controller"])
    return {
        "scenario": scenario.name,
        "schedule": job["schedule"],
        "model": job["model"],
        "level": job["level"],
        "controller": job["controller"],
        "controller_module_sha256": (
            None if module is None else hashlib.sha256(module.read_bytes()).hexdigest()
        ),
        "caution": asdict(CAUTION_FOR_DRUG.get(MODEL_DRUG[job["model"]], Caution())),
        "patient_model": job["spec"],
        "dose_limits": asdict(job["syringe"].limits),
        "patient_seeds": job["seeds"],
    }


def _reuse(path: Path, identity: dict[str, Any]) -> list[dict[str, Any]] | None:
    try:
        if json.loads((path / "run.json").read_text()) != identity:
            return None
        records = json.loads((path / "patients.json").read_text())
    except (OSError, ValueError):
        return None
    return records if len(records) == len(identity["patient_seeds"]) else None


def run_level(
    args: argparse.Namespace, scenario: Scenario, model: str, level: float, meter: Throughput
) -> dict[str, Any]:
    """One model at one level: who reaches the target, then every controller's rows."""
    drug = MODEL_DRUG[model]
    standard, stronger = syringes(load_library()[drug], scenario.pump.max_rate_ml_h)
    seeds = cohort_seeds(args.seed, args.patients)
    plan = reach_plan(scenario, model, level, seeds, standard, stronger, jobs=args.jobs)
    lpv = (DESIGN_FOR_DRUG if args.schedule in ("cautious", DEFAULT) else DRUG_LPV)[drug]
    controllers = [lpv if c == "lpv" else c for c in args.controllers]
    schedules = {c: schedule_of(args.schedule, c) for c in controllers}
    jobs: list[dict[str, Any]] = []
    for controller in controllers:
        for syringe, group_seeds in (
            (standard, sorted(plan["standard"] + plan["non_responders"])),
            (stronger, plan["switched"]),
        ):
            if syringe is None or not group_seeds:
                continue
            spec = syringe.patient_model(model, level)
            job = {"model": model, "level": level, "controller": controller, "syringe": syringe}
            job |= {"spec": spec, "seeds": group_seeds, "schedule": schedules[controller]}
            job["identity"] = _identity(args, scenario, job)
            job["dir"] = run_dir(args.out, model, level, controller, syringe) if args.out else None
            job["records"] = _reuse(job["dir"], job["identity"]) if job["dir"] else None
            jobs.append(job)
    _run_pending(args, scenario, [j for j in jobs if j["records"] is None], meter)
    rows = []
    responders: dict[str, list[dict[str, Any]]] = {c: [] for c in controllers}
    for job in jobs:
        by_seed = {r["patient_seed"]: r for r in job["records"]}
        reached = plan["standard"] if job["syringe"] is standard else plan["switched"]
        responders[job["controller"]] += [by_seed[s] for s in reached]
        if job["syringe"] is standard:
            groups = [("standard", plan["standard"]), ("non-responders", plan["non_responders"])]
        else:
            groups = [("switched", plan["switched"])]
        for group, group_seeds in groups:
            if group_seeds:
                rows.append(
                    {
                        "controller": job["controller"],
                        "group": group,
                        "syringe_ug_ml": job["syringe"].concentration_ug_ml,
                        "figures": row_figures([by_seed[s] for s in group_seeds]),
                    }
                )
    order = {"standard": 0, "switched": 1, "non-responders": 2}
    rows.sort(key=lambda r: (controllers.index(r["controller"]), order[r["group"]]))
    reach = {
        "patients": len(seeds),
        "standard": len(plan["standard"]),
        "switched": len(plan["switched"]),
        "non_responders": len(plan["non_responders"]),
        "stronger_syringe_ug_ml": None if stronger is None else stronger.concentration_ug_ml,
        "shortfall_mmhg": shortfall_figures(plan["shortfall_mmhg"]),
    }
    headline = [
        {"controller": c, "figures": row_figures(responders[c])}
        for c in controllers
        if responders[c]
    ]
    return {"reach": reach, "rows": rows, "responders": headline}


def _run_pending(
    args: argparse.Namespace, scenario: Scenario, jobs: list[dict[str, Any]], meter: Throughput
) -> None:
    """Run every pending cohort as one batch (both cores busy to the end) and write each."""
    if not jobs:
        return
    tasks: list[Task] = []
    for job in jobs:
        limits = job["syringe"].limits
        tasks += [
            (scenario, job["controller"], s, SAMPLE_PERIOD_S, job["schedule"], job["spec"], limits)
            for s in job["seeds"]
        ]
    label = f"{jobs[0]['model']} x{jobs[0]['level']:g}"

    def progress(done: int, total: int) -> None:
        end = "\n" if done == total else ""
        print(f"\r{label}: {done}/{total} runs", end=end, file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    results = run_ordered(
        _run_one, tasks, jobs=args.jobs, scheduler=args.scheduler, progress=progress
    )
    wall = time.perf_counter() - t0
    hours = scenario.duration_s / 3600.0
    owners = [(job["model"], job["controller"]) for job in jobs for _ in job["seeds"]]
    meter.add(
        wall,
        [
            (m, c, hours, cpu, plain)
            for (m, c), (_, cpu, plain) in zip(owners, results, strict=True)
        ],
    )
    print(f"{label}: {wall:.1f} s wall", file=sys.stderr, flush=True)
    start = 0
    for job in jobs:
        records = [r for r, _, _ in results[start : start + len(job["seeds"])]]
        start += len(job["seeds"])
        job["records"] = records
        if job["dir"] is not None:
            summary = summarize(
                records, scenario, job["controller"], args.seed, job["schedule"], job["spec"]
            )
            write_outputs(job["dir"], records, summary)
            write_atomic(job["dir"] / "run.json", json.dumps(job["identity"], indent=1) + "\n")


def _levels(text: str) -> list[float]:
    try:
        return [check_factor(float(v), f"--levels item {v!r}") for v in text.split(",")]
    except (ValueError, PatientModelError) as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _names(known: tuple[str, ...] | None) -> Any:
    def parse(text: str) -> list[str]:
        names = [v for v in text.split(",") if v]
        bad = [v for v in names if known is not None and v not in known]
        if bad or not names:
            raise argparse.ArgumentTypeError(
                f"{text!r}: allowed a comma-separated subset of {known}"
            )
        return names

    return parse


def parser() -> argparse.ArgumentParser:
    """The command line (every option's default and unit in its help)."""
    p = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawTextHelpFormatter
    )
    p.add_argument("--patients", type=int, default=250, help="cohort size (default 250)")
    p.add_argument("--seed", type=int, default=2026, help="cohort seed (default 2026)")
    p.add_argument(
        "--scenario", default="paper-disturbance", help="name or .toml (default %(default)s)"
    )
    p.add_argument(
        "--levels",
        type=_levels,
        default=list(LEVELS),
        help="sensitivity factors, comma-separated, each in [0.05, 20] (dimensionless;"
        " default 0.1,0.2,0.5,1,2,5,10)",
    )
    p.add_argument(
        "--models",
        type=_names(tuple(MODEL_DRUG)),
        default=list(MODEL_DRUG),
        help=f"patient models, comma-separated (default {','.join(MODEL_DRUG)})",
    )
    p.add_argument(
        "--controllers",
        type=_names(None),
        default=list(CONTROLLERS),
        help="controller specs, comma-separated; lpv = the model's drug's design"
        " (default %(default)s)",
    )
    p.add_argument(
        "--schedule",
        choices=(DEFAULT, *SOURCES),
        default=DEFAULT,
        help="scheduling source of every controller; default: each on pressor run's default"
        " (cautious for the LPV, estimated for the others)",
    )
    p.add_argument("--jobs", type=int, default=1, help="local worker processes (default 1)")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address (default: local)")
    p.add_argument(
        "--out", type=Path, default=None, help="write and reuse results here (default: none)"
    )
    p.add_argument("--json", type=Path, default=None, help="write the figures' JSON here")
    return p


def main(argv: list[str] | None = None) -> int:
    """Run the sweep and print its tables; 0 on completion, 2 on a bad argument."""
    args = parser().parse_args(argv)
    try:
        scenario = load_scenario(args.scenario)
    except ValueError as exc:
        print(f"sensitivity_sweep: {exc}", file=sys.stderr)
        return 2
    doc: dict[str, Any] = {
        "scenario": scenario.name,
        "cohort_seed": args.seed,
        "patients_per_level": args.patients,
        "schedule": args.schedule,
        "levels": args.levels,
        "reference_weight_kg": REFERENCE_WEIGHT_KG,
        "map": "true",
        "models": {},
    }
    print(
        f"sensitivity sweep: scenario {scenario.name}, cohort seed {args.seed}, {args.patients}"
        f" patients per level, schedule {args.schedule}"
        + (
            " (pressor run's: cautious for the LPV, estimated for the others)"
            if args.schedule == DEFAULT
            else ""
        )
        + ", metrics on the true MAP",
        flush=True,
    )
    meter = Throughput()
    for model in args.models:
        drug = MODEL_DRUG[model]
        standard, stronger = syringes(load_library()[drug], scenario.pump.max_rate_ml_h)
        result: dict[str, Any] = {
            "drug": drug,
            "standard_syringe": standard.describe(),
            "stronger_syringe": None if stronger is None else stronger.describe(),
            "levels": [],
        }
        for level in args.levels:
            try:
                result["levels"].append(
                    {"level": level, **run_level(args, scenario, model, level, meter)}
                )
            except PatientModelError as exc:
                print(f"sensitivity_sweep: {exc}", file=sys.stderr)
                return 2
        doc["models"][model] = result
        print("\n" + model_tables(model, result), flush=True)
    print(meter.report(args.jobs), file=sys.stderr, flush=True)
    text = json.dumps(doc, indent=1) + "\n"
    for path in (args.json, args.out / "sweep.json" if args.out else None):
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_atomic(path, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
