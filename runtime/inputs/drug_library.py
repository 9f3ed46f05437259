"""The drug library: per drug, the syringe concentrations allowed and the dose limits.

The shipped library is ``runtime/inputs/drug_library.toml`` (package data, sources in its comments,
docs/DRUGS.md); ``pressor run --drug-library FILE`` reads another. :func:`load_library` checks every
field and raises :class:`DrugLibraryError` naming the file, the field, the value and the allowed
range. :meth:`DrugEntry.limits` turns one drug's limits, the syringe concentration (µg/ml) and the
patient's weight (kg) into the :class:`DoseLimits` the supervisor enforces
(:mod:`pressor.runtime.core.supervisor`): the dose limits are converted to ml/h once, at the start, rounded
down so that no command at or below them exceeds the dose limit.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from pressor.contracts.drug import MAX_CONCENTRATION_UG_ML, MAX_DRUG_CHARS, dose_ug_min
from pressor.runtime.core.dose_guard import DoseLimits

#: the patient weights ``--weight-kg`` accepts (kg): adults, whom the designs' patient models
#: represent (a child under 30 kg is outside them); above 250 kg per-kg dosing by total weight is
#: no longer usual practice
WEIGHT_MIN_KG = 30.0
WEIGHT_MAX_KG = 250.0
#: the library format this reader understands
FORMAT_VERSION = 1
#: key families: (unit, per_kg, hard, soft, per hour)
FAMILIES = (
    ("ug/min", False, "hard_max_ug_min", "soft_max_ug_min", "max_ug_per_hour"),
    ("ug/kg/min", True, "hard_max_ug_kg_min", "soft_max_ug_kg_min", "max_ug_kg_per_hour"),
)
#: largest dose-rate limit accepted, in either unit (µg/min, µg/kg/min)
MAX_DOSE = 100000.0


class DrugLibraryError(ValueError):
    """A drug library file is missing, malformed, or has a field out of range."""


@dataclass(frozen=True)
class DrugEntry:
    """One drug of the library; limits in ``unit`` (µg/min or µg/kg/min; per hour: µg or µg/kg).

    Attributes
    ----------
    name
        Drug name (lower case).
    concentrations_ug_ml
        Syringe concentrations (µg/ml) allowed.
    unit
        ``ug/min`` or ``ug/kg/min``: the unit of ``hard_max`` and ``soft_max``.
    hard_max, soft_max
        Dose-rate limits (``unit``).
    max_per_hour
        Largest dose over any sliding hour (µg, or µg/kg for a per-kg entry).
    """

    name: str
    concentrations_ug_ml: tuple[float, ...]
    unit: str
    hard_max: float
    soft_max: float
    max_per_hour: float

    @property
    def per_kg(self) -> bool:
        """Whether the limits are per kg (``--weight-kg`` needed)."""
        return self.unit == "ug/kg/min"

    def limits(self, concentration_ug_ml: float, weight_kg: float | None) -> DoseLimits:
        """The limits in ml/h at ``concentration_ug_ml`` (µg/ml) for ``weight_kg`` (kg).

        Raises
        ------
        ValueError
            A per-kg entry without a weight.
        """
        if self.per_kg and weight_kg is None:
            raise ValueError(f"{self.name}: limits in ug/kg/min need the patient's weight")
        scale = weight_kg if self.per_kg else 1.0  # type: ignore[assignment]
        c = concentration_ug_ml
        hard = _rate_below(self.hard_max * scale, c)
        soft = min(_rate_below(self.soft_max * scale, c), hard)
        per_hour_ml = self.max_per_hour * scale / c
        return DoseLimits(hard, soft, per_hour_ml, c, weight_kg)


def _rate_below(dose_ug_per_min: float, c: float) -> float:
    """The largest rate (ml/h) whose dose at ``c`` (µg/ml) does not exceed ``dose_ug_per_min``."""
    rate = dose_ug_per_min * 60.0 / c
    while dose_ug_min(rate, c) > dose_ug_per_min:
        rate = math.nextafter(rate, 0.0)
    return rate


def default_library_path() -> Path:
    """Path of the shipped drug library."""
    return Path(str(resources.files("pressor.runtime.inputs") / "drug_library.toml"))


def _bad(path: Path, fieldname: str, value: Any, allowed: str) -> DrugLibraryError:
    return DrugLibraryError(f"{path}: field '{fieldname}' = {value!r}: allowed {allowed}")


def _number(path: Path, fieldname: str, value: Any, hi: float) -> float:
    """``value`` as a float in (0, ``hi``]."""
    allowed = f"a number in (0, {hi:g}]"
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _bad(path, fieldname, value, allowed)
    v = float(value)
    if not (math.isfinite(v) and 0.0 < v <= hi):
        raise _bad(path, fieldname, value, allowed)
    return v


def _entry(path: Path, name: str, body: Any) -> DrugEntry:
    where = f"drugs.{name}"
    if not (name.isascii() and name == name.lower() and 1 <= len(name) <= MAX_DRUG_CHARS):
        raise _bad(
            path, where, name, f"a lower-case ASCII name of 1 to {MAX_DRUG_CHARS} characters"
        )
    if not isinstance(body, dict):
        raise _bad(path, where, body, "a TOML table")
    concs = body.get("concentrations_ug_ml")
    if not isinstance(concs, list) or not 1 <= len(concs) <= 20:
        raise _bad(path, f"{where}.concentrations_ug_ml", concs, "a list of 1 to 20 numbers")
    cs = tuple(
        _number(path, f"{where}.concentrations_ug_ml", c, MAX_CONCENTRATION_UG_ML) for c in concs
    )
    family = [f for f in FAMILIES if any(k in body for k in f[2:])]
    if len(family) != 1:
        keys = " or ".join(", ".join(f[2:]) for f in FAMILIES)
        raise _bad(path, where, sorted(body), f"concentrations_ug_ml and exactly one of {keys}")
    unit, _, hard_key, soft_key, hour_key = family[0]
    allowed_keys = {"concentrations_ug_ml", hard_key, soft_key, hour_key}
    for key in body:
        if key not in allowed_keys:
            raise _bad(path, f"{where}.{key}", body[key], f"one of {sorted(allowed_keys)}")
    for key in (hard_key, soft_key, hour_key):
        if key not in body:
            raise _bad(path, f"{where}.{key}", None, "given (a positive number)")
    hard = _number(path, f"{where}.{hard_key}", body[hard_key], MAX_DOSE)
    soft = _number(path, f"{where}.{soft_key}", body[soft_key], MAX_DOSE)
    if soft > hard:
        raise _bad(path, f"{where}.{soft_key}", body[soft_key], f"(0, {hard_key} = {hard:g}]")
    hour = _number(path, f"{where}.{hour_key}", body[hour_key], MAX_DOSE * 60.0)
    if hour < soft * 60.0:
        raise _bad(
            path,
            f"{where}.{hour_key}",
            body[hour_key],
            f"[60 x {soft_key} = {soft * 60.0:g}, {MAX_DOSE * 60.0:g}] (the soft maximum for an"
            " hour)",
        )
    return DrugEntry(name, cs, unit, hard, soft, hour)


def load_library(path: str | Path | None = None) -> dict[str, DrugEntry]:
    """Read and check a drug library file (the shipped one when ``path`` is None).

    Returns
    -------
    dict
        Drug name -> :class:`DrugEntry`.

    Raises
    ------
    DrugLibraryError
        The file cannot be read or parsed, or a field is missing, unknown or out of range (the
        message names the file, the field, the value and the allowed range).
    """
    p = default_library_path() if path is None else Path(path)
    try:
        with open(p, "rb") as fh:
            table = tomllib.load(fh)
    except OSError as exc:
        raise DrugLibraryError(f"{p}: cannot read ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise DrugLibraryError(f"{p}: not valid TOML ({exc})") from None
    for key in table:
        if key not in ("format_version", "drugs"):
            raise _bad(p, key, table[key], "only format_version and [drugs.NAME] tables")
    if table.get("format_version") != FORMAT_VERSION:
        raise _bad(p, "format_version", table.get("format_version"), f"{FORMAT_VERSION}")
    drugs = table.get("drugs")
    if not isinstance(drugs, dict) or not drugs:
        raise _bad(p, "drugs", drugs, "at least one [drugs.NAME] table")
    return {name: _entry(p, name, body) for name, body in drugs.items()}
