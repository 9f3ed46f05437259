"""The Python API: run what ``pressor trial`` runs (and one patient of it) from Python.

Three functions, three typed results::

    from pressor import api

    run = api.simulate("lpv", "paper-tracking", patient_seed=3, duration_s=600.0)
    run.record["iae_mmhg_s"], run.to_pandas()          # one row per 0.1 s tick

    result = api.trial("pi", "paper-disturbance", n_patients=20, seed=1, jobs=2)
    result.summary["metrics"], result.to_pandas()      # one row per patient (patients.csv)
    result.write("out/")                               # patients.json, patients.csv, summary.json

    both = api.compare(["lpv", "pi"], "paper-disturbance", n_patients=20, seed=1)
    both.comparison["lpv vs pi"]["iae_mmhg_s"]         # paired statistics (comparison.json)
    both.trials["pi"].summary, both.write("out/")      # one folder per controller + comparison.json

All run the code the command runs: :func:`trial` calls :func:`pressor.hil_sim.trials.trial.run_cohort`, as
``pressor trial`` does (same seed, same records, same bytes, whatever ``jobs``), and
:func:`simulate` runs one patient exactly as a trial does (:func:`pressor.hil_sim.trials.trial.run_patient`'s
path: the world, the controller, the runtime's closed-loop core and supervisor, the metrics), which
is tick for tick what a lockstep ``pressor sil`` of that seed gives. ``controller`` is any
``--controller`` spec (``pi``, ``lpv``, ``smith:45``, a generated module, a plugin
``MODULE:CLASS[:ARGS]`` - :mod:`pressor.runtime.inputs.controller_plugin`) or a controller class itself (see
:func:`controller_spec`). ``to_pandas`` needs pandas (``pip install -e ".[pandas]"``).

:func:`compare` runs several controllers on the same patients, as ``pressor trial --controller
lpv,pi`` does. Errors: a bad argument raises :class:`ValueError` naming the argument as this API
spells it (``controller``, ``patient_model``, not a command-line option), the value and the allowed
range (or a subclass: :class:`pressor.runtime.inputs.controller_loader.ControllerSpecError`,
:class:`pressor.hil_sim.scenarios.scenario.ScenarioError`,
:class:`pressor.hil_sim.patients.patient_model.PatientModelError`); a controller that raises mid-run raises :class:`pressor.runtime.core.closed_loop.ControllerError` naming it,
the patient and the tick.
"""

from __future__ import annotations

import dataclasses
import io
import json
import re
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pressor.contracts.checks import check_int_range, check_range
from pressor.contracts.drug import DrugBinding
from pressor.hil_sim.episode import Trajectory
from pressor.hil_sim.patients.patient_model import (
    DEFAULT_PATIENT_MODEL,
    PATIENT_MODELS,
    check_model_for_scenario,
    default_design,
)
from pressor.hil_sim.patients.sensitivity import with_sensitivity
from pressor.hil_sim.patients.syringe import check_syringe, patients_on_syringe
from pressor.hil_sim.scenarios.scenario import Scenario, load_scenario
from pressor.hil_sim.trials.outputs import infusion_record, patients_csv, write_outputs
from pressor.hil_sim.trials.paired import compare_controllers
from pressor.hil_sim.trials.trial import _simulate_patient, controller_dir_name, run_cohort
from pressor.plumbing.files import write_atomic
from pressor.plumbing.parallel import BackendError
from pressor.runtime.core.closed_loop import ControllerError
from pressor.runtime.core.supervisor_config import ALARM_FAULTS, State
from pressor.runtime.estimation.sources import SOURCES
from pressor.runtime.inputs.clinician import TARGET_MAX_MMHG, TARGET_MIN_MMHG
from pressor.runtime.inputs.controller_loader import load_controller
from pressor.runtime.inputs.controller_plugin import split_controller_list
from pressor.runtime.inputs.defaults import DEFAULT_SCENARIO, default_schedule

if TYPE_CHECKING:  # pragma: no cover
    import pandas

__all__ = [
    "ComparisonResult",
    "SimulationResult",
    "TrialResult",
    "compare",
    "controller_spec",
    "simulate",
    "trial",
]

