"""Patient models as plugins: the :class:`PatientModel` protocol, the named models, the loader.

The world (:class:`pressor.hil_sim.world.World`) needs five things from a patient, whatever its equations:
build it from a seed and an internal step, advance it one internal step under the rate the pump
delivered, read its MAP, report K, T, τ for the scheduling truth and the records, and say how far
its steady state can go at the pump's maximum (``reachable``). :class:`PatientModel` writes that
down; any class that has those members plays in ``pressor trial``, ``pressor sil`` and
``pressor device`` (``--patient-model NAME|MODULE:CLASS``).

Named models (:data:`PATIENT_MODELS`; docs/PATIENTS.md lists equations, ranges and sources):

``paper`` (default)
    The seed paper's nonlinear first order plus time-varying delay
    (:class:`pressor.hil_sim.patients.patient.Patient`); K, T, τ are the model's own.
``pkpd``
    Two-compartment pharmacokinetics, effect site, sigmoid Emax, tachyphylaxis
    (:class:`pressor.hil_sim.patients.pkpd.PkpdPatient`, the model of ``benchmarks/independent_patients.py``).
``phenylephrine-2c``
    Phenylephrine's label two-compartment kinetics, effect site, Emax and a baroreflex-like
    counter-regulation (:class:`pressor.hil_sim.patients.phenylephrine.Phenylephrine2C`).
``norepinephrine``
    Norepinephrine at 16 µg/ml: one-compartment kinetics with severity-dependent clearance, effect
    lag and site, Hill curve, turnover counter-regulation
    (:class:`pressor.hil_sim.patients.norepinephrine.Norepinephrine1C`).

Every model draws its patient from ``patient_seed`` alone (same seed, same patient, same bytes);
the draw must not depend on the process, the worker or the order patients run in.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import math
from collections.abc import Mapping
from typing import ClassVar, Protocol, runtime_checkable

from pressor.contracts.drug import DrugBinding

#: the model a run uses when none is named
DEFAULT_PATIENT_MODEL = "paper"

#: name -> ``module:Class`` of the shipped models
PATIENT_MODELS: dict[str, str] = {
    "paper": "pressor.hil_sim.patients.patient:Patient",
    "pkpd": "pressor.hil_sim.patients.pkpd:PkpdPatient",
    "phenylephrine-2c": "pressor.hil_sim.patients.phenylephrine:Phenylephrine2C",
    "norepinephrine": "pressor.hil_sim.patients.norepinephrine:Norepinephrine1C",
}

#: name -> (drug and syringe its ml/h count, what it is, its source) of every shipped model, for
#: ``pressor patients`` (docs/PATIENTS.md gives the equations and ranges); a model added to
#: :data:`PATIENT_MODELS` gets its line here (tests/hil_sim/patients/test_patient_model.py)
PATIENT_MODEL_NOTES: dict[str, tuple[str, str, str]] = {
    "paper": (
        "phenylephrine",
        "nonlinear first order plus time-varying delay, K, T, tau driven by the infusion",
        "Tasoujian, Grigoriadis and Franchek, DSCC 2019 (Table 1)",
    ),
    "pkpd": (
        "phenylephrine 100 µg/ml",
        "two-compartment kinetics, effect site, sigmoid Emax, tachyphylaxis (a benchmark"
        " population, not fitted values)",
        "Hengstmann and Goronzy 1982; Sheiner et al. 1979; Porchet, Benowitz and Sheiner 1988",
    ),
    "phenylephrine-2c": (
        "phenylephrine 100 µg/ml",
        "label two-compartment kinetics, effect site, Emax, baroreflex-like counter-regulation",
        "US label (FDA NDA 203826) after Hengstmann and Goronzy 1982; Su et al. 2023",
    ),
    "norepinephrine": (
        "norepinephrine 16 µg/ml",
        "one compartment with severity-dependent clearance, endogenous production, effect site,"
        " Hill curve, turnover counter-regulation",
        "Beloeil et al., Br J Anaesth 2005; Li et al., Clin Pharmacokinet 2024",
    ),
}

#: name -> the drug and syringe (µg/ml) each shipped model is a patient of: its ml/h count that
#: syringe's (docs/PATIENTS.md). A design meets only its drug (:func:`check_drug`); a model added to
#: :data:`PATIENT_MODELS` gets its drug here (tests/hil_sim/patients/test_patient_model.py). A plugin
#: model names its own with class attributes ``DRUG`` and ``DRUG_CONCENTRATION_UG_ML``.
PATIENT_MODEL_DRUGS: dict[str, DrugBinding] = {
    "paper": DrugBinding("phenylephrine", 100.0),
    "pkpd": DrugBinding("phenylephrine", 100.0),
    "phenylephrine-2c": DrugBinding("phenylephrine", 100.0),
    "norepinephrine": DrugBinding("norepinephrine", 16.0),  # norepinephrine.CONCENTRATION_UG_ML
}

#: members a model class must have (methods, except the mapping ``coefficient_units``)
CLASS_MEMBERS = ("from_seed", "step", "coefficients", "max_delta_map_mmhg", "coefficient_units")
#: numeric members a model instance must have (attributes or properties, float)
INSTANCE_MEMBERS = ("baseline_mmhg", "map_mmhg", "delta_map_mmhg", "K", "T_s", "tau_s")


@runtime_checkable
class PatientModel(Protocol):
    """What the world needs from a simulated patient (units in the names).

    ``K`` (mmHg/(ml/h)), ``T_s`` (s) and ``tau_s`` (s) feed the scheduling truth the oracle
    schedule gives the controller, and the records' ``schedule_range``. A model that is not a first
    order plus delay reports *apparent* values and documents them (each shipped model: the MAP rise
    per extra ml/h once its fast dynamics settled, the sum of its fast time constants, its
    transport delay); none may be NaN, the controllers are scheduled on them.

    Attributes
    ----------
    coefficient_units
        Unit of every key :meth:`coefficients` returns (class attribute).
    baseline_mmhg
        MAP without drug (mmHg); the world's target is relative to it.
    map_mmhg
        MAP now without the scenario's disturbances (mmHg): ``baseline_mmhg + delta_map_mmhg``.
    delta_map_mmhg
        The drug's MAP change now (mmHg).
    K, T_s, tau_s
        Sensitivity (mmHg/(ml/h)), lag (s), transport delay (s) now: true or apparent.
    """

    coefficient_units: ClassVar[Mapping[str, str]]

    @classmethod
    def from_seed(cls, patient_seed: int, step_s: float) -> PatientModel:
        """The patient of ``patient_seed`` (an int in [0, 2**63)), stepped every ``step_s`` s."""
        ...

    @property
    def baseline_mmhg(self) -> float: ...

    @property
    def map_mmhg(self) -> float: ...

    @property
    def delta_map_mmhg(self) -> float: ...

    @property
    def K(self) -> float: ...

    @property
    def T_s(self) -> float: ...

    @property
    def tau_s(self) -> float: ...

    def step(self, rate_ml_h: float) -> None:
        """Advance one internal step with the pump delivering ``rate_ml_h`` (ml/h, mean)."""
        ...

    def coefficients(self) -> dict[str, float]:
        """The patient's drawn constants, JSON-ready (the trial records' ``coefficients``)."""
        ...

    def max_delta_map_mmhg(self, max_rate_ml_h: float) -> float:
        """Largest steady-state ΔMAP (mmHg) any constant rate in [0, ``max_rate_ml_h``] holds."""
        ...


class PatientModelError(ValueError):
    """A ``--patient-model`` that cannot be used (the message names module, class and reason)."""


def model_spec(spec: str) -> tuple[str, str]:
    """``(module, class)`` of a registry name or a ``MODULE:CLASS`` spec.

    Raises
    ------
    PatientModelError
        An unknown name, or a spec that is not ``MODULE:CLASS``.
    """
    target = PATIENT_MODELS.get(spec, spec)
    module, sep, cls = target.partition(":")
    if not sep or not module or not cls or ":" in cls:
        raise PatientModelError(
            f"--patient-model {spec!r}: unknown model; one of {', '.join(PATIENT_MODELS)}"
            " or MODULE:CLASS (a class satisfying pressor.hil_sim.patients.patient_model.PatientModel)"
        )
    return module, cls


@functools.cache
def load_patient_model(spec: str) -> type[PatientModel]:
    """The model class of ``spec`` (a :data:`PATIENT_MODELS` name or ``MODULE:CLASS``), checked.

    The check imports the module, finds the class, looks for every member of
    :class:`PatientModel` on it and on the patient of seed 0 at a 0.1 s step, and checks that
    patient's coefficients have units. Loaded once per process.

    Raises
    ------
    PatientModelError
        Naming the spec, the module, the class and what is missing or wrong.

    Notes
    -----
    ``MODEL@sensitivity=F`` gives ``MODEL``'s patients at F × their drug sensitivity
    (:mod:`pressor.hil_sim.patients.sensitivity`; F in [0.05, 20]).
    """
    from pressor.hil_sim.patients.sensitivity import (
        scaled_model,
        split_spec,
    )  # it imports this module

    base, factor = split_spec(spec)
    if factor is not None:
        return scaled_model(load_patient_model(base), factor)  # type: ignore[return-value]
    module_name, cls_name = model_spec(spec)
    where = f"--patient-model {spec!r}"
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise PatientModelError(f"{where}: cannot import module {module_name!r}: {exc}") from None
    cls = getattr(module, cls_name, None)
    if not isinstance(cls, type):
        raise PatientModelError(f"{where}: module {module_name!r} has no class {cls_name!r}")
    what = f"{where}: class {cls_name!r} of module {module_name!r}"
    missing = [
        m
        for m in CLASS_MEMBERS
        if not (hasattr(cls, m) if m == "coefficient_units" else callable(getattr(cls, m, None)))
    ]
    if missing:
        raise PatientModelError(
            f"{what} does not satisfy pressor.hil_sim.patients.patient_model.PatientModel: missing (or not"
            f" callable) {', '.join(missing)}"
        )
    try:
        probe = cls.from_seed(0, 0.1)  # type: ignore[attr-defined]
        missing = [m for m in INSTANCE_MEMBERS if not _is_number(getattr(probe, m, None))]
        coefficients = probe.coefficients()
    except Exception as exc:  # a plugin's own error: reported, not raised through
        raise PatientModelError(
            f"{what}: from_seed(0, 0.1) or coefficients() failed: {exc!r}"
        ) from None
    if missing:
        raise PatientModelError(
            f"{what} does not satisfy pressor.hil_sim.patients.patient_model.PatientModel: its patients have no"
            f" numeric {', '.join(missing)}"
        )
    no_unit = [k for k in coefficients if k not in cls.coefficient_units]  # type: ignore[attr-defined]
    if no_unit:
        raise PatientModelError(f"{what}: coefficient_units has no unit for {', '.join(no_unit)}")
    return cls  # type: ignore[return-value]


def check_model_for_scenario(spec: str, scenario_name: str, frozen: bool) -> type[PatientModel]:
    """:func:`load_patient_model`, refusing any model but ``paper`` on a frozen scenario (one that
    fixes the paper model's LTI mode, ``patient.mode = "frozen"``).

    Raises
    ------
    PatientModelError
        As :func:`load_patient_model`, or naming the scenario a model cannot play.
    """
    model = load_patient_model(spec)
    if frozen and ("@" in spec or model_spec(spec) != model_spec(DEFAULT_PATIENT_MODEL)):
        raise PatientModelError(
            f"--patient-model {spec!r}: scenario {scenario_name!r} fixes a frozen first-order"
            f' patient (patient.mode = "frozen"); only --patient-model {DEFAULT_PATIENT_MODEL}'
            " (without a sensitivity factor) plays it"
        )
    return model


def add_patient_model_option(parser: argparse.ArgumentParser) -> None:
    """Add ``--patient-model NAME|MODULE:CLASS`` (default ``paper``) to ``parser``; the value is
    checked by :func:`load_patient_model` where the command starts its run."""
    parser.add_argument(
        "--patient-model",
        default=DEFAULT_PATIENT_MODEL,
        metavar="NAME|MODULE:CLASS",
        help=f"the simulated patient: {', '.join(PATIENT_MODELS)} (docs/PATIENTS.md), or a class"
        " satisfying pressor.hil_sim.patients.patient_model.PatientModel; MODEL@sensitivity=F scales its drug"
        " sensitivity by F in [0.05, 20] (default: %(default)s, the seed paper's)",
    )


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and not math.isnan(value)


def model_drug(spec: str) -> DrugBinding | None:
    """The drug and syringe the patients of ``spec`` (a registry name, ``MODULE:CLASS``, either
    with ``@sensitivity=F``) are patients of: :data:`PATIENT_MODEL_DRUGS`, or a plugin class's
    ``DRUG`` and ``DRUG_CONCENTRATION_UG_ML``; ``None`` for a plugin that names none.

    Raises
    ------
    PatientModelError
        A model that does not load (:func:`load_patient_model`), or a plugin's drug that is not
        valid.
    """
    from pressor.hil_sim.patients.sensitivity import split_spec  # it imports this module

    base = split_spec(spec)[0]
    if base in PATIENT_MODEL_DRUGS:
        return PATIENT_MODEL_DRUGS[base]
    cls = load_patient_model(base)
    if not hasattr(cls, "DRUG"):
        return None
    try:
        return DrugBinding(str(cls.DRUG), float(getattr(cls, "DRUG_CONCENTRATION_UG_ML", math.nan)))
    except ValueError as exc:
        raise PatientModelError(f"--patient-model {spec!r}: {exc}") from None


def default_design(spec: str) -> str:
    """The controller a run on ``spec``'s patients defaults to: their drug's design
    (:func:`pressor.runtime.inputs.defaults.default_controller` of :func:`model_drug`).

    Raises
    ------
    PatientModelError
        As :func:`model_drug`.
    """
    from pressor.runtime.inputs.defaults import default_controller

    binding = model_drug(spec)
    return default_controller(None if binding is None else binding.name)
