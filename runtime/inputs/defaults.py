"""The defaults ``pressor run``, ``pressor sil``, ``pressor trial`` and :mod:`pressor.api` share.

One set, chosen on the sensitivity sweep (docs/notes/cautious-start.md): each drug's design on a
log-K scale, scheduled by the cautious start (its first doses are safe for the most sensitive
patient of the drug's 0.1x-10x population, and the MAP's evidence buys speed at the certified
rates). Any other LPV design schedules on the online estimate by default (a real device sends no
K, T, tau); the oracle stays for research, by name. A run on any schedule but the cautious start
(or the oracle) says so as it starts (:func:`caution_warning`).
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "DEFAULT_CONTROLLER",
    "DEFAULT_SCENARIO",
    "DESIGN_FOR_DRUG",
    "caution_warning",
    "default_controller",
    "default_schedule",
]

#: the controller each drug's runs default to: its design on a log-K scale (docs/DRUGS.md)
DESIGN_FOR_DRUG = {
    "phenylephrine": "lpv:cautious",
    "norepinephrine": "lpv:norepinephrine-cautious",
}
#: the default controller when no drug is named: phenylephrine's, the default drug's
DEFAULT_CONTROLLER = DESIGN_FOR_DRUG["phenylephrine"]
#: the scenario ``pressor sil`` and ``pressor trial`` run by default: a +20 mmHg step, a
#: haemorrhage and a fluid bolus in one hour (hil_sim/scenarios)
DEFAULT_SCENARIO = "paper-disturbance"


def default_controller(drug: str | None = None) -> str:
    """The ``--controller`` of a run that names none: ``drug``'s design (:data:`DESIGN_FOR_DRUG`),
    or :data:`DEFAULT_CONTROLLER` for no drug or a drug without a shipped design (the drug check
    then refuses the mismatch, naming both)."""
    return DESIGN_FOR_DRUG.get(drug or "", DEFAULT_CONTROLLER)


def default_schedule(controller: Any) -> str:
    """The ``--schedule`` of a run that names none: ``cautious`` for a design with a patient
    population on a log-K scale (:func:`pressor.contracts.drug.dose_scaled`), ``estimated`` for
    any other (the PI ignores its schedule)."""
    from pressor.contracts.drug import dose_scaled

    return "cautious" if dose_scaled(controller) else "estimated"


def caution_warning(spec: str, schedule: str) -> str | None:
    """The line a run prints when nothing sizes its first doses for the most sensitive patient.

    Only the cautious start (``--schedule cautious``, a design on a log-K scale) sizes the first
    doses for the most sensitive patient of the drug's 0.1x-10x population; the oracle knows the
    simulated patient (research only). Any other schedule, and the PI and the Smith predictor
    (which schedule on nothing), dose for a typical patient from the first second, and a
    drug-sensitive one overshoots: on the paper model at 10x the PI's step overshoot p90 is 673 %
    of the step (docs/notes/cautious-start.md, "Measured").

    Parameters
    ----------
    spec
        The ``--controller`` as given.
    schedule
        The run's ``--schedule`` (given, or :func:`default_schedule`'s).

    Returns
    -------
    str or None
        The warning, naming the controller, the schedule and what starts safe; None for
        ``cautious`` and ``oracle``.
    """
    if schedule in ("cautious", "oracle"):
        return None
    return (
        f"--controller {spec} on --schedule {schedule} does not start cautiously: nothing sizes"
        " its first doses for the most sensitive patient, and doses sized for a typical one"
        " overshoot a drug-sensitive patient (several times the step at 10x sensitivity,"
        " docs/notes/cautious-start.md); each drug's default design"
        f" ({', '.join(DESIGN_FOR_DRUG.values())}) on --schedule cautious starts safe for the"
        " most sensitive patient"
    )
