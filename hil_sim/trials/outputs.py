"""What a trial writes: each record's infusion in doses, the summary, ``patients.csv``.

The records come from :mod:`pressor.hil_sim.trials.trial`; this module turns them into the files
``pressor trial`` writes into its output folder (``patients.json``, ``patients.csv``,
``summary.json``) and the figures the API and the report read from them (docs/METRICS.md).
``patients.csv`` flattens each record's disturbance events into ``LABEL_start_s``,
``LABEL_peak_deviation_mmhg``, ``LABEL_recovery_s`` and ``LABEL_iae_mmhg_s`` columns, LABEL being
the kind (``hemorrhage``, ``bolus``; ``hemorrhage_2`` for a second one).
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pressor.contracts.drug import REFERENCE_WEIGHT_KG, DrugBinding, dose_ug_kg_min
from pressor.contracts.metrics import EVENT_METRICS, RUN_METRICS, aggregate, event_labels
from pressor.hil_sim.patients.patient_model import DEFAULT_PATIENT_MODEL, load_patient_model
from pressor.hil_sim.scenarios.scenario import Scenario
from pressor.plumbing.files import write_atomic


def infusion_record(
    record: dict[str, Any], drug: DrugBinding, weight_kg: float | None, duration_s: float
) -> dict[str, Any]:
    """The record's ``infusion``: the drug and syringe, the weight the doses are per, and the mean
    and peak infusion in ml/h and µg/kg/min.

    Parameters
    ----------
    record
        A patient's record (its ``drug_total_ml``, ml, and ``max_rate_ml_h``, ml/h).
    drug
        The drug and syringe (µg/ml) the run's ml/h count.
    weight_kg
        The patient's weight (kg); ``None``: the 70 kg reference adult the patient models count
        (:data:`pressor.contracts.drug.REFERENCE_WEIGHT_KG`), said so by ``weight_given`` false.
    duration_s
        The run's length (s): the mean rate is the drug given over it.
    """
    w = REFERENCE_WEIGHT_KG if weight_kg is None else float(weight_kg)
    c = float(drug.concentration_ug_ml)
    total, peak = record.get("drug_total_ml"), record.get("max_rate_ml_h")
    mean = None if total is None else total * 3600.0 / duration_s

    def per_kg(rate: float | None) -> float | None:
        return None if rate is None else dose_ug_kg_min(rate, c, w)

    return {
        "drug": drug.name,
        "concentration_ug_ml": c,
        "weight_kg": w,
        "weight_given": weight_kg is not None,
        "mean_rate_ml_h": mean,
        "peak_rate_ml_h": peak,
        "mean_dose_ug_kg_min": per_kg(mean),
        "peak_dose_ug_kg_min": per_kg(peak),
    }


def infusion_summary(records: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
    """The summary's ``infusion``: drug, syringe and weight of the records' ``infusion`` and the
    median over patients of the mean and peak rate (ml/h) and dose (µg/kg/min); ``None`` when the
    records carry none."""
    if not records or "infusion" not in records[0]:
        return None
    first = records[0]["infusion"]
    doc = {k: first[k] for k in ("drug", "concentration_ug_ml", "weight_kg", "weight_given")}
    for key in ("mean_rate_ml_h", "peak_rate_ml_h", "mean_dose_ug_kg_min", "peak_dose_ug_kg_min"):
        values = [r["infusion"][key] for r in records if r["infusion"][key] is not None]
        doc[f"median_{key}"] = float(np.median(values)) if values else None
    return doc


def summarize(
    records: Sequence[dict[str, Any]],
    scenario: Scenario,
    controller_spec: str,
    cohort_seed: int,
    schedule: str = "oracle",
    patient_model: str = DEFAULT_PATIENT_MODEL,
) -> dict[str, Any]:
    """The ``summary.json`` document: trial identity and the aggregated metrics; with a schedule
    other than the oracle also ``schedule`` and ``estimation`` (median over patients of each
    record's ``estimation`` figure); with a patient model other than ``paper`` also
    ``patient_model``. ``coefficient_units`` gives the unit of every coefficient of the records."""
    units = load_patient_model(patient_model).coefficient_units
    doc: dict[str, Any] = {"scenario": scenario.name, "controller": controller_spec}
    if patient_model != DEFAULT_PATIENT_MODEL:  # the default's summaries keep their bytes
        doc["patient_model"] = patient_model
    if scenario.target_mmhg is not None:  # a relative step's summaries keep their bytes
        doc["target_mmhg"] = float(scenario.target_mmhg)
    doc |= {
        "cohort_seed": int(cohort_seed),
        "n_patients": len(records),
        "unreachable_patient_seeds": [r["patient_seed"] for r in records if not r["reachable"]],
        "unstable_patient_seeds": [r["patient_seed"] for r in records if not r["stable"]],
        "coefficient_units": {k: units[k] for k in (records[0]["coefficients"] if records else {})},
        "metrics": aggregate(records),
    }
    infusion = infusion_summary(records)
    if infusion is not None:
        doc["infusion"] = infusion
    if schedule != "oracle":  # oracle summaries keep their bytes
        doc["schedule"] = schedule
        doc["estimation"] = {
            key: float(np.median([r["estimation"][key] for r in records]))
            for key in ("K_rel_err_pct", "T_rel_err_pct", "tau_abs_err_s")
        }
    return doc


_EVENT_COLUMNS = ("start_s",) + EVENT_METRICS
#: the record's ``infusion`` figures that ``patients.csv`` has a column for (units in the names)
_DOSE_COLUMNS = ("mean_rate_ml_h", "mean_dose_ug_kg_min", "peak_dose_ug_kg_min")


def patients_csv(records: Sequence[dict[str, Any]], units: dict[str, str]) -> str:
    """``patients.csv``'s text: a row per record, coefficient columns headed with their ``units``
    (name -> unit), schedule ranges, run metrics, doses and the disturbance events' figures."""
    coeff_keys = list(records[0]["coefficients"]) if records else []
    scalar_keys = (
        ["required_delta_mmhg", "max_delta_mmhg"]
        + list(RUN_METRICS)
        + ["reachable", "stable", "commands_out_of_range"]
    )
    dose_keys = list(_DOSE_COLUMNS) if records and "infusion" in records[0] else []
    # Every patient of a trial runs the same scenario, so the first one's events name the columns.
    labels = event_labels([d["kind"] for d in records[0]["disturbances"]]) if records else []
    ranges = list(records[0]["schedule_range"]) if records else []
    header = (
        ["patient_seed"]
        + [f"{k} ({units[k]})" for k in coeff_keys]
        + [f"{name}_{end}" for name in ranges for end in ("min", "max")]
        + scalar_keys
        + dose_keys
        + [f"{label}_{col}" for label in labels for col in _EVENT_COLUMNS]
    )
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for r in records:
        row = [r["patient_seed"]] + [r["coefficients"][k] for k in coeff_keys]
        row += [v for name in ranges for v in r["schedule_range"][name]]
        row += [r[k] for k in scalar_keys]
        row += [r["infusion"][k] for k in dose_keys]
        row += [d[col] for d in r["disturbances"] for col in _EVENT_COLUMNS]
        writer.writerow(["" if v is None else repr(v) if isinstance(v, float) else v for v in row])
    return buf.getvalue()


def write_outputs(
    out_dir: Path, records: Sequence[dict[str, Any]], summary: dict[str, Any]
) -> None:
    """Write ``patients.json``, ``patients.csv`` and ``summary.json`` atomically into ``out_dir``
    (the CSV's coefficient units from the summary's ``coefficient_units``)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    write_atomic(out_dir / "patients.json", json.dumps(list(records), indent=1) + "\n")
    write_atomic(out_dir / "patients.csv", patients_csv(records, summary["coefficient_units"]))
    write_atomic(out_dir / "summary.json", json.dumps(summary, indent=1) + "\n")