#: the per-tick columns of :meth:`SimulationResult.to_pandas` (name -> Trajectory field)
TICK_COLUMNS = {
    "t_s": "t_s",
    "map_mmhg": "map_mmhg",
    "map_true_mmhg": "map_true_mmhg",
    "target_mmhg": "target_mmhg",
    "command_ml_h": "command_ml_h",
    "rate_ml_h": "rate_ml_h",
    "delivered_ml_h": "delivered_ml_h",
    "K_mmhg_per_ml_h": "K",
    "T_s": "T_s",
    "tau_s": "tau_s",
    "sched_K_mmhg_per_ml_h": "sched_K",
    "sched_T_s": "sched_T_s",
    "sched_tau_s": "sched_tau_s",
    "quality": "quality",
    "pump_alarms": "alarms",
    "faults": "faults",
}


def _pandas() -> Any:
    try:
        import pandas
    except ImportError:
        raise ImportError(
            "to_pandas() needs pandas: pip install -e '.[pandas]' (or pip install pandas)"
        ) from None
    return pandas


@dataclass(frozen=True)
class SimulationResult:
    """One simulated patient (:func:`simulate`).

    Attributes
    ----------
    controller
        The controller spec the run used.
    scenario
        The scenario's name.
    patient_seed
        The patient's seed.
    record
        The patient's record, as ``pressor trial`` writes it in ``patients.json`` (seed,
        coefficients, schedule range, §3 metrics, disturbance events; docs/METRICS.md).
    trajectory
        Every tick (:class:`pressor.hil_sim.episode.Trajectory`: MAP in mmHg, rates in ml/h, K in
        mmHg/(ml/h), T and τ in s, supervisor state and fault bits).
    """

    controller: str
    scenario: str
    patient_seed: int
    record: dict[str, Any]
    trajectory: Trajectory

    @property
    def alarm(self) -> np.ndarray:
        """Per tick, whether the supervisor raised the alarm (HOLD, FAILSAFE or any fault bit)."""
        state = self.trajectory.state
        return (
            (state == int(State.HOLD))
            | (state == int(State.FAILSAFE))
            | ((self.trajectory.faults & ALARM_FAULTS) != 0)
        )

    def to_pandas(self) -> pandas.DataFrame:
        """One row per tick: :data:`TICK_COLUMNS`, ``state`` (the supervisor state's name) and
        ``alarm`` (bool)."""
        pd = _pandas()
        tr = self.trajectory
        frame = pd.DataFrame({col: getattr(tr, field) for col, field in TICK_COLUMNS.items()})
        frame["state"] = [State(int(s)).name for s in tr.state]
        frame["alarm"] = self.alarm
        return frame


@dataclass(frozen=True)
class TrialResult:
    """A cohort trial (:func:`trial`): what ``pressor trial`` prints and writes.

    Attributes
    ----------
    controller, scenario, cohort_seed, n_patients
        The trial's identity.
    records
        One record per patient, in cohort order (``patients.json``).
    summary
        The ``summary.json`` document (aggregated metrics, unreachable and unstable seeds).
    trajectories
        With ``trajectories=True``: the 1 Hz trajectories (``t_s`` (ticks,), ``map_true_mmhg``,
        ``target_mmhg`` in mmHg and ``rate_ml_h`` in ml/h (patients x ticks), ``patient_seed``);
        else ``None``.
    """

    controller: str
    scenario: str
    cohort_seed: int
    n_patients: int
    records: list[dict[str, Any]]
    summary: dict[str, Any]
    trajectories: dict[str, np.ndarray] | None = None

    def to_pandas(self, trajectories: bool = False) -> pandas.DataFrame:
        """The per-patient table, with the columns of ``patients.csv`` (units in the names).

        Parameters
        ----------
        trajectories
            Instead, the trajectories in long form: one row per patient and second, columns
            ``patient_seed``, ``t_s``, ``map_true_mmhg``, ``target_mmhg``, ``rate_ml_h``
            (needs ``trial(..., trajectories=True)``).
        """
        pd = _pandas()
        if not trajectories:
            text = patients_csv(self.records, self.summary["coefficient_units"])
            return pd.read_csv(io.StringIO(text))
        tr = self.trajectories
        if tr is None:
            raise ValueError("to_pandas(trajectories=True): run trial(..., trajectories=True)")
        n, ticks = tr["map_true_mmhg"].shape
        return pd.DataFrame(
            {
                "patient_seed": np.repeat(tr["patient_seed"], ticks),
                "t_s": np.tile(tr["t_s"], n),
                **{k: tr[k].ravel() for k in ("map_true_mmhg", "target_mmhg", "rate_ml_h")},
            }
        )

    def write(self, out_dir: str | Path) -> Path:
        """Write ``patients.json``, ``patients.csv`` and ``summary.json`` (the bytes ``pressor
        trial`` writes for the same arguments) into ``out_dir``; returns it."""
        out = Path(out_dir)
        write_outputs(out, self.records, self.summary)
        return out


