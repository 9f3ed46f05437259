"""What the safety supervisor checks and with which limits: states, fault kinds, configuration.

The state machine itself is :mod:`pressor.runtime.core.supervisor`; this module holds what it is configured
with; what ``pressor faults`` prints of it is :mod:`pressor.runtime.core.supervisor_bounds`.

Fault kinds (bit flags, :class:`Fault`) and detection bounds (at 10 Hz, defaults):

- ``MAP_NAN`` non-finite MAP — same tick;
- ``MAP_RANGE`` MAP outside [``map_min_mmhg``, ``map_max_mmhg``] (catches line disconnect ~0 and
  flush ~300) — same tick;
- ``MAP_SPIKE`` |MAP_k − MAP_{k−1}| > ``spike_mmhg`` between consecutive plausible samples — same
  tick; a real level change is a single spike and is accepted after ``recover_after_s``;
- ``MAP_FLATLINE`` a frozen line (new samples stuck within ±max(``flatline_eps_mmhg``, quantum/2)
  for a count of samples scaled to the announced noise and the quantum, and ``flatline_s`` at
  least) or a damped one (variance collapse of the new samples) - :mod:`pressor.runtime.core.flatline`; only
  when the monitor announces noise (``sensor_noise_mmhg`` > 0): a noise-free simulator
  legitimately produces constant samples;
- ``SENSOR_QUALITY`` the monitor flags the sample (any bit of ``quality`` in ``quality_mask``; by
  default every bit but ``QUALITY_HELD``, which marks a repeated value, not a fault);
- ``STALE_SAMPLE`` the sample older than ``stale_after_s`` (the runtime's
  ``--sample-age-limit-s``, default 3 s; a held sample ages from the last new one);
- ``LINK_LOSS`` no frame at all for ``link_loss_after_s``;
- ``SCHED_INVALID`` scheduling marked invalid or non-finite (when ``sched_required``);
- ``SCHED_OUT_OF_BOX`` K, T or τ outside ``sched_box``;
- ``SCHED_RATE`` |Δρ|/Δt above ``sched_rate_tolerance`` × ``sched_rate_bounds``;
  with ``sched_action="advise"`` these two are advisory (flagged, counted, logged; the state and
  the command are unchanged) — for a generated controller that clamps ρ to its box and limits its
  rate itself (docs/INTERFACES.md), so that leaving the design envelope is reported, not fought;
- ``TARGET_INVALID`` the MAP target is non-finite or outside the plausible MAP range;
- ``COMMAND_INVALID`` the controller returned a non-finite command (held, → HOLD);
- ``CONTROLLER_FAULT`` (``controller_faults="latch"``, ``pressor run``) the controller raised in
  ``step`` or returned something ``float()`` refuses (held, → HOLD); with ``"stop"`` (``pressor
  sil``, ``trial``) the core ends the run instead
  (:class:`pressor.runtime.core.closed_loop.ControllerError`). Under ``"latch"`` this and
  ``COMMAND_INVALID`` hold until the clinician's acknowledgement
  (:mod:`pressor.runtime.core.supervisor_io`);
- ``COMMAND_CLAMPED`` the controller returned a command outside [0, max] (clamped; an alarm, not a
  state change);
- ``LINK_ERRORS`` the link layer discarded something since the last tick (bad CRC, junk bytes,
  sequence gaps, abandoned partial frames, incomplete ticks, refused signatures, pump statuses
  numbered for a tick already answered, which leave the pump checks off) - advisory:
  what got through passed its CRC (and signature), lockstep resends lost ticks; same tick;
- ``PUMP_ALARM`` the pump reports occlusion, empty reservoir or its own watchdog
  (``pump_alarm_mask``) - on the tick its status arrives (the status of tick k follows the
  advance to k, one tick after the cause). After a pump watchdog trip the held command is re-based
  on the pump's delivered (safe) rate, so re-entry slews from what the pump actually does;
- ``PUMP_MISMATCH`` the delivered rate differs from the command sent one tick earlier by more than
  max(``pump_mismatch_abs_ml_h``, ``pump_mismatch_rel`` × command) for ``pump_mismatch_s``; at
  once when the status reports a rate no pump delivers (infinite, negative, or above
  ``pump_max_ml_h``, the device's announced pump maximum; default ``max_rate_ml_h``);
- ``ESTIMATOR_FALLBACK`` (``--schedule estimated`` only) the online estimator's health check
  rejected its estimate (diverged, non-finite, K or T implausible): the scheduling source reports
  the prior (the nominal patient) instead, so the safe action is already taken - the controller is
  scheduled on the prior and the loop keeps running; advisory (no state change), alarm raised,
  logged; same tick;
- ``ESTIMATE_OUT_OF_BOX`` (``--schedule estimated`` only) the estimate the controller is scheduled
  on has been outside ``sched_box`` for ``estimate_box_s`` (default 60 s) without a break;
  advisory alarm (the controller clamps ρ to its box, as it does with any scheduling value);
- ``SAMPLE_TIME`` (the shell's boundary check, :mod:`pressor.runtime.shell.boundary`) the MAP sample's
  ``sim_time_s`` is not finite, runs backwards, or is not its tick times the period (within half a
  period; a tick number that jumped while the time did not): the sample is not used, the loop runs
  on the tick's own time (tick × period) and holds; the next sample with a consistent time clears
  it;
- ``RECORD_ERROR`` a record writer (the ``.tlog``, the ``.rrd``) failed (disk full, I/O error): the
  record stops there, control goes on; advisory, alarm raised for the rest of the run;
- ``DEVICE_CHANGED`` a hello in the middle of the run announces another drug, concentration, pump
  maximum, monitor noise, sample period or link mode than the first one (:mod:`pressor.runtime.shell.boundary`):
  the run keeps the first hello's terms, the device is sent a PRESSOR_REFUSAL, and the loop
  holds until the clinician acknowledges (latched like a controller fault);
- ``DOSE_HARD_LIMIT``, ``DOSE_SOFT_LIMIT``, ``DOSE_HOUR_LIMIT`` (``pressor run``, with
  ``dose_limits`` from the drug library) the final command is cut to the hard dose maximum, to
  the soft one (unless the clinician confirmed doses above it, then only flagged), or to what the
  sliding hour allows, tapered over 10 min and charged on elapsed time
  (:mod:`pressor.runtime.core.dose_guard`); ``DOSE_SHORTFALL`` a cut held 10 min with MAP more than 5 mmHg
  below the target: the patient cannot be brought to target within the limits; advisory, alarm
  raised (the guard's ``reason`` names the limit and the shortfall).

The pump checks need a pump status of this tick (``pump_delivered_ml_h`` not NaN); a missing one is
not a fault (the link watchdogs cover silence).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from typing import Any

from pressor.contracts.controller import Controller
from pressor.contracts.faults import (
    PUMP_ALARM_OCCLUSION,
    PUMP_ALARM_RESERVOIR_EMPTY,
    PUMP_ALARM_WATCHDOG,
    QUALITY_HELD,
)
from pressor.runtime.core.dose_guard import (
    DOSE_HARD_LIMIT,
    DOSE_HOUR_LIMIT,
    DOSE_SHORTFALL,
    DOSE_SOFT_LIMIT,
    DoseLimits,
)


class State(IntEnum):
    """Supervisor states (the integer is what the recording logs under ``/safety/state``)."""

    STARTUP = 0
    AUTO = 1
    HOLD = 2
    FAILSAFE = 3
    RECOVERING = 4
    STOPPED = 5
    MANUAL = 6


class Fault(IntFlag):
    """Fault kinds detected by the supervisor (bit flags; see the module docstring for bounds)."""

    NONE = 0
    MAP_NAN = 1 << 0
    MAP_RANGE = 1 << 1
    MAP_SPIKE = 1 << 2
    MAP_FLATLINE = 1 << 3
    SENSOR_QUALITY = 1 << 4
    STALE_SAMPLE = 1 << 5
    LINK_LOSS = 1 << 6
    SCHED_INVALID = 1 << 7
    SCHED_OUT_OF_BOX = 1 << 8
    SCHED_RATE = 1 << 9
    COMMAND_INVALID = 1 << 10
    COMMAND_CLAMPED = 1 << 11
    TARGET_INVALID = 1 << 12
    LINK_ERRORS = 1 << 13
    PUMP_ALARM = 1 << 14
    PUMP_MISMATCH = 1 << 15
    ESTIMATOR_FALLBACK = 1 << 16
    ESTIMATE_OUT_OF_BOX = 1 << 17
    DOSE_HARD_LIMIT = DOSE_HARD_LIMIT
    DOSE_SOFT_LIMIT = DOSE_SOFT_LIMIT
    DOSE_HOUR_LIMIT = DOSE_HOUR_LIMIT
    CONTROLLER_FAULT = 1 << 21
    SAMPLE_TIME = 1 << 22
    RECORD_ERROR = 1 << 23
    DEVICE_CHANGED = 1 << 24
    DOSE_SHORTFALL = DOSE_SHORTFALL


#: the drug library's faults (advisory: the command is cut, the state unchanged)
DOSE_FAULTS = (
    Fault.DOSE_HARD_LIMIT | Fault.DOSE_SOFT_LIMIT | Fault.DOSE_HOUR_LIMIT | Fault.DOSE_SHORTFALL
)


#: the controller's own faults: what ``controller_faults="latch"`` keeps until acknowledged
CONTROLLER_FAULTS = Fault.CONTROLLER_FAULT | Fault.COMMAND_INVALID
#: what the supervisor does with a controller fault: "stop" (the core ends the run on an
#: exception; a non-finite command holds until inputs are good for recover_after_s) or "latch"
#: (``pressor run``: both hold until the clinician acknowledges)
CONTROLLER_FAULT_ACTIONS = ("stop", "latch")

#: faults the shell finds at the boundary, before the core (:mod:`pressor.runtime.shell.boundary`): handed
#: to the supervisor in ``SupervisorInput.boundary_faults``
BOUNDARY_FAULTS = Fault.SAMPLE_TIME | Fault.RECORD_ERROR | Fault.DEVICE_CHANGED

#: faults that never change the state (the command is clamped and the event logged)
ADVISORY = (
    Fault.COMMAND_CLAMPED
    | Fault.LINK_ERRORS
    | Fault.RECORD_ERROR
    | Fault.ESTIMATOR_FALLBACK
    | Fault.ESTIMATE_OUT_OF_BOX
    | DOSE_FAULTS
)
#: pump alarm bits that count as a pump fault
PUMP_ALARM_MASK = PUMP_ALARM_OCCLUSION | PUMP_ALARM_RESERVOIR_EMPTY | PUMP_ALARM_WATCHDOG
#: scheduling faults that are advisory when ``sched_action == "advise"``
SCHED_ENVELOPE = Fault.SCHED_OUT_OF_BOX | Fault.SCHED_RATE
#: fault name -> bit, as plain ints (IntFlag arithmetic runs Python-level enum code)
FAULT_BITS: dict[str, int] = {f.name: int(f) for f in Fault}
#: the default sample age limit (s): three updates of a 1 Hz monitor (one missed update plus
#: jitter), 3 % of the fastest patient lag (T >= 100 s) - holding MAP that long costs nothing
DEFAULT_SAMPLE_AGE_LIMIT_S = 3.0
#: quality bits that count as bad by default: all but QUALITY_HELD (unknown bits too)
QUALITY_MASK = 0xFFFFFFFF & ~QUALITY_HELD
#: the faults that raise the alarm (plain int, for the per-tick path): every one, a clamped command
#: too (the shipped controllers clamp themselves and never trip it; a plugin that does is alarmed)
ALARM_FAULTS = sum(FAULT_BITS.values())


def fault_names(faults: int) -> list[str]:
    """The names of the bits set in ``faults`` (e.g. ``['MAP_NAN', 'STALE_SAMPLE']``)."""
    return [name for name, bit in FAULT_BITS.items() if faults & bit]


@dataclass(frozen=True)
class SupervisorConfig:
    """Limits and timings of the supervisor (units in the names).

    Raises
    ------
    ValueError
        On construction, naming the field, its value and the allowed range.
    """

    sample_period_s: float = 0.1
    max_rate_ml_h: float = 120.0
    map_min_mmhg: float = 20.0
    map_max_mmhg: float = 250.0
    spike_mmhg: float = 20.0
    sensor_noise_mmhg: float = 0.0
    flatline_s: float = 10.0
    flatline_eps_mmhg: float = 0.05
    flatline_window: int = 30
    flatline_ratio: float = 0.25
    quality_mask: int = QUALITY_MASK
    stale_after_s: float = DEFAULT_SAMPLE_AGE_LIMIT_S
    link_loss_after_s: float = 1.0
    sched_required: bool = False
    sched_box: tuple[tuple[float, float], ...] | None = None
    sched_rate_bounds: tuple[float, ...] | None = None
    sched_rate_tolerance: float = 1.5
    sched_action: str = "hold"
    hold_max_s: float = 10.0
    safe_rate_ml_h: float | None = None
    failsafe_ramp_ml_h_per_s: float = 1.0
    recover_after_s: float = 5.0
    reentry_step_ml_h: float = 0.5
    pump_alarm_mask: int = PUMP_ALARM_MASK
    pump_max_ml_h: float | None = None
    pump_mismatch_s: float = 1.0
    pump_mismatch_abs_ml_h: float = 1.0
    pump_mismatch_rel: float = 0.05
    estimate_box_s: float = 60.0
    dose_limits: DoseLimits | None = None
    controller_faults: str = "stop"

    def __post_init__(self) -> None:
        def need(name: str, ok: bool, allowed: str) -> None:
            if not ok:
                raise ValueError(
                    f"supervisor field '{name}' = {getattr(self, name)!r}; allowed {allowed}"
                )

        need("sample_period_s", 0.0 < self.sample_period_s <= 10.0, "(0, 10] s")
        need("max_rate_ml_h", 0.0 < self.max_rate_ml_h <= 10000.0, "(0, 10000] ml/h")
        need("map_min_mmhg", 0.0 <= self.map_min_mmhg < self.map_max_mmhg, "[0, map_max_mmhg)")
        need("map_max_mmhg", self.map_max_mmhg <= 400.0, "(map_min_mmhg, 400] mmHg")
        need("spike_mmhg", self.spike_mmhg > 0.0, "> 0 mmHg")
        need("flatline_s", self.flatline_s > 0.0, "> 0 s")
        need("sensor_noise_mmhg", 0.0 <= self.sensor_noise_mmhg <= 50.0, "[0, 50] mmHg")
        need("flatline_eps_mmhg", self.flatline_eps_mmhg > 0.0, "> 0 mmHg")
        need("flatline_window", 2 <= self.flatline_window <= 10000, "[2, 10000] samples")
        need("flatline_ratio", 0.0 < self.flatline_ratio < 1.0, "(0, 1)")
        need(
            "stale_after_s",
            self.sample_period_s <= self.stale_after_s <= 60.0,
            "[sample_period_s, 60] s",
        )
        need("link_loss_after_s", self.link_loss_after_s > 0.0, "> 0 s")
        need("sched_rate_tolerance", self.sched_rate_tolerance >= 1.0, ">= 1")
        need("sched_action", self.sched_action in ("hold", "advise"), "'hold' or 'advise'")
        need("hold_max_s", self.hold_max_s >= 0.0, ">= 0 s")
        need(
            "safe_rate_ml_h",
            self.safe_rate_ml_h is None or 0.0 <= self.safe_rate_ml_h <= self.max_rate_ml_h,
            "None or [0, max_rate_ml_h] ml/h",
        )
        need("failsafe_ramp_ml_h_per_s", self.failsafe_ramp_ml_h_per_s > 0.0, "> 0 ml/h/s")
        need("recover_after_s", self.recover_after_s >= 0.0, ">= 0 s")
        need("reentry_step_ml_h", self.reentry_step_ml_h > 0.0, "> 0 ml/h per tick")
        need(
            "pump_max_ml_h",
            self.pump_max_ml_h is None or self.max_rate_ml_h <= self.pump_max_ml_h <= 10000.0,
            "None or [max_rate_ml_h, 10000] ml/h",
        )
        need("pump_mismatch_s", self.pump_mismatch_s >= 0.0, ">= 0 s")
        need("pump_mismatch_abs_ml_h", self.pump_mismatch_abs_ml_h > 0.0, "> 0 ml/h")
        need("pump_mismatch_rel", 0.0 <= self.pump_mismatch_rel <= 1.0, "[0, 1]")
        need("estimate_box_s", self.estimate_box_s >= 0.0, ">= 0 s")
        need(
            "controller_faults",
            self.controller_faults in CONTROLLER_FAULT_ACTIONS,
            " or ".join(repr(a) for a in CONTROLLER_FAULT_ACTIONS),
        )
        if self.sched_box is not None:
            need(
                "sched_box",
                len(self.sched_box) == 3 and all(lo <= hi for lo, hi in self.sched_box),
                "three (low, high) pairs for K, T_s, tau_s",
            )
        if self.sched_rate_bounds is not None:
            need(
                "sched_rate_bounds",
                len(self.sched_rate_bounds) == 3 and all(b > 0 for b in self.sched_rate_bounds),
                "three positive rates for K (1/s·mmHg/(ml/h)), T (s/s), tau (s/s)",
            )


def sched_limits_of(controller: Controller) -> tuple[Any, Any]:
    """The design box and rate bounds a generated controller declares, else ``(None, None)``.

    Looked up on the instance, then on its module: ``GRID_LO``/``GRID_HI`` (3 values: K, T s,
    τ s) and ``RATE_BOUNDS`` (3 values per s) as ``codegen`` emits them. The PI baseline
    declares none (it is not scheduled), so its scheduling inputs are not checked.
    """
    module = sys.modules.get(type(controller).__module__)
    sources = (controller, module)

    def find(name: str) -> Any:
        for src in sources:
            if src is not None and hasattr(src, name):
                return getattr(src, name)
        return None

    lo, hi, rate = find("GRID_LO"), find("GRID_HI"), find("RATE_BOUNDS")
    box = None
    if lo is not None and hi is not None and len(lo) == 3 and len(hi) == 3:
        box = tuple((float(a), float(b)) for a, b in zip(lo, hi, strict=True))
    rates = tuple(float(r) for r in rate) if rate is not None and len(rate) == 3 else None
    return box, rates


def supervisor_config_for(
    controller: Controller, sensor_noise_mmhg: float, **overrides: Any
) -> SupervisorConfig:
    """A supervisor configuration matched to ``controller`` and the device's sensor.

    Sample period and pump limit come from the controller; the scheduling box and rates from
    :func:`sched_limits_of`; the flatline rules scale with the announced noise and are off
    without it (a noise-free simulated sensor legitimately repeats values). Leaving the design box or rate bounds is
    advisory by default (``sched_action="advise"``): the generated controller clamps and
    rate-limits ρ itself (docs/INTERFACES.md), and the simulated patients routinely leave the envelope
    (paper-tracking seed 3: K down to 0.18 < 0.25; τ moving ~1 s/s against a 0.1 s/s bound), so
    holding would stop LPV control of most patients. ``overrides`` replace any field.
    """
    box, rates = sched_limits_of(controller)
    cfg: dict[str, Any] = {
        "sample_period_s": float(controller.sample_period_s),
        "max_rate_ml_h": float(controller.max_rate_ml_h),
        "sensor_noise_mmhg": float(sensor_noise_mmhg),
        "sched_required": box is not None,
        "sched_box": box,
        "sched_rate_bounds": rates,
        "sched_action": "advise",
        "stale_after_s": max(DEFAULT_SAMPLE_AGE_LIMIT_S, float(controller.sample_period_s)),
    }
    cfg.update(overrides)
    return SupervisorConfig(**cfg)
