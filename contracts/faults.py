"""The fault catalogue both ends agree on: kinds, arguments, detection bounds, safe states, reports.

``--fault KIND[:ARGS]`` (``pressor sil``, ``pressor device``) and ``[[faults]]`` tables in a
scenario TOML name a fault from :data:`CATALOGUE`. ARGS are ``key=value`` pairs separated by commas
(``link-stall:start_s=60,duration_s=3``); bare numbers fill ``start_s`` then ``duration_s``
(``sensor-nan:300,5``). Every argument has a documented default, so ``--fault KIND`` alone works.
Times are in simulated seconds and are rounded to whole ticks of the loop (fault timing lives in
virtual time, so a lockstep run with faults is as deterministic as one without).

This module is pure (no I/O besides reading a scenario TOML on request) and imports nothing from
``hil_sim``: the device side (``hil_sim.faults``) imports it to *inject* the faults, the runtime
uses it only to *label and score* them in its summary, from the schedule it was given on its own
command line and from the supervisor's detection log. The runtime's control path never sees a
fault except through its inputs.

Detection bounds (defaults, 10 Hz; the *watchdog period* is the supervisor's link-loss time,
1 s = 10 ticks): every link and sensor fault is detected within one watchdog period of its start
(bound in :class:`FaultKind`); pump faults within the bounds given per kind; scheduling faults
only when the controller is scheduled (the PI baseline ignores K, T, τ, so for it they are
"not applicable"). Latency is counted in ticks from the fault's first tick.

Pump alarm bits (``PUMP_STATUS.alarms``) are defined here, once, for both ends.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: pump alarm bit flags carried by PUMP_STATUS (hil_sim.pump uses these values)
PUMP_ALARM_OCCLUSION = 1
PUMP_ALARM_RESERVOIR_EMPTY = 2
PUMP_ALARM_WATCHDOG = 4
PUMP_ALARM_INVALID_COMMAND = 8
PUMP_ALARM_OUT_OF_RANGE = 16

#: monitor quality bits carried by MAP_SAMPLE.quality (hil_sim.sensor uses these values)
QUALITY_INVALID = 1
QUALITY_WAVEFORM = 2  # the monitor's waveform check: no pulsatility / over-damped line

#: default ``start_s`` of a fault (s of sim time)
DEFAULT_START_S = 300.0


class FaultSpecError(ValueError):
    """A bad fault specification; the message names source, field, value and allowed range."""


@dataclass(frozen=True)
class Param:
    """One fault argument: name (with unit suffix), default, allowed closed range, meaning."""

    name: str
    default: float
    lo: float
    hi: float
    doc: str
    integer: bool = False


@dataclass(frozen=True)
class FaultKind:
    """A fault kind of the catalogue.

    Attributes
    ----------
    name
        ``link-flip`` ... (the ``--fault`` name).
    group
        ``link``, ``sensor``, ``pump`` or ``sched``.
    doc
        What the device does.
    params
        Arguments besides the common ``start_s``, ``duration_s``, ``seed``.
    default_duration_s
        Default ``duration_s``.
    detected_as
        Supervisor fault names (``runtime.supervisor.Fault``) that count as detecting it.
    bound_ticks
        Documented detection bound (ticks after the first fault tick at 10 Hz; scaled with the rate
        via :meth:`bound_at`); ``None`` when no bound from the start can be given.
    safe_state
        The documented reaction.
    scheduled_only
        Only detectable (and only relevant) for a scheduled controller.
    """

    name: str
    group: str
    doc: str
    params: tuple[Param, ...]
    default_duration_s: float
    detected_as: tuple[str, ...]
    bound_ticks: int | None
    bound_doc: str
    safe_state: str
    scheduled_only: bool = False
    default_start_s: float = DEFAULT_START_S

    def bound_at(self, sample_period_s: float) -> int | None:
        """The detection bound in ticks at ``sample_period_s`` (bounds are 10 Hz tick counts)."""
        if self.bound_ticks is None:
            return None
        return max(1, int(math.ceil(self.bound_ticks * 0.1 / sample_period_s - 1e-9)))


_COMMON = (
    Param("start_s", DEFAULT_START_S, 0.0, 7 * 86400.0, "first fault time (s of sim time)"),
    Param("duration_s", math.nan, 0.0, 7 * 86400.0, "length (s); 0 = one tick"),
    Param("seed", 0, 0, 2**32 - 1, "seed of the fault's random draws", integer=True),
)

_LINK_SAFE = (
    "AUTO: CRC/sequence checks discard the bad frames, lockstep resends the tick; advisory alarm"
    " LINK_ERRORS logged"
)
_HOLD = "HOLD (last command held, controller frozen, alarm); FAILSAFE after hold_max_s"
_LOSS = "HOLD at STALE_SAMPLE, FAILSAFE at LINK_LOSS (ramp to safe rate); pump watchdog after 5 s"

CATALOGUE: dict[str, FaultKind] = {
    k.name: k
    for k in (
        FaultKind(
            "link-flip",
            "link",
            "random bit flips in bytes both ways (first device write of the window always hit)",
            (Param("rate", 0.01, 0.0, 1.0, "probability a byte is hit"),),
            10.0,
            ("LINK_ERRORS",),
            1,
            "the tick of the first hit frame (<= 1 tick)",
            _LINK_SAFE,
        ),
        FaultKind(
            "link-drop",
            "link",
            "whole frames dropped both ways (first device frame of the window always dropped)",
            (Param("rate", 0.1, 0.0, 1.0, "probability a frame is dropped"),),
            10.0,
            ("LINK_ERRORS",),
            1,
            "the tick of the first dropped frame (<= 1 tick)",
            _LINK_SAFE,
        ),
        FaultKind(
            "link-stall",
            "link",
            "no frames either way for duration_s; the device keeps simulating (lockstep: the"
            " runtime sees the silent ticks on the virtual clock)",
            (),
            3.0,
            ("STALE_SAMPLE", "LINK_LOSS"),
            10,
            "STALE_SAMPLE after stale_after_s (4 ticks), LINK_LOSS after 1 s (10 ticks)",
            _LOSS,
        ),
        FaultKind(
            "link-disconnect",
            "link",
            "cable pulled: the burst in flight is cut mid-frame, nothing passes for duration_s,"
            " then the device reconnects (new hello, sequence restarts)",
            (),
            8.0,
            ("STALE_SAMPLE", "LINK_LOSS"),
            10,
            "STALE_SAMPLE after stale_after_s (4 ticks), LINK_LOSS after 1 s (10 ticks)",
            _LOSS,
        ),
        FaultKind(
            "link-garbage",
            "link",
            "a flood of random bytes before every device write",
            (Param("bytes", 256, 1, 65536, "garbage bytes per write", integer=True),),
            10.0,
            ("LINK_ERRORS",),
            1,
            "the first tick of the flood (<= 1 tick)",
            _LINK_SAFE,
        ),
        FaultKind(
            "link-duplicate",
            "link",
            "device frames duplicated and bursts reordered (first write of the window always)",
            (
                Param(
                    "rate", 0.2, 0.0, 1.0, "probability a frame is duplicated / a burst reordered"
                ),
            ),
            10.0,
            ("LINK_ERRORS",),
            1,
            "the first duplicated/reordered tick (<= 1 tick)",
            _LINK_SAFE,
        ),
        FaultKind(
            "sensor-nan",
            "sensor",
            "the monitor sends NaN (no quality flag)",
            (),
            5.0,
            ("MAP_NAN",),
            1,
            "same tick",
            _HOLD,
        ),
        FaultKind(
            "sensor-flatline",
            "sensor",
            "reading stuck at the last value before the fault; the monitor's waveform check"
            " flags it after flag_after_s (flag_after_s > duration: never flagged, only the"
            " supervisor's own flatline check of a noisy sensor can see it)",
            (Param("flag_after_s", 0.5, 0.0, 86400.0, "waveform-quality flag delay (s)"),),
            10.0,
            ("SENSOR_QUALITY", "MAP_FLATLINE"),
            10,
            "monitor flag after flag_after_s (default 5 ticks) <= 1 watchdog period",
            _HOLD,
        ),
        FaultKind(
            "sensor-flush",
            "sensor",
            "fast-flush of the line: the reading jumps to the flush-bag pressure",
            (Param("level_mmhg", 300.0, -50.0, 400.0, "reading during the flush (mmHg)"),),
            4.0,
            ("MAP_RANGE", "MAP_SPIKE"),
            1,
            "same tick (outside [20, 250] mmHg)",
            _HOLD,
        ),
        FaultKind(
            "sensor-damped",
            "sensor",
            "over-damped line: the reading lags the truth (first order); the monitor's waveform"
            " check flags the damped waveform after flag_after_s",
            (
                Param("tc_s", 30.0, 0.1, 600.0, "lag time constant (s)"),
                Param("flag_after_s", 0.5, 0.0, 86400.0, "waveform-quality flag delay (s)"),
            ),
            60.0,
            ("SENSOR_QUALITY",),
            10,
            "monitor flag after flag_after_s (default 5 ticks) <= 1 watchdog period",
            _HOLD,
        ),
        FaultKind(
            "sensor-disconnect",
            "sensor",
            "transducer open to air: reading ~ level_mmhg (plus the sensor's noise)",
            (Param("level_mmhg", 0.0, -50.0, 400.0, "reading while disconnected (mmHg)"),),
            20.0,
            ("MAP_RANGE", "MAP_SPIKE"),
            1,
            "same tick (outside [20, 250] mmHg)",
            _HOLD,
        ),
        FaultKind(
            "sensor-range",
            "sensor",
            "values outside any physiological range",
            (Param("value_mmhg", 400.0, -1000.0, 1000.0, "reported MAP (mmHg)"),),
            5.0,
            ("MAP_RANGE",),
            1,
            "same tick",
            _HOLD,
        ),
        FaultKind(
            "pump-occlusion",
            "pump",
            "line occluded: nothing delivered, the pump's pressure alarm trips",
            (),
            20.0,
            ("PUMP_ALARM",),
            2,
            "the next pump status (1 tick)",
            _HOLD,
        ),
        FaultKind(
            "pump-empty",
            "pump",
            "reservoir empty: the pump stops with an alarm; a new syringe after duration_s",
            (),
            20.0,
            ("PUMP_ALARM",),
            2,
            "the next pump status (1 tick)",
            _HOLD,
        ),
        FaultKind(
            "pump-ignore",
            "pump",
            "the pump acknowledges commands but keeps its rate",
            (),
            20.0,
            ("PUMP_MISMATCH",),
            None,
            "pump_mismatch_s (1 s) + 1 tick after the command moves away from the stuck rate"
            " (default start 60 s: the command is still moving)",
            _HOLD,
            default_start_s=60.0,
        ),
        FaultKind(
            "pump-mismatch",
            "pump",
            "delivered rate = factor x commanded (wrong syringe size); the status reports the"
            " measured delivery",
            (Param("factor", 0.5, 0.0, 10.0, "delivered / commanded"),),
            20.0,
            ("PUMP_MISMATCH",),
            12,
            "pump_mismatch_s (1 s) + 1 tick while the command exceeds the tolerance",
            _HOLD,
        ),
        FaultKind(
            "sched-out-of-box",
            "sched",
            "K reported outside the design box",
            (Param("K", 2.0, -10.0, 10.0, "reported K (mmHg/(ml/h))"),),
            20.0,
            ("SCHED_OUT_OF_BOX",),
            1,
            "same tick",
            "advisory by default (controller clamps rho to its box; --sched-faults hold: HOLD)",
            scheduled_only=True,
        ),
        FaultKind(
            "sched-jump",
            "sched",
            "K reported as a square wave +/- amplitude around the truth, alternating every tick",
            (Param("amplitude", 0.05, 0.0, 10.0, "K amplitude (mmHg/(ml/h))"),),
            20.0,
            ("SCHED_RATE",),
            2,
            "the second fault tick (a rate needs two samples)",
            "advisory by default (controller rate-limits rho; --sched-faults hold: HOLD)",
            scheduled_only=True,
        ),
        FaultKind(
            "sched-missing",
            "sched",
            "scheduling parameters missing: NaN and marked invalid",
            (),
            20.0,
            ("SCHED_INVALID",),
            1,
            "same tick",
            _HOLD,
            scheduled_only=True,
        ),
    )
}

FAULT_KINDS: tuple[str, ...] = tuple(CATALOGUE)


@dataclass(frozen=True)
class FaultSpec:
    """One scheduled fault.

    Attributes
    ----------
    kind
        A :data:`CATALOGUE` name.
    start_s, duration_s
        Window (s of sim time).
    seed
        Seed of its random draws.
    args
        Kind-specific arguments by name (all filled with defaults).
    index
        Position in the schedule (distinguishes two faults of one kind).
    """

    kind: str
    start_s: float
    duration_s: float
    seed: int = 0
    args: dict[str, float] = field(default_factory=dict)
    index: int = 0

    @property
    def info(self) -> FaultKind:
        return CATALOGUE[self.kind]

    def ticks(self, sample_period_s: float) -> tuple[int, int]:
        """``(first, end)`` ticks of the window, end exclusive (at least one tick)."""
        first = int(round(self.start_s / sample_period_s))
        n = max(1, int(round(self.duration_s / sample_period_s)))
        return first, first + n

    def to_cli(self) -> str:
        """The ``--fault`` text that parses back to this spec."""
        parts = [f"start_s={self.start_s!r}", f"duration_s={self.duration_s!r}"]
        parts.append(f"seed={self.seed}")
        parts += [f"{k}={v!r}" for k, v in self.args.items()]
        return f"{self.kind}:{','.join(parts)}"


def _number(src: str, key: str, text: Any, p: Param) -> float:
    if isinstance(text, bool):
        raise FaultSpecError(f"{src}: field '{key}' = {text!r} must be a number")
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise FaultSpecError(
            f"{src}: field '{key}' = {text!r} must be a number in [{p.lo:g}, {p.hi:g}]"
        ) from None
    if not (math.isfinite(v) and p.lo <= v <= p.hi) or (p.integer and v != int(v)):
        kind = "an integer" if p.integer else "a number"
        raise FaultSpecError(
            f"{src}: field '{key}' = {text!r} outside [{p.lo:g}, {p.hi:g}] ({kind})"
        )
    return int(v) if p.integer else v


def make_spec(kind: str, values: dict[str, Any], src: str, index: int = 0) -> FaultSpec:
    """Validate ``values`` (argument name -> value) for ``kind`` into a :class:`FaultSpec`.

    Raises
    ------
    FaultSpecError
        Naming ``src``, the field, the value and the allowed range.
    """
    if kind not in CATALOGUE:
        raise FaultSpecError(f"{src}: field 'kind' = {kind!r} must be one of {list(FAULT_KINDS)}")
    info = CATALOGUE[kind]
    allowed = {p.name: p for p in (*_COMMON, *info.params)}
    out: dict[str, float] = {}
    for key, text in values.items():
        if key not in allowed:
            raise FaultSpecError(
                f"{src}: field '{key}' = {text!r} unknown for {kind}; allowed {sorted(allowed)}"
            )
        out[key] = _number(src, key, text, allowed[key])
    start = out.pop("start_s", info.default_start_s)
    duration = out.pop("duration_s", info.default_duration_s)
    seed = int(out.pop("seed", 0))
    args = {p.name: out.get(p.name, p.default) for p in info.params}
    return FaultSpec(kind, float(start), float(duration), seed, args, index)


def parse_fault(text: str, index: int = 0, src: str = "--fault") -> FaultSpec:
    """Parse ``KIND[:ARGS]`` (see the module docstring)."""
    kind, _, rest = text.strip().partition(":")
    values: dict[str, Any] = {}
    positional = ("start_s", "duration_s")
    n_pos = 0
    for item in filter(None, (s.strip() for s in rest.replace(":", ",").split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            if n_pos >= len(positional):
                raise FaultSpecError(
                    f"{src} {text}: field 'args' = {item!r} at most two bare numbers"
                    " (start_s, duration_s); use key=value"
                )
            key, value = positional[n_pos], item
            n_pos += 1
        values[key.strip()] = value.strip()
    return make_spec(kind, values, f"{src} {text}", index)


def parse_faults(texts: list[str] | tuple[str, ...]) -> list[FaultSpec]:
    """Parse every ``--fault`` of a command line (indices in order)."""
    return [parse_fault(t, i) for i, t in enumerate(texts)]


def parse_fault_table(table: Any, file: str, i: int, index: int = 0) -> FaultSpec:
    """One ``[[faults]]`` table of a scenario TOML (``kind = "..."`` plus arguments)."""
    src = f"{file}: faults[{i}]"
    if not isinstance(table, dict):
        raise FaultSpecError(f"{src}: must be a table [[faults]]")
    values = dict(table)
    kind = values.pop("kind", None)
    if not isinstance(kind, str):
        raise FaultSpecError(f"{src}: field 'kind' = {kind!r} must be one of {list(FAULT_KINDS)}")
    return make_spec(kind, values, src, index)


def scenario_file_faults(path: str | Path, first_index: int = 0) -> list[FaultSpec]:
    """The ``[[faults]]`` of a scenario TOML file (empty if none or unreadable)."""
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError):
        return []
    raw = data.get("faults", [])
    if not isinstance(raw, list):
        return []
    return [parse_fault_table(t, str(path), i, first_index + i) for i, t in enumerate(raw)]


# --------------------------------------------------------------------------- listing
def catalogue_rows() -> list[tuple[str, str, str, str]]:
    """``(kind, args with defaults, detection bound, safe state)`` for ``pressor faults``."""
    rows = []
    for k in CATALOGUE.values():
        args = [f"start_s={k.default_start_s:g}", f"duration_s={k.default_duration_s:g}", "seed=0"]
        args += [f"{p.name}={p.default:g}" for p in k.params]
        bound = k.bound_doc + (" [scheduled controllers only]" if k.scheduled_only else "")
        rows.append((k.name, ",".join(args), bound, k.safe_state))
    return rows


# --------------------------------------------------------------------------- scoring
class FaultScorer:
    """Streaming version of :func:`fault_report`: O(faults) memory, fed one tick at a time.

    Feed every tick in order with :meth:`update`; :meth:`report` gives the same list
    :func:`fault_report` computes from whole arrays (used by long soak runs that do not keep the
    trajectory).
    """

    def __init__(
        self,
        specs: list[FaultSpec],
        fault_bit: dict[str, int],
        sample_period_s: float,
        scheduled: bool,
        auto_state: int = 1,
        recovering_state: int = 4,
    ) -> None:
        self.ts = sample_period_s
        self.auto = auto_state
        self.recovering = recovering_state
        self._prev_cmd: float | None = None
        self._items = []
        for spec in specs:
            info = spec.info
            first, end = spec.ticks(sample_period_s)
            bound = info.bound_at(sample_period_s)
            mask = 0
            for name in info.detected_as:
                mask |= fault_bit[name]
            entry: dict[str, Any] = {
                "kind": spec.kind,
                "start_tick": first,
                "end_tick": end,
                "detected_tick": None,
                "detected_as": [],
                "latency_ticks": None,
                "bound_ticks": bound,
                "within_bound": None,
                "safe_state_s": 0.0,
                "reentry_tick": None,
                "max_reentry_step_ml_h": 0.0,
                "alarm": False,
                "applicable": scheduled or not info.scheduled_only,
            }
            limit = end + (bound or 0) + int(round(2.0 / sample_period_s))
            # phase: 0 waiting, 1 in safe state, 2 done
            self._items.append(
                {
                    "e": entry,
                    "mask": mask,
                    "limit": limit,
                    "phase": 0,
                    "names": info.detected_as,
                    "bits": fault_bit,
                    "rec": False,
                }
            )

    def update(self, tick: int, state: int, faults: int, command: float) -> None:
        """One tick: supervisor state, fault bits and command (ml/h)."""
        prev = self._prev_cmd
        step = 0.0 if prev is None else abs(command - prev)
        self._prev_cmd = command
        for it in self._items:
            e = it["e"]
            if it["phase"] == 2 or not e["applicable"] or tick < e["start_tick"]:
                continue
            if it["phase"] == 0:
                if tick >= it["limit"]:
                    it["phase"] = 2
                    continue
                if faults & it["mask"]:
                    e["detected_tick"] = tick
                    e["detected_as"] = [n for n in it["names"] if faults & it["bits"][n]]
                    e["latency_ticks"] = tick - e["start_tick"]
                    bound = e["bound_ticks"]
                    e["within_bound"] = None if bound is None else e["latency_ticks"] <= bound
                    e["alarm"] = True
                    it["phase"] = 2 if state == self.auto else 1
                    it["since"] = tick
                continue
            # phase 1: in the safe state until AUTO again
            if state == self.recovering and not it["rec"]:
                it["rec"] = True
                e["max_reentry_step_ml_h"] = max(e["max_reentry_step_ml_h"], step)
            elif it["rec"]:
                e["max_reentry_step_ml_h"] = max(e["max_reentry_step_ml_h"], step)
            if state == self.auto:
                if not it["rec"]:
                    e["max_reentry_step_ml_h"] = max(e["max_reentry_step_ml_h"], step)
                e["reentry_tick"] = tick
                e["safe_state_s"] = float((tick - it["since"]) * self.ts)
                it["phase"] = 2
            else:
                e["safe_state_s"] = float((tick + 1 - it["since"]) * self.ts)

    def report(self) -> list[dict[str, Any]]:
        """The scored list (see :func:`fault_report`)."""
        return [dict(it["e"]) for it in self._items]


def fault_report(
    specs: list[FaultSpec],
    trajectory: dict[str, np.ndarray],
    fault_bit: dict[str, int],
    sample_period_s: float,
    scheduled: bool,
    auto_state: int = 1,
    recovering_state: int = 4,
) -> list[dict[str, Any]]:
    """Score each injected fault from the run's per-tick supervisor log.

    Parameters
    ----------
    specs
        The schedule (what ``--fault`` said).
    trajectory
        The loop's arrays: ``tick``, ``command_ml_h``, ``state``, ``faults`` (supervisor bits).
    fault_bit
        Supervisor fault name -> bit.
    sample_period_s
        Loop period (s).
    scheduled
        Whether the controller uses K, T, τ (else scheduling faults are not applicable).

    Returns
    -------
    list of dict
        Per fault: ``kind``, ``start_tick``, ``end_tick``, ``detected_tick`` (first tick at or after
        the start with one of the kind's detection bits; ``None`` if never), ``detected_as``,
        ``latency_ticks``, ``bound_ticks``, ``within_bound``, ``safe_state_s`` (time from detection
        until the supervisor is back in AUTO, s), ``reentry_tick`` (that AUTO tick),
        ``max_reentry_step_ml_h`` (largest |Δ command| from entering RECOVERING through the first
        AUTO tick), ``alarm`` (the detection raised the alarm), ``applicable``.
    """
    scorer = FaultScorer(specs, fault_bit, sample_period_s, scheduled, auto_state, recovering_state)
    update = scorer.update
    for k, st, fb, c in zip(
        trajectory["tick"].tolist(),
        trajectory["state"].tolist(),
        trajectory["faults"].tolist(),
        trajectory["command_ml_h"].tolist(),
        strict=True,
    ):
        update(k, st, fb, c)
    return scorer.report()
