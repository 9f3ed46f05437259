"""The supervisor's faults in words: what each means, what the loop did, and when it is expected.

A summary's ``supervisor.detections`` counts each fault kind (:class:`Fault` names) the times it was
raised; :func:`describe_detections` turns that into lines a clinician reads (``SCHED_RATE raised
once: the patient's K, T or tau changed faster than the design's certified rates; advisory: ...``).
The meanings follow the supervisor's module docstring (:mod:`pressor.runtime.core.supervisor_config`)
and docs/PROTOCOL.md ("Alarms"); ``pressor faults`` prints the detection rules and bounds.
"""

from __future__ import annotations

from pressor.runtime.core.supervisor_config import ADVISORY, SCHED_ENVELOPE, Fault

#: fault name -> what it means, in words
MEANINGS: dict[str, str] = {
    "MAP_NAN": "the monitor sent no number for MAP",
    "MAP_RANGE": "MAP outside any plausible value (a disconnected or flushed line)",
    "MAP_SPIKE": "MAP jumped between two samples by more than a real patient's MAP can",
    "MAP_FLATLINE": "the MAP line froze or was damped (its samples stopped moving like the"
    " announced noise)",
    "SENSOR_QUALITY": "the monitor flagged its own MAP sample as poor",
    "STALE_SAMPLE": "the MAP sample was too old to act on",
    "LINK_LOSS": "nothing arrived from the device for the link-loss time",
    "SCHED_INVALID": "the patient's K, T, tau (the schedule) were missing or marked invalid",
    "SCHED_OUT_OF_BOX": "the patient's K, T or tau were outside the design's certified box",
    "SCHED_RATE": "the patient's K, T or tau changed faster than the design's certified rates",
    "COMMAND_INVALID": "the controller returned a rate that is not a finite number",
    "COMMAND_CLAMPED": "the controller asked for a rate outside [0, pump maximum]",
    "TARGET_INVALID": "the MAP target was not a plausible value",
    "LINK_ERRORS": "the link discarded damaged, unsigned or incomplete frames",
    "PUMP_ALARM": "the pump reported an occlusion, an empty syringe or its own watchdog",
    "PUMP_MISMATCH": "the pump delivered another rate than the one commanded",
    "ESTIMATOR_FALLBACK": "the online estimate of K, T, tau failed its health check",
    "ESTIMATE_OUT_OF_BOX": "the online estimate stayed outside the design's box for a minute",
    "DOSE_HARD_LIMIT": "the command was cut to the drug library's hard dose maximum",
    "DOSE_SOFT_LIMIT": "the command reached the drug library's soft dose maximum",
    "DOSE_HOUR_LIMIT": "the command was cut to what the drug library allows in an hour",
    "DOSE_SHORTFALL": (
        "a dose limit or the pump's maximum kept MAP more than 5 mmHg below the target for 10 min"
    ),
    "CONTROLLER_FAULT": "the controller raised an error or returned something that is not a number",
    "SAMPLE_TIME": "a MAP sample's time was inconsistent with its tick",
    "RECORD_ERROR": "a record file (.tlog, .rrd) could not be written further",
    "DEVICE_CHANGED": "the device announced another drug, syringe or pump in the middle of the run",
}

#: what the loop does on an advisory fault, and on one that holds the loop
_ADVISORY_DOES = "advisory: flagged and logged, control went on unchanged"
_ADVISORY_SCHED = (
    "advisory: the controller clamps and rate-limits its schedule itself, control went on"
)
_HOLDS = "held the last rate (HOLD, then FAILSAFE if it lasted 10 s) until the inputs were good"

#: fault name -> when the docs call it expected (a note for the reader, not an excuse)
EXPECTED: dict[str, str] = {
    "SCHED_RATE": "expected once at the start of an infusion on the paper's patient model, whose"
    " delay jumps when the pump first starts (docs/DESIGN-CHOICES.md)",
}


def is_advisory(name: str, sched_advise: bool = True) -> bool:
    """Whether fault ``name`` leaves the loop's state and command unchanged (the default
    ``--sched-faults advise`` makes the scheduling envelope's faults advisory too)."""
    bit = Fault[name]
    return bool(bit & ADVISORY) or (sched_advise and bool(bit & SCHED_ENVELOPE))


def _times(n: int) -> str:
    return {1: "once", 2: "twice"}.get(n, f"{n} times")


def describe_fault(name: str, count: int, sched_advise: bool = True) -> str:
    """One line for a fault raised ``count`` times: its name, the count, what it means, what the
    loop did and, where the docs call it expected, that it is."""
    if name not in Fault.__members__:
        return f"{name} raised {_times(count)}"
    if is_advisory(name, sched_advise):
        does = _ADVISORY_SCHED if Fault[name] & SCHED_ENVELOPE else _ADVISORY_DOES
    else:
        does = _HOLDS
    line = f"{name} raised {_times(count)}: {MEANINGS.get(name, name)}; {does}"
    if name in EXPECTED:
        line += f"; {EXPECTED[name]}"
    return line


def describe_detections(detections: dict[str, int], sched_advise: bool = True) -> list[str]:
    """A line per fault raised (:func:`describe_fault`), in the supervisor's order; ``[]`` for
    none."""
    order = list(Fault.__members__)
    names = sorted(detections, key=lambda n: order.index(n) if n in order else len(order))
    return [describe_fault(n, detections[n], sched_advise) for n in names if detections[n]]
