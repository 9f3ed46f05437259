"""The drug and syringe a simulated run uses, checked against the controller and the patients.

A design meets only its drug, at the syringe whose ml/h its gains count
(:func:`pressor.contracts.drug.binding_of`). A drug-agnostic baseline (PI, Smith:
:func:`pressor.contracts.drug.drug_agnostic`) runs on the patient model's drug, on the model's
syringe or on any other syringe of that drug in the shipped drug library
(``runtime/inputs/drug_library.toml``), as a clinician would load one: the patients then receive
``c / c_model`` ml/h of the model's syringe for every ml/h of a ``c`` µg/ml one, i.e. they respond
to each ml/h ``c / c_model`` times as strongly (:func:`patients_on_syringe`, the sensitivity wrapper
of :mod:`pressor.hil_sim.patients.sensitivity`), and the records count doses with ``c``.
"""

from __future__ import annotations

import math
from typing import Any

from pressor.contracts.drug import DrugBinding
from pressor.hil_sim.patients.patient_model import PatientModelError, model_drug
from pressor.hil_sim.patients.sensitivity import SENSITIVITY_RANGE, split_spec, with_sensitivity

__all__ = ["check_drug", "check_syringe", "library_concentrations", "patients_on_syringe"]


def library_concentrations(drug: str) -> tuple[float, ...]:
    """The syringe concentrations (µg/ml) the shipped drug library allows for ``drug`` (none for a
    drug it does not list)."""
    from pressor.runtime.inputs.drug_library import load_library

    entry = load_library().get(drug)
    return () if entry is None else tuple(entry.concentrations_ug_ml)


def check_drug(
    controller: Any,
    controller_spec: str,
    patient_model: str,
    *,
    controller_field: str = "--controller",
    model_field: str = "--patient-model",
) -> DrugBinding:
    """The drug and syringe a run of ``controller`` on ``patient_model``'s patients uses: a design
    meets only its drug (:func:`pressor.contracts.drug.binding_of`); a drug-agnostic controller
    (:func:`pressor.contracts.drug.drug_agnostic`: the PI and Smith baselines) takes the model's.

    Parameters
    ----------
    controller
        The loaded controller.
    controller_spec, patient_model
        What the caller named them (for the message).
    controller_field, model_field
        The caller's names of the two (``--controller`` on the command line, ``controller`` in
        :mod:`pressor.api`).

    Raises
    ------
    PatientModelError
        One line naming both drugs, when the design's drug is not the model's.
    """
    from pressor.contracts.drug import DEFAULT_BINDING, binding_of, drug_agnostic

    theirs = model_drug(patient_model)
    if drug_agnostic(controller):
        return DEFAULT_BINDING if theirs is None else theirs
    ours = binding_of(controller)
    if theirs is not None and theirs.name != ours.name:
        raise PatientModelError(
            f"{controller_field} {controller_spec}: a {ours.name} design ({ours.describe()})"
            f" meets only {ours.name} patients, and {model_field} {patient_model} is a"
            f" {theirs.name} patient ({theirs.describe()}); choose a {theirs.name} design"
            " ('pressor designs' lists them) or a drug-agnostic baseline (pi, smith)"
        )
    return ours


def check_syringe(
    controller: Any,
    controller_spec: str,
    patient_model: str,
    drug: str | None = None,
    concentration_ug_ml: float | None = None,
    *,
    fields: tuple[str, str, str, str] = (
        "--controller",
        "--patient-model",
        "--drug",
        "--concentration-ug-ml",
    ),
) -> DrugBinding:
    """:func:`check_drug`, then the clinician's ``drug`` and ``concentration_ug_ml`` (µg/ml; each
    ``None`` when not given) checked against it: a design's ml/h count its own syringe, so another
    drug or syringe is refused naming both, as ``pressor run`` refuses one that is not the
    design's. A drug-agnostic baseline takes the patient model's drug at the model's syringe or at
    another of the drug library's syringes of that drug (then run the patients through
    :func:`patients_on_syringe`).

    Parameters
    ----------
    fields
        The caller's names of the controller, the patient model, the drug and the concentration
        (the command line's options by default; :mod:`pressor.api` passes its arguments' names).

    Returns
    -------
    DrugBinding
        The run's drug and syringe (what the records count doses with).

    Raises
    ------
    PatientModelError
        One line naming the value given and the run's drug or syringe (for a baseline, also the
        library's syringes of the drug).
    """
    from pressor.contracts.drug import drug_agnostic

    c_field, m_field, d_field, k_field = fields
    binding = check_drug(
        controller, controller_spec, patient_model, controller_field=c_field, model_field=m_field
    )
    agnostic = drug_agnostic(controller)
    whose = (
        f"{m_field} {patient_model}'s patients count ml/h of"
        if agnostic
        else f"the loaded design ({c_field} {controller_spec}) is for"
    )
    if drug is not None and drug != binding.name:
        raise PatientModelError(f"{d_field} {drug}: {whose} {binding.describe()}")
    c = concentration_ug_ml
    if c is None or math.isclose(c, binding.concentration_ug_ml, rel_tol=1e-6):
        return binding
    if agnostic:
        allowed = library_concentrations(binding.name)
        chosen = next((a for a in allowed if math.isclose(a, c, rel_tol=1e-6)), None)
        if chosen is not None:
            return DrugBinding(binding.name, chosen)
        listed = ", ".join(f"{a:g}" for a in allowed) + " ug/ml" if allowed else "none"
        raise PatientModelError(
            f"{k_field} {c:g}: {whose} {binding.describe()}, and a baseline runs on another"
            f" syringe of the drug library only ({binding.name}: {listed})"
        )
    raise PatientModelError(f"{k_field} {c:g}: {whose} {binding.describe()}")


def patients_on_syringe(
    patient_model: str, run: DrugBinding, field: str = "--concentration-ug-ml"
) -> str:
    """The patient-model spec of ``patient_model``'s patients fed from ``run``'s syringe.

    Every ml/h of a ``c`` µg/ml syringe delivers what ``c / c_model`` ml/h of the model's
    ``c_model`` µg/ml syringe deliver, so the patients are the model's at ``c / c_model`` times its
    sensitivity (times a sensitivity ``patient_model`` already has: ``MODEL@sensitivity=F``).
    ``patient_model`` unchanged when ``run`` is the model's syringe, or another drug's, or the
    model names no drug.

    Raises
    ------
    PatientModelError
        The combined factor outside the sensitivity range, naming ``field``, the syringe and the
        factor.
    """
    theirs = model_drug(patient_model)
    if theirs is None or theirs.name != run.name:
        return patient_model
    c, c_model = run.concentration_ug_ml, theirs.concentration_ug_ml
    if math.isclose(c, c_model, rel_tol=1e-6):
        return patient_model
    base, given = split_spec(patient_model)
    factor = (1.0 if given is None else given) * c / c_model
    lo, hi = SENSITIVITY_RANGE
    if not lo <= factor <= hi:
        raise PatientModelError(
            f"{field} {c:g}: the patients ({patient_model}) would respond to each ml/h as the"
            f" model's to {factor:g} ml/h of its {c_model:g} ug/ml syringe; allowed {lo:g} to"
            f" {hi:g} times (lower the sensitivity or choose another syringe)"
        )
    return with_sensitivity(base, factor)
