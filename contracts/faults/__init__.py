"""The fault catalogue both ends agree on: kinds, arguments, detection bounds, safe states, reports.

``--fault KIND[:ARGS]`` (``pressor sil``, ``pressor device``) and ``[[faults]]`` tables in a
scenario TOML name a fault from :data:`CATALOGUE`. ARGS are ``key=value`` pairs separated by commas
(``link-stall:start_s=60,duration_s=3``); bare numbers fill ``start_s`` then ``duration_s``
(``sensor-nan:300,5``). Every argument has a documented default, so ``--fault KIND`` alone works.
Times are in simulated seconds and are rounded to whole ticks of the loop (fault timing lives in
virtual time, so a lockstep run with faults is as deterministic as one without).

This package is pure (no I/O besides reading a scenario TOML on request) and imports nothing from
``hil_sim``: the device side (``pressor.hil_sim.scenarios.faults``) imports it to *inject* the faults, the runtime
uses it only to *label and score* them in its summary, from the schedule it was given on its own
command line and from the supervisor's detection log. The runtime's control path never sees a
fault except through its inputs.

The modules: :mod:`~pressor.contracts.faults.wire_bits` (pump alarm and monitor quality bits, defined
once for both ends), :mod:`~pressor.contracts.faults.catalogue` (the kinds, their arguments and detection
bounds), :mod:`~pressor.contracts.faults.spec` (parsing ``--fault`` and ``[[faults]]``),
:mod:`~pressor.contracts.faults.scoring` (scoring detections from the supervisor's log).
"""

from typing import TYPE_CHECKING, Any

from pressor.contracts.faults.catalogue import (
    CATALOGUE,
    DEFAULT_START_S,
    FAULT_KINDS,
    FaultKind,
    Param,
    catalogue_rows,
)
from pressor.contracts.faults.spec import (
    FaultSpec,
    FaultSpecError,
    make_spec,
    parse_fault,
    parse_fault_table,
    parse_faults,
)
from pressor.contracts.faults.wire_bits import (
    PUMP_ALARM_INVALID_COMMAND,
    PUMP_ALARM_OCCLUSION,
    PUMP_ALARM_OUT_OF_RANGE,
    PUMP_ALARM_RESERVOIR_EMPTY,
    PUMP_ALARM_WATCHDOG,
    QUALITY_HELD,
    QUALITY_INVALID,
    QUALITY_WAVEFORM,
)

if TYPE_CHECKING:
    from pressor.contracts.faults.scoring import FaultScorer, fault_report

#: names served by :mod:`~pressor.contracts.faults.scoring`, which imports numpy: loaded on first use,
#: so that parsing ``--fault`` (every command's argument check) stays free of numpy
_SCORING = frozenset({"FaultScorer", "fault_report"})


def __getattr__(name: str) -> Any:
    if name in _SCORING:
        from pressor.contracts.faults import scoring

        return getattr(scoring, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "CATALOGUE",
    "DEFAULT_START_S",
    "FAULT_KINDS",
    "PUMP_ALARM_INVALID_COMMAND",
    "PUMP_ALARM_OCCLUSION",
    "PUMP_ALARM_OUT_OF_RANGE",
    "PUMP_ALARM_RESERVOIR_EMPTY",
    "PUMP_ALARM_WATCHDOG",
    "QUALITY_HELD",
    "QUALITY_INVALID",
    "QUALITY_WAVEFORM",
    "catalogue_rows",
    "fault_report",
    "FaultKind",
    "FaultScorer",
    "FaultSpec",
    "FaultSpecError",
    "make_spec",
    "Param",
    "parse_fault",
    "parse_fault_table",
    "parse_faults",
]