@dataclass(frozen=True)
class ComparisonResult:
    """Several controllers on the same patients (:func:`compare`): what ``pressor trial
    --controller A,B,...`` prints and writes.

    Attributes
    ----------
    controllers
        The controller specs, in the order given; the first is compared with each other one.
    scenario, cohort_seed, n_patients
        The cohort every controller ran on.
    trials
        Spec -> that controller's :class:`TrialResult` (the same patients, in cohort order).
    comparison
        The paired comparison, ``"A vs B" -> metric -> statistics`` (``n``, ``win_rate_pct``,
        ``median_ratio``, ``median_difference``, ``wilcoxon_p``): the ``comparison.json``
        document (:func:`pressor.hil_sim.trials.paired.compare_controllers`).
    """

    controllers: tuple[str, ...]
    scenario: str
    cohort_seed: int
    n_patients: int
    trials: dict[str, TrialResult]
    comparison: dict[str, dict[str, dict[str, Any]]]

    def write(self, out_dir: str | Path) -> Path:
        """Write what ``pressor trial`` writes for several controllers: one folder per
        controller (``patients.json``, ``patients.csv``, ``summary.json``) and
        ``comparison.json``, the same bytes; returns ``out_dir``."""
        out = Path(out_dir)
        for spec, result in self.trials.items():
            result.write(out / controller_dir_name(spec))
        write_atomic(out / "comparison.json", json.dumps(self.comparison, indent=1) + "\n")
        return out


def controller_spec(controller: str | type, args: Mapping[str, Any] | None = None) -> str:
    """The ``--controller`` spec of ``controller``.

    Parameters
    ----------
    controller
        A spec (returned as is), or a class satisfying :class:`pressor.contracts.controller.Controller`:
        ``module:Class``, or ``FILE.py:Class`` for a class of the script being run (``__main__``),
        so that worker processes import it again from its file.
    args
        Constructor keyword arguments of a class (Python literals: numbers, bools, strings
        without commas), appended as ``:key=value,...``.

    Raises
    ------
    ValueError
        ``args`` with a string spec, or a value that does not survive the spec's text.
    """
    if not isinstance(controller, str | type):
        raise ValueError(
            f"controller = {controller!r}: allowed a controller spec (str: 'lpv', 'pi',"
            " 'smith:45', a generated module's path, 'MODULE:CLASS[:ARGS]') or a controller class"
        )
    if isinstance(controller, str):
        if args:
            raise ValueError("controller_args: give them in the spec (MODULE:CLASS:key=value,...)")
        return controller
    module = controller.__module__
    if module == "__main__":
        module = str(Path(sys.modules["__main__"].__file__ or "").resolve())
    spec = f"{module}:{controller.__qualname__}"
    if args:
        items = [f"{k}={v!r}" for k, v in args.items()]
        if any("," in item for item in items):
            raise ValueError(f"controller_args {dict(args)!r}: values must not contain ','")
        spec += ":" + ",".join(items)
    return spec


