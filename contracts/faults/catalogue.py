"""The fault catalogue: each kind with its arguments, detection bound and safe state.

Detection bounds (defaults, 10 Hz; the *watchdog period* is the supervisor's link-loss time,
1 s = 10 ticks): every link and sensor fault is detected within one watchdog period of its start
(bound in :class:`FaultKind`); pump faults within the bounds given per kind; scheduling faults
only when the controller is scheduled (the PI baseline ignores K, T, τ, so for it they are
"not applicable"). Latency is counted in ticks from the fault's first tick.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: default ``start_s`` of a fault (s of sim time)
DEFAULT_START_S = 300.0


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
        Supervisor fault names (``pressor.runtime.core.supervisor_config.Fault``) that count as detecting
        it.
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


#: the arguments every fault kind takes besides its own
COMMON_PARAMS = (
    Param("start_s", DEFAULT_START_S, 0.0, 7 * 86400.0, "first fault time (s of sim time)"),
    Param("duration_s", math.nan, 0.0, 7 * 86400.0, "length (s); 0 = one tick"),
    Param("seed", 0, 0, 2**32 - 1, "seed of the fault's random draws", integer=True),
)

_LINK_SAFE = (
    "AUTO: CRC/sequence checks discard the bad frames, lockstep resends the tick; advisory alarm"
    " LINK_ERRORS logged"
)
_HOLD = "HOLD (last command held, controller frozen, alarm); FAILSAFE after hold_max_s"
_LOSS = "FAILSAFE at LINK_LOSS (ramp to safe rate); pump watchdog after 5 s"

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
            "LINK_LOSS after 1 s (10 ticks); STALE_SAMPLE (sample age limit, 3 s) comes later",
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
            "LINK_LOSS after 1 s (10 ticks); STALE_SAMPLE (sample age limit, 3 s) comes later",
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
            (Param("K", 5.0, -10.0, 10.0, "reported K (mmHg/(ml/h))"),),
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


def catalogue_rows() -> list[tuple[str, str, str, str]]:
    """``(kind, args with defaults, detection bound, safe state)`` for ``pressor faults``."""
    rows = []
    for k in CATALOGUE.values():
        args = [f"start_s={k.default_start_s:g}", f"duration_s={k.default_duration_s:g}", "seed=0"]
        args += [f"{p.name}={p.default:g}" for p in k.params]
        bound = k.bound_doc + (" [scheduled controllers only]" if k.scheduled_only else "")
        rows.append((k.name, ",".join(args), bound, k.safe_state))
    return rows
