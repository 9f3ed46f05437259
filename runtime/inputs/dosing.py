"""``pressor run``'s syringe and patient: the design's drug binding, the drug library, the weight.

:func:`bind_syringe` checks, before any device is opened:

1. ``--drug`` and ``--concentration-ug-ml``, when given, against the loaded design's binding
   (:func:`pressor.contracts.drug.binding_of`): the shipped design's gains count ml/h of its syringe, so
   another drug or concentration is refused naming both (no rescaling: docs/DRUGS.md);
2. the drug and concentration against the drug library (``--drug-library``, default the shipped
   ``runtime/inputs/drug_library.toml``): a drug it does not list, or a concentration it does not
   allow for the drug, is refused;
3. ``--weight-kg`` (kg, in [30, 250]): required when the drug's limits are per kg.

It returns the clinician input with the design's drug and concentration and the
:class:`pressor.runtime.inputs.drug_library.DoseLimits` the supervisor enforces. :func:`dose_summary` is the
summary's ``dose`` record: the commanded doses in µg/min and, with a weight, µg/kg/min.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path
from typing import Any

from pressor.contracts.checks import allowed_range
from pressor.contracts.drug import DrugBinding, dose_ug_kg_min, dose_ug_min
from pressor.plumbing.usage import UsageError
from pressor.runtime.inputs.clinician import ClinicianInput, argtype, number_in
from pressor.runtime.inputs.drug_library import (
    WEIGHT_MAX_KG,
    WEIGHT_MIN_KG,
    DrugLibraryError,
    default_library_path,
    load_library,
)


def parse_weight(text: str) -> float:
    """A patient weight (kg) from ``text``; ``ValueError`` naming the allowed range otherwise."""
    return number_in(text, WEIGHT_MIN_KG, WEIGHT_MAX_KG, "kg")


#: what ``--weight-kg`` means for ``pressor run``
RUN_WEIGHT_HELP = (
    "the patient's weight (kg, {rng}): required when the drug library doses the drug per kg"
    " (norepinephrine), optional otherwise (phenylephrine, dosed in ug/min; with it the summary"
    " also gives ug/kg/min)"
)


def add_weight_option(p: argparse.ArgumentParser, help_text: str = RUN_WEIGHT_HELP) -> None:
    """Add ``--weight-kg KG`` (in [30, 250] kg, default ``None``) to ``p``; ``{rng}`` in
    ``help_text`` reads the allowed range."""
    p.add_argument(
        "--weight-kg",
        type=argtype("--weight-kg", parse_weight),
        default=None,
        metavar="KG",
        help=help_text.format(rng=f"allowed [{WEIGHT_MIN_KG:g}, {WEIGHT_MAX_KG:g}]"),
    )


def add_dosing_options(p: argparse.ArgumentParser) -> None:
    """Add ``--weight-kg``, ``--confirm-above-soft-limit`` and ``--drug-library`` to ``p``
    (``pressor run``)."""
    add_weight_option(p)
    p.add_argument(
        "--confirm-above-soft-limit",
        action="store_true",
        help="the clinician confirms doses above the drug library's soft maximum: it then only"
        " raises the advisory DOSE_SOFT_LIMIT (default: off, the command is cut to the soft"
        " maximum; the hard maximum always cuts)",
    )
    p.add_argument(
        "--drug-library",
        type=Path,
        default=None,
        metavar="FILE",
        help="drug library (TOML, docs/DRUGS.md): per drug the concentrations allowed and the hard,"
        " soft and hourly dose maxima the supervisor enforces (default: the shipped one,"
        " published dosing ranges)",
    )


def bind_syringe(
    clinician: ClinicianInput,
    design: DrugBinding,
    controller: str,
    library: Path | None,
    confirm_above_soft: bool = False,
) -> ClinicianInput:
    """Check the syringe and the patient against the design and the library (module docstring).

    Parameters
    ----------
    clinician
        The parsed clinician options.
    design
        The loaded design's drug binding.
    controller
        The ``--controller`` spec (for the messages).
    library
        ``--drug-library`` (``None``: the shipped library).
    confirm_above_soft
        ``--confirm-above-soft-limit``: commands above the soft maximum are only flagged, not
        cut (:class:`pressor.runtime.core.dose_guard.DoseLimits`).

    Returns
    -------
    ClinicianInput
        ``clinician`` with the design's drug and concentration, the weight and the dose limits.

    Raises
    ------
    pressor.plumbing.usage.UsageError
        One line naming both values (the option's and the design's or the library's).
    """
    where = f"the loaded design (--controller {controller}) is for {design.describe()}"
    if clinician.drug_given and clinician.drug != design.name:
        raise UsageError(f"--drug {clinician.drug}: {where}")
    conc = clinician.concentration_ug_ml
    if clinician.concentration_given and not math.isclose(
        conc, design.concentration_ug_ml, rel_tol=1e-6
    ):
        raise UsageError(
            f"--concentration-ug-ml {conc:g}: {where}; its gains count ml/h of that syringe"
        )
    path = default_library_path() if library is None else library
    try:
        entries = load_library(path)
    except DrugLibraryError as exc:
        raise UsageError(f"--drug-library {exc}") from None
    entry = entries.get(design.name)
    if entry is None:
        raise UsageError(
            f"--drug-library {path}: no entry for {design.name} (the loaded design's drug);"
            f" it lists {', '.join(sorted(entries))}"
        )
    c = design.concentration_ug_ml
    if not any(math.isclose(c, a, rel_tol=1e-6) for a in entry.concentrations_ug_ml):
        allowed = ", ".join(f"{a:g}" for a in entry.concentrations_ug_ml)
        raise UsageError(
            f"--drug-library {path}: {design.name} at {c:g} ug/ml (the loaded design's) is not"
            f" allowed; allowed {allowed} ug/ml"
        )
    weight = clinician.weight_kg
    if entry.per_kg and weight is None:
        raise UsageError(
            f"--weight-kg: required: the drug library doses {design.name} in ug/kg/min (a weight"
            f" {allowed_range(WEIGHT_MIN_KG, WEIGHT_MAX_KG, unit='kg')})"
        )
    limits = dataclasses.replace(entry.limits(c, weight), confirm_above_soft=confirm_above_soft)
    return dataclasses.replace(
        clinician,
        drug=design.name,
        concentration_ug_ml=c,
        dose_limits=limits,
        dose_unit=entry.unit,
    )


def dose_summary(
    commands_ml_h: Any,
    period_s: float,
    clinician: ClinicianInput,
    detections: dict[str, int],
    times_s: Any = None,
) -> dict[str, Any]:
    """The summary's ``dose`` record of a ``pressor run``.

    Parameters
    ----------
    commands_ml_h
        The commands sent, one per tick (ml/h).
    period_s
        The loop period (s).
    clinician
        The bound clinician input (:func:`bind_syringe`).
    detections
        The supervisor's detection counts (the ``DOSE_*`` ones are copied).
    times_s
        The run time (s) of each tick: each command is charged until the next tick (the pump runs
        it that long, a stall or a skipped stretch included), the last one period; ``None``: one
        period each.

    Returns
    -------
    dict
        ``unit`` of the library limits, ``weight_kg``, the limits in that unit and in ml/h,
        ``max_command_ug_min``, ``max_command_ug_kg_min`` (``None`` without a weight),
        ``total_ug`` (commanded over the run) and the ``DOSE_*`` detections.
    """
    c, w, lim = clinician.concentration_ug_ml, clinician.weight_kg, clinician.dose_limits
    peak = max((float(u) for u in commands_ml_h if u == u), default=0.0)
    u = [float(x) for x in commands_ml_h]
    if times_s is None:
        spans = [period_s] * len(u)
    else:
        t = [float(x) for x in times_s]
        spans = [max(b - a, 0.0) for a, b in zip(t, t[1:], strict=False)] + [period_s] * bool(t)
    total_ml = math.fsum(x * dt for x, dt in zip(u, spans, strict=True) if x == x) / 3600.0

    def in_unit(rate_ml_h: float) -> float:
        if clinician.dose_unit == "ug/kg/min":
            return dose_ug_kg_min(rate_ml_h, c, w)  # type: ignore[arg-type]
        return dose_ug_min(rate_ml_h, c)

    return {
        "unit": clinician.dose_unit,
        "weight_kg": w,
        "hard_max": in_unit(lim.hard_max_ml_h),
        "soft_max": in_unit(lim.soft_max_ml_h),
        "hard_max_ml_h": lim.hard_max_ml_h,
        "soft_max_ml_h": lim.soft_max_ml_h,
        "max_ml_per_hour": lim.max_ml_per_hour,
        "max_command_ml_h": peak,
        "max_command_ug_min": dose_ug_min(peak, c),
        "max_command_ug_kg_min": None if w is None else dose_ug_kg_min(peak, c, w),
        "total_ug": total_ml * c,
        "detections": {k: v for k, v in detections.items() if k.startswith("DOSE_")},
    }


def log_dose_series(recorder: Any, trajectory: dict[str, Any], clinician: ClinicianInput) -> None:
    """Add the commanded dose and the library's maxima to a ``pressor run`` recording.

    ``/dose/command_ug_min`` always, ``/dose/command_ug_kg_min`` with a weight, and
    ``/dose/hard_max``, ``/dose/soft_max`` in the library's unit for the drug; on the tick and
    sim-time timelines of the loop's series (:data:`pressor.runtime.record.blueprint.DOSE_ENTITIES`).
    """
    import numpy as np

    c, w, lim = clinician.concentration_ug_ml, clinician.weight_kg, clinician.dose_limits
    ticks, times = trajectory["tick"], trajectory["sim_time_s"]
    u = np.asarray(trajectory["command_ml_h"], dtype=float)
    ones = np.ones_like(u)
    unit = clinician.dose_unit
    convert = (lambda r: r * c / (60.0 * w)) if unit == "ug/kg/min" else (lambda r: r * c / 60.0)
    series = [("/dose/command_ug_min", "dose commanded (ug/min)", u * c / 60.0)]
    if w is not None:
        series.append(("/dose/command_ug_kg_min", "dose commanded (ug/kg/min)", u * c / (60.0 * w)))
    series += [
        ("/dose/hard_max", f"hard maximum ({unit})", ones * convert(lim.hard_max_ml_h)),
        ("/dose/soft_max", f"soft maximum ({unit})", ones * convert(lim.soft_max_ml_h)),
    ]
    for entity, label, values in series:
        recorder.log_series(entity, label, ticks, times, values)