def _scenario(
    scenario: str | Path | Scenario, duration_s: float | None, target_mmhg: float | None = None
) -> Scenario:
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if duration_s is not None:
        check_range("duration_s", duration_s, 1.0, 7 * 86400.0, unit="s")
        sc = dataclasses.replace(sc, duration_s=float(duration_s))
    if target_mmhg is not None:
        check_range("target_mmhg", target_mmhg, TARGET_MIN_MMHG, TARGET_MAX_MMHG, unit="mmHg")
        sc = dataclasses.replace(sc, target_mmhg=float(target_mmhg))
    return sc


@dataclass(frozen=True)
class _Clinical:
    """The API's clinical arguments: an absolute target (mmHg), the syringe's drug and
    concentration (µg/ml) and the patients' weight (kg); ``None``: not given."""

    target_mmhg: float | None = None
    drug: str | None = None
    concentration_ug_ml: float | None = None
    weight_kg: float | None = None

    def check(self) -> None:
        """Each value in its range, errors naming the API's argument."""
        from pressor.contracts.drug import MAX_CONCENTRATION_UG_ML
        from pressor.runtime.inputs.clinician import parse_drug
        from pressor.runtime.inputs.drug_library import WEIGHT_MAX_KG, WEIGHT_MIN_KG

        if self.drug is not None:
            if not isinstance(self.drug, str):
                raise ValueError(f"drug = {self.drug!r}: allowed a drug name (str)")
            try:
                parse_drug(self.drug)
            except ValueError as exc:
                raise ValueError(f"drug {exc}") from None
        if self.concentration_ug_ml is not None:
            check_range(
                "concentration_ug_ml",
                self.concentration_ug_ml,
                0.0,
                MAX_CONCENTRATION_UG_ML,
                lo_open=True,
                unit="ug/ml",
            )
        if self.weight_kg is not None:
            check_range("weight_kg", self.weight_kg, WEIGHT_MIN_KG, WEIGHT_MAX_KG, unit="kg")


#: command-line option -> the API's argument, for errors raised by the code both share
_API_NAMES = {
    "--controller": "controller",
    "--scenario": "scenario",
    "--patient-model": "patient_model",
    "--scheduler": "scheduler",
}
_OPTION = re.compile(r"^(field ')?(--controller|--scenario|--patient-model|--scheduler)\b")


@contextmanager
def _in_api_terms() -> Iterator[None]:
    """Re-raise an error of the code the command line shares (a loader's :class:`ValueError`, a
    :class:`pressor.plumbing.parallel.BackendError`, a
    :class:`pressor.runtime.core.closed_loop.ControllerError`) that names a command-line option
    (``--controller 'x': ...``) with the API's argument in its place (``controller 'x': ...``),
    same type."""
    try:
        yield
    except (ValueError, BackendError, ControllerError) as exc:
        text = str(exc)
        match = _OPTION.match(text)
        if match is None:
            raise
        renamed = (match.group(1) or "") + _API_NAMES[match.group(2)] + text[match.end() :]
        raise type(exc)(renamed) from None


def _check_rate(rate_hz: float, sc: Scenario) -> float:
    """The loop period (s) of ``rate_hz`` (Hz), which must be a whole multiple of the scenario's
    patient step (as :class:`pressor.hil_sim.world.World` requires); errors name ``rate_hz``."""
    check_range("rate_hz", rate_hz, 0.1, 1000.0, unit="Hz")
    period_s = 1.0 / rate_hz
    n_sub = round(period_s / sc.internal_step_s)
    if n_sub < 1 or abs(n_sub * sc.internal_step_s - period_s) > 1e-9 * period_s:
        raise ValueError(
            f"rate_hz = {rate_hz!r}: its period {period_s:g} s must be a whole multiple of"
            f" scenario {sc.name!r}'s patient step {sc.internal_step_s:g} s (e.g. rate_hz ="
            f" {1.0 / sc.internal_step_s:g})"
        )
    return period_s


