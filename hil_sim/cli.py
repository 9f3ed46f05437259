"""``pressor scenarios`` and ``pressor trial``: the named scenarios and the in-silico cohort trial.

``pressor trial --controller lpv|pi|smith[:LAMBDA_S]|PATH|MODULE:CLASS[:ARGS] --patients N --seed S --scenario NAME [--schedule oracle|estimated|nominal|validated] [--patient-model NAME|MODULE:CLASS] [--sensitivity F] [--jobs J | --scheduler ADDRESS] --out DIR``
prints a progress bar (stderr), then a table of the median and 90th percentile of each §3 metric
(reachable patients; unreachable ones counted and listed apart) and of each disturbance event's
peak |deviation|, recovery time and IAE (reachable patients; ``docs/METRICS.md``), and writes ``DIR/patients.json``,
``DIR/patients.csv`` and ``DIR/summary.json`` atomically. Same arguments → identical files, whatever
``--jobs``. Exit 0 on completion, 1 when a controller raised (one line naming it, the patient and
the tick: :class:`pressor.runtime.core.closed_loop.ControllerError`), 2 on bad usage or input (one line
naming field, value and range). A plugin controller (:mod:`pressor.runtime.inputs.controller_plugin`) is
named by ``MODULE:CLASS[:ARGS]``, ``FILE.py:CLASS[:ARGS]`` or an installed entry point's name.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pressor.contracts.checks import check_int_range, check_range
from pressor.hil_sim.patients.patient_model import add_patient_model_option
from pressor.plumbing.usage import UsageError, UsageParser, run_command, usage_exit
from pressor.runtime.inputs.clinician import add_syringe_options, add_target_option
from pressor.runtime.inputs.dosing import add_weight_option

#: longest simulated time per patient (s), as :func:`pressor.api.trial`'s ``duration_s``
MAX_DURATION_S = 7 * 86400.0
MIN_DURATION_S = 1.0
#: what the trial's clinical options mean
TRIAL_TARGET_HELP = (
    "an absolute MAP target (mmHg, {rng}) for every patient from the scenario's step time on, in"
    " place of the scenario's step above each patient's baseline (default: the scenario's step)"
)
TRIAL_DRUG_HELP = (
    "drug in the syringe: must be the design's (a drug-agnostic baseline, pi or smith: the"
    " patient model's); recorded with every patient (default: that drug)"
)
TRIAL_CONCENTRATION_HELP = (
    "syringe concentration (ug/ml): must be the one whose ml/h the design counts (a baseline,"
    " pi or smith: the patient model's or another of the drug library's syringes of its drug,"
    " the patients then responding to each ml/h in proportion); the doses in ug/kg/min are"
    " converted with it (default: that one)"
)
TRIAL_WEIGHT_HELP = (
    "the patients' weight (kg, {rng}): the records' and the table's doses in ug/kg/min are per"
    " this weight (default: the 70 kg reference adult the patient models count, said so)"
)


def _scenarios(argv: Sequence[str]) -> int:
    UsageParser(
        prog="pressor scenarios",
        description="list the named scenarios: name, file, description (any other .toml file"
        " with the same fields can be passed by path: --scenario path/to/file.toml)",
    ).parse_args(argv)
    from pressor.hil_sim.scenarios.scenario import (  # numpy, scipy: after the arguments parse
        SCENARIO_DIR,
        ScenarioError,
        load_scenario,
        scenario_names,
    )

    names = scenario_names()
    width = max(len(n) for n in names)
    files = {name: str(SCENARIO_DIR / f"{name}.toml") for name in names}
    file_width = max(len(f) for f in files.values())
    for name in names:
        try:
            desc = load_scenario(name).description
        except ScenarioError as exc:
            desc = f"INVALID: {exc}"
        print(f"{name:<{width}}  {files[name]:<{file_width}}  {desc}")
    return 0


def _progress_bar(done: int, total: int) -> None:
    width = 30
    filled = int(width * done / total)
    end = "\n" if done == total else ""
    print(
        f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} patients",
        end=end,
        file=sys.stderr,
        flush=True,
    )


def _trial(argv: Sequence[str]) -> int:
    from pressor.runtime.estimation.sources import SOURCES
    from pressor.runtime.inputs.config import (
        CONTROLLER_DEFAULT_HELP,
        SCHEDULE_DEFAULT_HELP,
        SCHEDULE_HELP,
    )
    from pressor.runtime.inputs.controller_loader import shipped_specs
    from pressor.runtime.inputs.defaults import DEFAULT_SCENARIO

    p = UsageParser(prog="pressor trial", description="in-silico cohort trial of a controller")
    p.add_argument(
        "--controller",
        default=None,
        help=f"{CONTROLLER_DEFAULT_HELP}; a shipped controller: {' | '.join(shipped_specs())}"
        " (pressor designs lists them; smith: Smith predictor, lambda 30 s) | PATH to a generated "
        "module | a plugin class MODULE:CLASS[:ARGS] or FILE.py:CLASS[:ARGS] or an installed "
        "'pressor.controllers' entry point NAME[:ARGS] (ARGS: key=value,...); several, "
        "comma-separated (lpv,pi,smith), run the same cohort under each and compare them per "
        "patient",
    )
    p.add_argument(
        "--report",
        action="store_true",
        help="also write OUT/report.html (plots, paired table) and the per-patient trajectories",
    )
    p.add_argument("--patients", type=int, default=20, help="cohort size N (1..100000)")
    p.add_argument("--seed", type=int, default=1, help="cohort seed S (>= 0)")
    p.add_argument(
        "--scenario",
        default=DEFAULT_SCENARIO,
        help="scenario name or .toml path (default %(default)s)",
    )
    p.add_argument(
        "--jobs", type=int, default=1, help="local worker processes, 1..64 (default: %(default)s)"
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run the patients on a running Dask cluster, e.g. tcp://127.0.0.1:8786 "
        "(default: local processes, see --jobs); same records either way",
    )
    p.add_argument(
        "--schedule", choices=SOURCES, default=None, help=f"{SCHEDULE_HELP}{SCHEDULE_DEFAULT_HELP}"
    )
    p.add_argument("--rate", type=float, default=10.0, help="loop rate in Hz (default 10)")
    add_patient_model_option(p)
    p.add_argument(
        "--sensitivity",
        type=float,
        default=1.0,
        metavar="F",
        help="scale every patient's drug sensitivity by F (dimensionless, 0.05..20): the patient"
        " responds to each delivered ml/h as the model's responds to F ml/h, so its K is F times"
        " the model's, T and tau unchanged (hil_sim/patients/sensitivity.py); 1 runs the model as drawn"
        " (default: %(default)g)",
    )
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help=f"simulated time per patient (s, allowed [{MIN_DURATION_S:g}, {MAX_DURATION_S:g}];"
        " default: the scenario's duration_s)",
    )
    add_target_option(p, TRIAL_TARGET_HELP)
    add_syringe_options(p, TRIAL_DRUG_HELP, TRIAL_CONCENTRATION_HELP)
    add_weight_option(p, TRIAL_WEIGHT_HELP)
    p.add_argument(
        "--out",
        required=True,
        type=Path,
        help="output directory (a reused one first loses an earlier run's comparison.json and"
        " report.html)",
    )
    args = p.parse_args(argv)
    try:
        check_int_range("--patients", args.patients, 1, 100000)
        check_int_range("--seed", args.seed, 0, 9_000_000_000_000)
        check_int_range("--jobs", args.jobs, 1, 64)
        check_range("--rate", args.rate, 0.1, 1000.0, unit="Hz")
        check_range("--sensitivity", args.sensitivity, 0.05, 20.0, unit="(dimensionless)")
        if args.duration is not None:
            check_range("--duration", args.duration, MIN_DURATION_S, MAX_DURATION_S, unit="s")
    except ValueError as e:
        p.error(str(e))

    import dataclasses

    from pressor.hil_sim.patients.patient_model import (
        PatientModelError,
        check_model_for_scenario,
    )
    from pressor.hil_sim.patients.sensitivity import with_sensitivity
    from pressor.hil_sim.patients.syringe import check_syringe, patients_on_syringe
    from pressor.hil_sim.scenarios.scenario import ScenarioError, load_scenario
    from pressor.hil_sim.trials.outputs import write_outputs
    from pressor.hil_sim.trials.paired import compare_controllers, format_comparison
    from pressor.hil_sim.trials.report import write_report
    from pressor.hil_sim.trials.table import format_table, format_unreachable
    from pressor.hil_sim.trials.trial import controller_dir_name, run_cohort
    from pressor.plumbing.files import write_atomic
    from pressor.plumbing.parallel import BackendError, WorkerLost
    from pressor.runtime.core.closed_loop import ControllerError
    from pressor.runtime.inputs.config import warn_uncautious
    from pressor.runtime.inputs.controller_loader import ControllerSpecError, load_controller
    from pressor.runtime.inputs.controller_plugin import split_controller_list
    from pressor.runtime.inputs.defaults import default_schedule

    period = 1.0 / args.rate
    try:
        scenario = load_scenario(args.scenario)
        if args.duration is not None:
            scenario = dataclasses.replace(scenario, duration_s=args.duration)
        if args.target_mmhg is not None:
            scenario = dataclasses.replace(scenario, target_mmhg=args.target_mmhg)
        patient_model = with_sensitivity(args.patient_model, args.sensitivity)
        check_model_for_scenario(patient_model, scenario.name, scenario.frozen is not None)
    except (ScenarioError, PatientModelError) as exc:
        raise UsageError(str(exc)) from None
    if args.controller is None:
        from pressor.hil_sim.patients.patient_model import default_design

        args.controller = default_design(args.patient_model)
    specs = split_controller_list(args.controller)
    if "" in specs or len(set(specs)) != len(specs):
        raise UsageError(
            f"field '--controller' = {args.controller!r}: name each controller once, comma-separated"
        )
    drugs = {}
    models: dict[str, str] = {}  # the patients on the run's syringe (a baseline's may differ)
    schedules: dict[str, str] = {}
    for spec in specs:
        try:
            controller = load_controller(spec, period)
            drugs[spec] = check_syringe(
                controller, spec, args.patient_model, args.drug, args.concentration_ug_ml
            )
            models[spec] = patients_on_syringe(patient_model, drugs[spec])
        except (ControllerSpecError, PatientModelError) as exc:
            raise UsageError(str(exc)) from None
        schedules[spec] = args.schedule or default_schedule(controller)
    folders = [controller_dir_name(spec) for spec in specs]
    if len(specs) > 1 and len(set(folders)) != len(folders):
        dup = next(f for f in folders if folders.count(f) > 1)
        same = [spec for spec, f in zip(specs, folders, strict=True) if f == dup]
        raise UsageError(
            f"field '--controller': {' and '.join(same)} would write the same folder {dup!r}"
            " under --out; rename one file or class"
        )
    _remove_stale_outputs(args.out)
    records: dict[str, list[dict[str, Any]]] = {}
    trajectories: dict[str, dict[str, Any]] = {}
    for spec in specs:
        out = args.out if len(specs) == 1 else args.out / controller_dir_name(spec)
        warn_uncautious(spec, schedules[spec], "pressor trial")  # before its cohort runs
        try:
            records[spec], summary, trajectory = run_cohort(
                scenario,
                spec,
                args.seed,
                args.patients,
                traced=args.report,
                jobs=args.jobs,
                sample_period_s=period,
                progress=_progress_bar,
                scheduler=args.scheduler,
                schedule=schedules[spec],
                patient_model=models[spec],
                drug=drugs[spec],
                weight_kg=args.weight_kg,
            )
        except (ControllerError, WorkerLost) as exc:  # a plugin that raised, a worker lost: exit 1
            print(f"pressor trial: {exc}", file=sys.stderr)
            return 1
        except (ValueError, BackendError) as exc:  # e.g. a rate the patient step does not divide
            raise UsageError(str(exc)) from None
        if trajectory is not None:
            trajectories[spec] = trajectory
        write_outputs(out, records[spec], summary)
        print(format_table(summary))
        unreachable = format_unreachable(records[spec])
        if unreachable:
            print(unreachable)
        print(f"wrote {out / 'patients.json'}, {out / 'patients.csv'}, {out / 'summary.json'}")
    comparison = compare_controllers(records) if len(specs) > 1 else {}
    if comparison:
        write_atomic(args.out / "comparison.json", json.dumps(comparison, indent=1) + "\n")
        print(format_comparison(comparison))
        print(f"wrote {args.out / 'comparison.json'}")
    if args.report:
        title = f"{scenario.name}: {', '.join(specs)}; cohort seed {args.seed}, {args.patients} patients"
        path = write_report(args.out, title, records, trajectories, comparison)
        print(f"report: {path}")
    return 0


#: files in ``--out`` that describe a whole run (all its controllers): an earlier run's would sit
#: beside this run's results as if they were its own
RUN_WIDE_OUTPUTS = ("comparison.json", "report.html")


def _remove_stale_outputs(out: Path) -> None:
    """Remove an earlier run's :data:`RUN_WIDE_OUTPUTS` from ``out`` before this run writes (the
    per-controller files are overwritten; these might not be), saying so on stderr."""
    for name in RUN_WIDE_OUTPUTS:
        path = out / name
        if path.is_file():
            try:
                path.unlink()
            except OSError as exc:
                raise UsageError(
                    f"--out {out}: cannot remove an earlier run's {name}: {exc}"
                ) from None
            print(f"pressor trial: removed {path} (an earlier run's)", file=sys.stderr)


def main(command: str, argv: list[str]) -> int:
    """Entry point for the dispatcher: ``scenarios`` or ``trial`` (exit 2 on bad usage or input)."""
    handlers = {"scenarios": _scenarios, "trial": _trial}
    if command not in handlers:
        return usage_exit("pressor.hil_sim.cli", f"unknown command {command!r}")
    return run_command(f"pressor {command}", handlers[command], argv)
