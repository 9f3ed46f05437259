"""In-silico cohort trial: one controller, one scenario, n seeded patients, §3 metrics.

Each patient runs in the pure in-process simulator (:func:`hil_sim.closed_loop.simulate`) with a
fresh controller from :func:`runtime.controller_loader.load_controller`. Patients are independent,
so the worker processes (``jobs``) or the Dask cluster (``scheduler``) change only the wall time: results are collected in patient order and
every output file is byte-identical whatever ``jobs`` is.

Metrics judge the *true* MAP (what the patient experiences; a flushed or disconnected line must not
count as hypertension), with the settling band chosen by whether the scenario's monitor is noisy
(DESIGN.md §3). ``reachable`` compares the largest ΔMAP the scenario asks for (target step minus
disturbances) with the largest steady-state ΔMAP the pump's maximum rate gives at this patient's
sensitivity (max over i ≤ max of k0·i·e^(−k1·i)): a patient whose shortfall exceeds the metrics'
band (:func:`contracts.metrics.reachable_band_mmhg`) is unreachable.

The scenario's hemorrhages and boluses are the disturbance events the metrics split the run at
(``docs/METRICS.md``): the step metrics stop at the first one and each gets a record in the
patient's ``disturbances`` list; a sinusoid is background, not an event. ``patients.csv`` flattens
the records into ``LABEL_start_s``, ``LABEL_peak_deviation_mmhg``, ``LABEL_recovery_s`` and
``LABEL_iae_mmhg_s`` columns, LABEL being the kind (``hemorrhage``, ``bolus``; ``hemorrhage_2``
for a second one).
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from contracts.files import write_atomic
from contracts.metrics import (
    EVENT_KINDS,
    EVENT_METRICS,
    RUN_METRICS,
    Event,
    aggregate,
    event_labels,
    run_metrics,
)
from hil_sim.backend import run_ordered
from hil_sim.closed_loop import simulate
from hil_sim.cohort import cohort_seeds
from hil_sim.scenario import Scenario
from hil_sim.world import World
from runtime.controller_loader import load_controller


def scenario_events(scenario: Scenario) -> list[Event]:
    """The scenario's disturbance events ``(kind, start_s)``: its hemorrhages and boluses."""
    return [(d.kind, d.start_s) for d in scenario.disturbances if d.kind in EVENT_KINDS]


def run_patient(
    scenario: Scenario, controller_spec: str, patient_seed: int, sample_period_s: float = 0.1
) -> dict[str, Any]:
    """Simulate one patient and return its JSON-ready record (seed, coefficients, metrics)."""
    world = World(scenario, patient_seed, sample_period_s)
    controller = load_controller(controller_spec, sample_period_s)
    traj = simulate(world, controller)
    has_step = scenario.step_mmhg != 0.0
    metrics = run_metrics(
        traj.t_s,
        traj.map_true_mmhg,
        traj.target_mmhg,
        traj.rate_ml_h,
        max_rate_ml_h=scenario.pump.max_rate_ml_h,
        step_time_s=scenario.step_time_s if has_step else None,
        step_mmhg=scenario.step_mmhg if has_step else None,
        noisy=scenario.noisy,
        reachable=world.reachable(),
        map_true_mmhg=traj.map_true_mmhg,
        events=scenario_events(scenario),
    )
    record: dict[str, Any] = {
        "patient_seed": int(patient_seed),
        "coefficients": world.params.to_dict(),
        "required_delta_mmhg": world.required_delta_mmhg(),
        "max_delta_mmhg": world.params.max_delta_map_mmhg(scenario.pump.max_rate_ml_h),
    }
    record.update(metrics)
    record["commands_out_of_range"] = int(world.pump.commands_out_of_range)
    return record


def _worker(args: tuple[Scenario, str, int, float]) -> dict[str, Any]:
    return run_patient(*args)


def run_trial(
    scenario: Scenario,
    controller_spec: str,
    cohort_seed: int,
    n_patients: int,
    jobs: int = 1,
    sample_period_s: float = 0.1,
    progress: Callable[[int, int], None] | None = None,
    scheduler: str | None = None,
) -> list[dict[str, Any]]:
    """Run the cohort ``(cohort_seed, n_patients)``; records in patient order.

    Parameters
    ----------
    scenario
        The scenario every patient runs.
    controller_spec
        ``pi``, ``lpv`` or a path to a generated module.
    cohort_seed, n_patients
        The cohort (:func:`hil_sim.cohort.cohort_seeds`).
    jobs
        Local worker processes (≥ 1); does not change the results.
    progress
        Called with (done, total) after each patient.
    scheduler
        Address of a Dask scheduler (``tcp://HOST:PORT``) to run the patients on instead of local
        processes (:mod:`hil_sim.backend`); does not change the results.
    """
    tasks = [
        (scenario, controller_spec, s, sample_period_s)
        for s in cohort_seeds(cohort_seed, n_patients)
    ]
    return run_ordered(_worker, tasks, jobs=jobs, scheduler=scheduler, progress=progress)


def summarize(
    records: Sequence[dict[str, Any]], scenario: Scenario, controller_spec: str, cohort_seed: int
) -> dict[str, Any]:
    """The ``summary.json`` document: trial identity and the aggregated metrics."""
    return {
        "scenario": scenario.name,
        "controller": controller_spec,
        "cohort_seed": int(cohort_seed),
        "n_patients": len(records),
        "unreachable_patient_seeds": [r["patient_seed"] for r in records if not r["reachable"]],
        "unstable_patient_seeds": [r["patient_seed"] for r in records if not r["stable"]],
        "metrics": aggregate(records),
    }


_EVENT_COLUMNS = ("start_s",) + EVENT_METRICS


def _csv_text(records: Sequence[dict[str, Any]]) -> str:
    coeff_keys = list(records[0]["coefficients"]) if records else []
    scalar_keys = (
        ["required_delta_mmhg", "max_delta_mmhg"]
        + list(RUN_METRICS)
        + ["reachable", "stable", "commands_out_of_range"]
    )
    # Every patient of a trial runs the same scenario, so the first one's events name the columns.
    labels = event_labels([d["kind"] for d in records[0]["disturbances"]]) if records else []
    header = (
        ["patient_seed"]
        + coeff_keys
        + scalar_keys
        + [f"{label}_{col}" for label in labels for col in _EVENT_COLUMNS]
    )
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for r in records:
        row = [r["patient_seed"]] + [r["coefficients"][k] for k in coeff_keys]
        row += [r[k] for k in scalar_keys]
        row += [d[col] for d in r["disturbances"] for col in _EVENT_COLUMNS]
        writer.writerow(["" if v is None else repr(v) if isinstance(v, float) else v for v in row])
    return buf.getvalue()


def write_outputs(
    out_dir: Path, records: Sequence[dict[str, Any]], summary: dict[str, Any]
) -> None:
    """Write ``patients.json``, ``patients.csv`` and ``summary.json`` atomically into ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    write_atomic(out_dir / "patients.json", json.dumps(list(records), indent=1) + "\n")
    write_atomic(out_dir / "patients.csv", _csv_text(records))
    write_atomic(out_dir / "summary.json", json.dumps(summary, indent=1) + "\n")