def _checked(
    controller: str | type | None,
    controller_args: Mapping[str, Any] | None,
    scenario: str | Path | Scenario,
    duration_s: float | None,
    rate_hz: float,
    schedule: str | None,
    patient_model: str,
    clinical: _Clinical = _Clinical(),
) -> tuple[str, Scenario, float, str, DrugBinding, str]:
    """(spec, scenario, period s, schedule, the run's drug and syringe, the patient model on that
    syringe: :func:`pressor.hil_sim.patients.syringe.patients_on_syringe`) after the checks
    ``pressor trial`` makes before it runs (a design meets only its drug:
    :func:`pressor.hil_sim.patients.syringe.check_syringe`), the defaults resolved as
    ``pressor trial`` resolves them (the patient model's drug's design and that design's
    schedule: :mod:`pressor.runtime.inputs.defaults`); errors name the API's arguments
    (``controller``), not the command line's (``--controller``)."""
    check_range("rate_hz", rate_hz, 0.1, 1000.0, unit="Hz")
    if schedule is not None and schedule not in SOURCES:
        raise ValueError(f"schedule = {schedule!r}: allowed {', '.join(SOURCES)}")
    if controller is None:
        with _in_api_terms():
            controller = default_design(patient_model)
    spec = controller_spec(controller, controller_args)
    if isinstance(controller, str) and len(split_controller_list(controller)) > 1:
        raise ValueError(
            f"controller = {controller!r} names several controllers: compare([...]) runs several"
            " on the same patients"
        )
    clinical.check()
    with _in_api_terms():
        sc = _scenario(scenario, duration_s, clinical.target_mmhg)
        check_model_for_scenario(patient_model, sc.name, sc.frozen is not None)
        period_s = _check_rate(rate_hz, sc)
        loaded = load_controller(spec, period_s)  # fail fast, naming the spec
        drug = check_syringe(
            loaded,
            spec,
            patient_model,
            None if clinical.drug is None else clinical.drug.strip().lower(),
            clinical.concentration_ug_ml,
            fields=("controller", "patient_model", "drug", "concentration_ug_ml"),
        )
        patients = patients_on_syringe(patient_model, drug, "concentration_ug_ml")
    return spec, sc, period_s, schedule or default_schedule(loaded), drug, patients


def _with_sensitivity(patient_model: str, sensitivity: float) -> str:
    """:func:`pressor.hil_sim.patients.sensitivity.with_sensitivity`, its errors naming the API's
    arguments (``patient_model``, ``sensitivity``)."""
    if not isinstance(patient_model, str):
        raise ValueError(
            f"patient_model = {patient_model!r}: allowed a model name (str: one of"
            f" {', '.join(PATIENT_MODELS)}) or 'MODULE:CLASS'"
        )
    with _in_api_terms():
        return with_sensitivity(patient_model, sensitivity)


