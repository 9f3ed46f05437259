"""In-silico cohort trial: one controller, one scenario, n seeded patients, §3 metrics.

Each patient runs in the pure in-process simulator (:func:`pressor.hil_sim.episode.simulate`) with a
fresh controller from :func:`pressor.runtime.inputs.controller_loader.load_controller`. Patients are
independent, so the worker processes (``jobs``) or the Dask cluster (``scheduler``) change only the
wall time: results are collected in patient order and every output file is byte-identical whatever
``jobs`` is.

Metrics judge the *true* MAP (what the patient experiences; a flushed or disconnected line must not
count as hypertension), with the settling band chosen by whether the scenario's monitor is noisy
(docs/METRICS.md). ``reachable`` compares the largest ΔMAP the scenario asks for (target step minus
disturbances) with the largest steady-state ΔMAP the pump's maximum rate gives at this patient's
sensitivity (the model's ``max_delta_map_mmhg``; the paper model: max over i ≤ max of
k0·i·e^(−k1·i)): a patient whose shortfall exceeds the metrics' band
(:func:`pressor.contracts.metrics.reachable_band_mmhg`) is unreachable.

``patient_model`` picks the patient model (:mod:`pressor.hil_sim.patients.patient_model`: a registry name or
``MODULE:CLASS``, resolved again in each worker process from that string); the records and the
summary of a model other than the default ``paper`` carry its name as ``patient_model`` (the
default's keep their bytes) and its own ``coefficients`` with their units.

The scenario's hemorrhages and boluses are the disturbance events the metrics split the run at
(``docs/METRICS.md``): the step metrics stop at the first one and each gets a record in the
patient's ``disturbances`` list; a sinusoid is background, not an event. What a trial writes from
the records: :mod:`pressor.hil_sim.trials.outputs`.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pressor.contracts.drug import DrugBinding
from pressor.contracts.metrics import EVENT_KINDS, Event, run_metrics
from pressor.hil_sim.episode import Trajectory, simulate
from pressor.hil_sim.native.controller import native_twin
from pressor.hil_sim.native.dose_guard import native_dose_guard
from pressor.hil_sim.native.estimator import native_schedule
from pressor.hil_sim.native.patient import native_patient
from pressor.hil_sim.patients.cohort import cohort_seeds
from pressor.hil_sim.patients.patient_model import DEFAULT_PATIENT_MODEL
from pressor.hil_sim.scenarios.scenario import Scenario
from pressor.hil_sim.trials.outputs import infusion_record, summarize
from pressor.hil_sim.world import World
from pressor.plumbing.parallel import run_ordered
from pressor.runtime.core.closed_loop import ControllerError
from pressor.runtime.core.dose_guard import DOSE_HARD_LIMIT, DOSE_HOUR_LIMIT, DoseLimits
from pressor.runtime.core.supervisor import Supervisor
from pressor.runtime.core.supervisor_config import supervisor_config_for
from pressor.runtime.estimation.sources import make_schedule
from pressor.runtime.inputs.controller_loader import load_controller


def controller_dir_name(spec: str) -> str:
    """A readable, file-name-safe name for a controller spec: ``smith:45`` -> ``smith_45``,
    ``lpv:wide-delay`` -> ``lpv_wide-delay``, a generated module's path -> its stem, a plugin ->
    its file stem (or module's last part, or entry point name), class and arguments
    (``/tmp/x/gspi.py:GSPI:kp0=3.0`` -> ``gspi_GSPI_kp0_3.0``, ``pkg.ctrl:Gain`` -> ``ctrl_Gain``)."""
    from pressor.runtime.inputs.controller_loader import LPV_PREFIX, SMITH_PREFIX
    from pressor.runtime.inputs.controller_plugin import (
        ControllerPluginError,
        is_plugin_spec,
        split_spec,
    )

    head = spec.partition(":")[0]
    base = spec
    if spec.endswith(".py"):
        base = Path(spec).stem
    elif head not in (LPV_PREFIX, SMITH_PREFIX, "pi") and is_plugin_spec(spec):
        try:
            module, cls, args = split_spec(spec)
        except ControllerPluginError:
            pass
        else:
            if is_plugin_spec(head):  # an installed entry point's name
                stem = head
            elif module.endswith(".py"):
                stem = Path(module).stem
            else:
                stem = module.rpartition(".")[2]
            base = "_".join(part for part in (stem, cls, args) if part)
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", base).strip("_") or "controller"


def scenario_events(scenario: Scenario) -> list[Event]:
    """The scenario's disturbance events ``(kind, start_s)``: its hemorrhages and boluses."""
    return [(d.kind, d.start_s) for d in scenario.disturbances if d.kind in EVENT_KINDS]


#: sample period (s) of the trajectories kept for a report (the loop's 10 Hz thinned to 1 Hz)
REPORT_SAMPLE_S = 1.0


def estimation_errors(traj: Trajectory) -> dict[str, float]:
    """How far the schedule was from the simulator's truth: the median absolute errors over the
    second half of the run of K (% of K), T (% of T) and τ (s)."""
    half = traj.t_s.size // 2
    return {
        "K_rel_err_pct": float(
            np.median(np.abs(traj.sched_K[half:] - traj.K[half:]) / traj.K[half:] * 100.0)
        ),
        "T_rel_err_pct": float(
            np.median(np.abs(traj.sched_T_s[half:] - traj.T_s[half:]) / traj.T_s[half:] * 100.0)
        ),
        "tau_abs_err_s": float(np.median(np.abs(traj.sched_tau_s[half:] - traj.tau_s[half:]))),
    }


def run_patient(
    scenario: Scenario,
    controller_spec: str,
    patient_seed: int,
    sample_period_s: float = 0.1,
    schedule: str = "oracle",
    patient_model: str = DEFAULT_PATIENT_MODEL,
    dose_limits: DoseLimits | None = None,
) -> dict[str, Any]:
    """Simulate one patient and return its JSON-ready record (seed, coefficients, metrics).

    ``schedule`` names the scheduling source (:func:`pressor.runtime.estimation.sources.make_schedule`),
    run by the runtime's core exactly as ``pressor run``/``sil`` run it; when it is not the oracle
    the record gains ``estimation`` (:func:`estimation_errors`). ``patient_model`` names the
    patient model (:mod:`pressor.hil_sim.patients.patient_model`). ``dose_limits`` (ml/h, from the drug
    library: :meth:`pressor.runtime.inputs.drug_library.DrugEntry.limits`) makes the supervisor cut every
    command to them as ``pressor run``'s does; the record's ``reachable`` and ``max_delta_mmhg``
    are then judged at the smaller of the pump's maximum and the hard dose limit, and the record
    gains ``dose`` (:func:`dose_record`). Without it the record keeps its bytes.
    """
    return _simulate_patient(
        scenario, controller_spec, patient_seed, sample_period_s, schedule, patient_model,
        dose_limits,
    )[0]  # fmt: skip


def dose_record(limits: DoseLimits, traj: Trajectory) -> dict[str, float | None]:
    """The record's ``dose``: the limits (``concentration_ug_ml`` µg/ml, ``weight_kg`` kg or
    ``None``, ``hard_max_ml_h`` ml/h, ``max_ml_per_hour`` ml) and how long the supervisor cut the
    command to the hard limit (``hard_limited_s``) and to the hourly one (``hour_limited_s``), s."""
    ts = float(traj.t_s[1] - traj.t_s[0]) if traj.t_s.size > 1 else 0.0
    return {
        "concentration_ug_ml": float(limits.concentration_ug_ml),
        "weight_kg": None if limits.weight_kg is None else float(limits.weight_kg),
        "hard_max_ml_h": float(limits.hard_max_ml_h),
        "max_ml_per_hour": float(limits.max_ml_per_hour),
        "hard_limited_s": float(np.count_nonzero(traj.faults & DOSE_HARD_LIMIT) * ts),
        "hour_limited_s": float(np.count_nonzero(traj.faults & DOSE_HOUR_LIMIT) * ts),
    }


def _simulate_patient(
    scenario: Scenario,
    controller_spec: str,
    patient_seed: int,
    sample_period_s: float,
    schedule: str,
    patient_model: str = DEFAULT_PATIENT_MODEL,
    dose_limits: DoseLimits | None = None,
) -> tuple[dict[str, Any], Trajectory]:
    world = World(scenario, patient_seed, sample_period_s, patient_model=patient_model)
    world.patient = native_patient(world.patient)  # before its first step
    controller = native_twin(load_controller(controller_spec, sample_period_s))
    supervisor = None  # simulate()'s default, pressor sil's
    max_rate = scenario.pump.max_rate_ml_h
    if dose_limits is not None:
        noise = scenario.sensor.noise_std_mmhg
        cfg = supervisor_config_for(controller, noise, dose_limits=dose_limits)
        supervisor = Supervisor(cfg)
        supervisor.dose_guard = native_dose_guard(supervisor.dose_guard)
        max_rate = min(max_rate, dose_limits.hard_max_ml_h)
    try:
        source = native_schedule(make_schedule(schedule, sample_period_s, controller))
        traj = simulate(world, controller, supervisor=supervisor, schedule=source)
    except ControllerError as exc:  # name the patient too (the message crosses processes)
        raise ControllerError(
            f"--controller {controller_spec!r}, patient seed {patient_seed}: {exc}"
        ) from None
    step_mmhg = world.step_mmhg  # an absolute target: this patient's distance to it
    has_step = step_mmhg != 0.0
    metrics = run_metrics(
        traj.t_s,
        traj.map_true_mmhg,
        traj.target_mmhg,
        traj.rate_ml_h,
        max_rate_ml_h=scenario.pump.max_rate_ml_h,
        step_time_s=scenario.step_time_s if has_step else None,
        step_mmhg=step_mmhg if has_step else None,
        noisy=scenario.noisy,
        reachable=world.reachable(max_rate),
        map_true_mmhg=traj.map_true_mmhg,
        events=scenario_events(scenario),
    )
    record: dict[str, Any] = {"patient_seed": int(patient_seed)}
    if patient_model != DEFAULT_PATIENT_MODEL:  # the default's records keep their bytes
        record["patient_model"] = patient_model
    record["coefficients"] = world.patient.coefficients()
    record["schedule_range"] = _schedule_range(traj)
    record["required_delta_mmhg"] = world.required_delta_mmhg()
    record["max_delta_mmhg"] = world.patient.max_delta_map_mmhg(max_rate)
    record.update(metrics)
    record["commands_out_of_range"] = int(world.pump.commands_out_of_range)
    if dose_limits is not None:  # records without limits keep their bytes
        record["dose"] = dose_record(dose_limits, traj)
    if schedule != "oracle":  # oracle records keep their bytes
        record["estimation"] = estimation_errors(traj)
    return record, traj


def _schedule_range(traj: Trajectory) -> dict[str, list[float]]:
    """The patient's true K (mmHg/(ml/h)), T (s) and τ (s) over the run, as [min, max] each."""
    return {
        name: [float(np.min(values)), float(np.max(values))]
        for name, values in (
            ("K_mmhg_per_ml_h", traj.K),
            ("T_s", traj.T_s),
            ("tau_s", traj.tau_s),
        )
    }


Task = tuple[Scenario, str, int, float, str, str]


def _worker(args: Task) -> dict[str, Any]:
    return run_patient(*args)


def _worker_traced(args: Task) -> tuple[dict[str, Any], dict]:
    record, traj = _simulate_patient(*args)
    every = max(1, int(round(REPORT_SAMPLE_S / args[3])))
    thinned = {
        "t_s": traj.t_s[::every],
        "map_true_mmhg": traj.map_true_mmhg[::every],
        "target_mmhg": traj.target_mmhg[::every],
        "rate_ml_h": traj.rate_ml_h[::every],
    }
    return record, thinned


def run_trial(
    scenario: Scenario,
    controller_spec: str,
    cohort_seed: int,
    n_patients: int,
    jobs: int = 1,
    sample_period_s: float = 0.1,
    progress: Callable[[int, int], None] | None = None,
    scheduler: str | None = None,
    schedule: str = "oracle",
    patient_model: str = DEFAULT_PATIENT_MODEL,
) -> list[dict[str, Any]]:
    """Run the cohort ``(cohort_seed, n_patients)``; records in patient order.

    Parameters
    ----------
    scenario
        The scenario every patient runs.
    controller_spec
        ``pi``, ``lpv`` or a path to a generated module.
    cohort_seed, n_patients
        The cohort (:func:`pressor.hil_sim.patients.cohort.cohort_seeds`).
    jobs
        Local worker processes (≥ 1); does not change the results.
    progress
        Called with (done, total) after each patient.
    scheduler
        Address of a Dask scheduler (``tcp://HOST:PORT``) to run the patients on instead of local
        processes (:mod:`pressor.plumbing.parallel`); does not change the results.
    schedule
        The scheduling source (``oracle``, ``estimated``, ``nominal``, ``validated``;
        :func:`run_patient`).
    patient_model
        The patient model, a registry name or ``MODULE:CLASS`` (:mod:`pressor.hil_sim.patients.patient_model`);
        every worker must be able to import it.
    """
    tasks = _tasks(
        scenario, controller_spec, cohort_seed, n_patients, sample_period_s, schedule, patient_model
    )
    return run_ordered(_worker, tasks, jobs=jobs, scheduler=scheduler, progress=progress)


def _tasks(
    scenario: Scenario,
    spec: str,
    cohort_seed: int,
    n_patients: int,
    sample_period_s: float,
    schedule: str,
    patient_model: str,
) -> list[Task]:
    return [
        (scenario, spec, s, sample_period_s, schedule, patient_model)
        for s in cohort_seeds(cohort_seed, n_patients)
    ]


def run_trial_traced(
    scenario: Scenario,
    controller_spec: str,
    cohort_seed: int,
    n_patients: int,
    jobs: int = 1,
    sample_period_s: float = 0.1,
    progress: Callable[[int, int], None] | None = None,
    scheduler: str | None = None,
    schedule: str = "oracle",
    patient_model: str = DEFAULT_PATIENT_MODEL,
) -> tuple[list[dict[str, Any]], dict[str, np.ndarray]]:
    """:func:`run_trial` that also keeps every patient's trajectory, thinned to 1 Hz, for a report.

    Returns
    -------
    records, trajectories
        The records (as :func:`run_trial` returns them) and the arrays
        :data:`pressor.hil_sim.trials.report.TRAJECTORY_KEYS` names: ``t_s`` (ticks,), ``map_true_mmhg``,
        ``target_mmhg``, ``rate_ml_h`` (patients × ticks; mmHg, mmHg, ml/h) and ``patient_seed``.
    """
    tasks = _tasks(
        scenario, controller_spec, cohort_seed, n_patients, sample_period_s, schedule, patient_model
    )
    runs = run_ordered(_worker_traced, tasks, jobs=jobs, scheduler=scheduler, progress=progress)
    records = [r for r, _ in runs]
    arrays = {
        key: np.stack([tr[key] for _, tr in runs])
        for key in ("map_true_mmhg", "target_mmhg", "rate_ml_h")
    }
    arrays["t_s"] = runs[0][1]["t_s"]
    arrays["patient_seed"] = np.array([r["patient_seed"] for r in records], dtype=np.int64)
    return records, arrays


def run_cohort(
    scenario: Scenario,
    controller_spec: str,
    cohort_seed: int,
    n_patients: int,
    *,
    traced: bool = False,
    drug: DrugBinding | None = None,
    weight_kg: float | None = None,
    **options: Any,
) -> tuple[list[dict[str, Any]], dict[str, Any], dict[str, np.ndarray] | None]:
    """What ``pressor trial`` and :func:`pressor.api.trial` run for one controller.

    ``options`` are :func:`run_trial`'s (``jobs``, ``sample_period_s``, ``progress``,
    ``scheduler``, ``schedule``, ``patient_model``). ``drug`` (the run's drug and syringe,
    :func:`pressor.hil_sim.patients.syringe.check_syringe`) and ``weight_kg`` (kg; ``None``: the
    reference adult) give every record its ``infusion`` (:func:`infusion_record`) and the summary
    its own (:func:`infusion_summary`). Returns the records, the summary (:func:`summarize`) and,
    when ``traced``, the trajectories of :func:`run_trial_traced`.
    """
    run = run_trial_traced if traced else run_trial
    result = run(scenario, controller_spec, cohort_seed, n_patients, **options)
    records, trajectories = result if traced else (result, None)
    if drug is not None:
        for r in records:
            r["infusion"] = infusion_record(r, drug, weight_kg, scenario.duration_s)
    summary = summarize(
        records,
        scenario,
        controller_spec,
        cohort_seed,
        options.get("schedule", "oracle"),
        options.get("patient_model", DEFAULT_PATIENT_MODEL),
    )
    return records, summary, trajectories
