"""``pressor patients`` and ``pressor designs``: what ships, a line each.

``pressor patients`` lists the simulated patient models of the registry
(:data:`pressor.hil_sim.patients.patient_model.PATIENT_MODELS`) with the drug their ml/h count, what
each is and its source (docs/PATIENTS.md). ``pressor designs`` lists the controllers
``--controller`` takes by name: every shipped LPV design, read from the loader's table
(:data:`pressor.runtime.inputs.controller_loader.LPV_DESIGNS`, so a design added there is listed
here), with its drug, concentration, certified box and rates and the artifact it was generated
from, then the baselines. Both take no options; exit 0, or 2 on an unknown argument.
"""

from __future__ import annotations

from collections.abc import Sequence

from pressor.plumbing.usage import UsageParser, run_command, usage_exit


def patient_lines() -> list[str]:
    """A line per shipped patient model: name (the default marked), drug, what it is, source."""
    from pressor.hil_sim.patients.patient_model import (
        DEFAULT_PATIENT_MODEL,
        PATIENT_MODEL_NOTES,
        PATIENT_MODELS,
    )

    names = {n: n + (" (default)" if n == DEFAULT_PATIENT_MODEL else "") for n in PATIENT_MODELS}
    notes = {n: PATIENT_MODEL_NOTES.get(n, ("-", PATIENT_MODELS[n], "-")) for n in PATIENT_MODELS}
    w_name = max(len(v) for v in names.values())
    w_drug = max(len(v[0]) for v in notes.values())
    return [
        f"{names[n]:<{w_name}}  {notes[n][0]:<{w_drug}}  {notes[n][1]}; source: {notes[n][2]}"
        for n in PATIENT_MODELS
    ]


def _range(lo: float, hi: float) -> str:
    return f"{lo:g}-{hi:g}"


def design_lines() -> list[str]:
    """A line per shipped controller: every LPV design of the loader's table (its drug and
    syringe, certified box, rates, artifact), then the baselines."""
    from pressor.contracts.drug import DEFAULT_BINDING
    from pressor.runtime.inputs.controller_loader import (
        BASELINES,
        DEFAULT_LPV_MODULE,
        LPV_DESIGNS,
        design_header,
        design_specs,
    )

    rows: list[tuple[str, str, str]] = []
    aliases = [f"lpv:{n}" for n, path in LPV_DESIGNS.items() if path == DEFAULT_LPV_MODULE]
    for spec, path in zip(design_specs(), LPV_DESIGNS.values(), strict=True):
        h = design_header(path)
        name = spec + (f" (default; also {', '.join(aliases)})" if spec == "lpv" else "")
        drug = f"{h.get('DRUG', '?')} {h.get('DRUG_CONCENTRATION_UG_ML', float('nan')):g} µg/ml"
        text = "LPV design"
        lo, hi, rates = h.get("GRID_LO"), h.get("GRID_HI"), h.get("RATE_BOUNDS")
        if lo and hi:
            text += (
                f" certified for K {_range(lo[0], hi[0])} mmHg/(ml/h), T {_range(lo[1], hi[1])} s,"
                f" tau {_range(lo[2], hi[2])} s"
            )
        if rates:
            text += (
                f" changing at most {rates[0]:g} mmHg/(ml/h)/s, {rates[1]:g} s/s, {rates[2]:g} s/s"
            )
        command = str(h.get("GENERATION_COMMAND", ""))
        artifact = next((w for w in command.split() if w.endswith(".npz")), None)
        if artifact:
            text += f"; from {artifact}"
        rows.append((name, drug, text))
    default_drug = f"{DEFAULT_BINDING.name} {DEFAULT_BINDING.concentration_ug_ml:g} µg/ml"
    rows += [(spec, default_drug, text) for spec, text in BASELINES.items()]
    w_name = max(len(r[0]) for r in rows)
    w_drug = max(len(r[1]) for r in rows)
    return [f"{a:<{w_name}}  {b:<{w_drug}}  {c}" for a, b, c in rows]


def _patients(argv: Sequence[str]) -> int:
    UsageParser(
        prog="pressor patients",
        description="list the simulated patient models (--patient-model NAME): drug, what each is,"
        " source (docs/PATIENTS.md; any class satisfying the PatientModel protocol plugs in as"
        " MODULE:CLASS)",
    ).parse_args(argv)
    print("\n".join(patient_lines()))
    return 0


def _designs(argv: Sequence[str]) -> int:
    UsageParser(
        prog="pressor designs",
        description="list the controllers --controller takes by name: the shipped LPV designs"
        " (drug, certified box, artifact) and the baselines (your own: a generated .py or a"
        " plugin class, docs/INTERFACES.md)",
    ).parse_args(argv)
    print("\n".join(design_lines()))
    return 0


def main(command: str, argv: list[str]) -> int:
    """Entry point for the dispatcher: ``patients`` or ``designs``."""
    handlers = {"patients": _patients, "designs": _designs}
    if command not in handlers:
        return usage_exit("pressor.listing", f"unknown command {command!r}")
    return run_command(f"pressor {command}", handlers[command], argv)