def simulate(
    controller: str | type | None = None,
    scenario: str | Path | Scenario = DEFAULT_SCENARIO,
    patient_seed: int = 1,
    *,
    controller_args: Mapping[str, Any] | None = None,
    duration_s: float | None = None,
    rate_hz: float = 10.0,
    schedule: str | None = None,
    patient_model: str = DEFAULT_PATIENT_MODEL,
    sensitivity: float = 1.0,
    target_mmhg: float | None = None,
    drug: str | None = None,
    concentration_ug_ml: float | None = None,
    weight_kg: float | None = None,
) -> SimulationResult:
    """Simulate one patient in process, as one patient of ``pressor trial``.

    Parameters
    ----------
    controller
        A ``--controller`` spec or a controller class (:func:`controller_spec`); default the
        patient model's drug's design on a log-K scale (``lpv:cautious`` for phenylephrine,
        :mod:`pressor.runtime.inputs.defaults`).
    scenario
        A scenario name (``pressor scenarios``), a ``.toml`` path or a :class:`Scenario`.
    patient_seed
        The patient's seed, [0, 2**63).
    controller_args
        Keyword arguments of a controller class.
    duration_s
        Simulated time (s), [1, 604800]; default the scenario's ``duration_s``.
    rate_hz
        Loop rate (Hz), [0.1, 1000].
    schedule
        Where K, T, τ come from: ``oracle``, ``estimated``, ``nominal``, ``validated`` or
        ``cautious``; default ``cautious`` for a design on a log-K scale, ``estimated`` for any
        other.
    patient_model
        A patient model name or ``MODULE:CLASS`` (:mod:`pressor.hil_sim.patients.patient_model`).
    sensitivity
        The patient's drug sensitivity × this factor (dimensionless, [0.05, 20];
        :mod:`pressor.hil_sim.patients.sensitivity`); 1 (default) runs the model as drawn, byte for byte.
    target_mmhg
        An absolute MAP target (mmHg, [50, 120]) from the scenario's step time on, in place of
        the scenario's step above the patient's baseline; default the scenario's step.
    drug, concentration_ug_ml
        The syringe's drug and concentration (µg/ml), checked against the run's: the design's (a
        drug-agnostic baseline, ``pi`` or ``smith``: the patient model's); a design for another
        drug than the patient model's is refused naming both. Default: the run's.
    weight_kg
        The patient's weight (kg, [30, 250]) the record's doses in µg/kg/min are per; default
        the 70 kg reference adult (the record's ``infusion.weight_given`` is then false).

    Returns
    -------
    SimulationResult
    """
    check_int_range("patient_seed", patient_seed, 0, 2**63 - 1)
    patient_model = _with_sensitivity(patient_model, sensitivity)
    clinical = _Clinical(target_mmhg, drug, concentration_ug_ml, weight_kg)
    spec, sc, period_s, schedule, binding, patient_model = _checked(
        controller,
        controller_args,
        scenario,
        duration_s,
        rate_hz,
        schedule,
        patient_model,
        clinical,
    )
    with _in_api_terms():  # a controller that raises: ControllerError naming `controller`
        record, traj = _simulate_patient(sc, spec, patient_seed, period_s, schedule, patient_model)
    record["infusion"] = infusion_record(record, binding, weight_kg, sc.duration_s)
    return SimulationResult(spec, sc.name, int(patient_seed), record, traj)


def trial(
    controller: str | type | None = None,
    scenario: str | Path | Scenario = DEFAULT_SCENARIO,
    n_patients: int = 20,
    seed: int = 1,
    *,
    controller_args: Mapping[str, Any] | None = None,
    jobs: int = 1,
    scheduler: str | None = None,
    duration_s: float | None = None,
    rate_hz: float = 10.0,
    schedule: str | None = None,
    patient_model: str = DEFAULT_PATIENT_MODEL,
    sensitivity: float = 1.0,
    trajectories: bool = False,
    progress: Callable[[int, int], None] | None = None,
    target_mmhg: float | None = None,
    drug: str | None = None,
    concentration_ug_ml: float | None = None,
    weight_kg: float | None = None,
) -> TrialResult:
    """Run a cohort trial, as ``pressor trial`` does (same records for the same arguments).

    Parameters
    ----------
    controller
        A ``--controller`` spec or a controller class (:func:`controller_spec`); default as
        :func:`simulate`'s.
    scenario
        A scenario name, a ``.toml`` path or a :class:`Scenario`.
    n_patients
        Cohort size, [1, 100000].
    seed
        Cohort seed, [0, 9e12].
    controller_args
        Keyword arguments of a controller class.
    jobs
        Local worker processes, [1, 64]; does not change the results.
    scheduler
        A Dask scheduler address (``tcp://HOST:PORT``) instead of local processes.
    duration_s
        Simulated time per patient (s); default the scenario's.
    rate_hz, schedule, patient_model, sensitivity
        As :func:`simulate`.
    trajectories
        Also keep every patient's trajectory at 1 Hz (:attr:`TrialResult.trajectories`).
    progress
        Called with ``(done, total)`` after each patient.
    target_mmhg, drug, concentration_ug_ml, weight_kg
        As :func:`simulate`, for every patient (``pressor trial --target-mmhg``, ``--drug``,
        ``--concentration-ug-ml``, ``--weight-kg``).

    Returns
    -------
    TrialResult
    """
    for name, value, lo, hi in (
        ("n_patients", n_patients, 1, 100000),
        ("seed", seed, 0, 9_000_000_000_000),
        ("jobs", jobs, 1, 64),
    ):
        check_int_range(name, value, lo, hi)
    patient_model = _with_sensitivity(patient_model, sensitivity)
    clinical = _Clinical(target_mmhg, drug, concentration_ug_ml, weight_kg)
    spec, sc, period_s, schedule, binding, patient_model = _checked(
        controller,
        controller_args,
        scenario,
        duration_s,
        rate_hz,
        schedule,
        patient_model,
        clinical,
    )
    with _in_api_terms():  # an unusable scheduler, a controller that raises
        records, summary, traj = run_cohort(
            sc,
            spec,
            seed,
            n_patients,
            traced=trajectories,
            jobs=jobs,
            sample_period_s=period_s,
            progress=progress,
            scheduler=scheduler,
            schedule=schedule,
            patient_model=patient_model,
            drug=binding,
            weight_kg=weight_kg,
        )
    return TrialResult(spec, sc.name, int(seed), n_patients, records, summary, traj)


def compare(
    controllers: Sequence[str | type] | str,
    scenario: str | Path | Scenario = DEFAULT_SCENARIO,
    n_patients: int = 20,
    seed: int = 1,
    *,
    jobs: int = 1,
    scheduler: str | None = None,
    duration_s: float | None = None,
    rate_hz: float = 10.0,
    schedule: str | None = None,
    patient_model: str = DEFAULT_PATIENT_MODEL,
    sensitivity: float = 1.0,
    trajectories: bool = False,
    progress: Callable[[str, int, int], None] | None = None,
    target_mmhg: float | None = None,
    drug: str | None = None,
    concentration_ug_ml: float | None = None,
    weight_kg: float | None = None,
) -> ComparisonResult:
    """Run several controllers on the same patients and compare them in pairs, as ``pressor trial
    --controller A,B,...`` does (the same records and the same ``comparison.json``).

    Parameters
    ----------
    controllers
        Two or more controllers, each a spec or a controller class (:func:`controller_spec`), or
        one comma-separated string of specs (``"lpv,pi"``); each named once. The first is compared
        with each of the others.
    scenario, n_patients, seed, jobs, scheduler, duration_s, rate_hz, schedule, patient_model, \
sensitivity, trajectories, target_mmhg, drug, concentration_ug_ml, weight_kg
        As :func:`trial`, the same for every controller (``schedule`` None: each controller's
        default).
    progress
        Called with ``(spec, done, total)`` after each patient of each controller.

    Returns
    -------
    ComparisonResult

    Raises
    ------
    ValueError
        Fewer than two controllers, one named twice, or any argument :func:`trial` refuses; every
        controller is checked before any runs.
    """
    given = split_controller_list(controllers) if isinstance(controllers, str) else controllers
    specs = [controller_spec(c) for c in given]
    if len(specs) < 2 or "" in specs or len(set(specs)) != len(specs):
        raise ValueError(
            f"controllers = {specs!r}: name two or more controllers, each once (one controller:"
            " trial())"
        )
    clinical = _Clinical(target_mmhg, drug, concentration_ug_ml, weight_kg)
    for spec in specs:  # every controller checked before any runs
        _checked(
            spec,
            None,
            scenario,
            duration_s,
            rate_hz,
            schedule,
            _with_sensitivity(patient_model, sensitivity),
            clinical,
        )
    trials: dict[str, TrialResult] = {}
    for spec in specs:
        trials[spec] = trial(
            spec,
            scenario,
            n_patients,
            seed,
            jobs=jobs,
            scheduler=scheduler,
            duration_s=duration_s,
            rate_hz=rate_hz,
            schedule=schedule,
            patient_model=patient_model,
            sensitivity=sensitivity,
            trajectories=trajectories,
            progress=None if progress is None else (lambda d, t, s=spec: progress(s, d, t)),
            target_mmhg=target_mmhg,
            drug=drug,
            concentration_ug_ml=concentration_ug_ml,
            weight_kg=weight_kg,
        )
    comparison = compare_controllers({spec: r.records for spec, r in trials.items()})
    first = trials[specs[0]]
    return ComparisonResult(
        tuple(specs), first.scenario, first.cohort_seed, n_patients, trials, comparison
    )
