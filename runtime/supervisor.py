"""The safety supervisor: a small, pure state machine between the inputs, the controller and the pump.

No I/O, no clock: every call gets the time (s) and the inputs explicitly, so the same input sequence
gives the same output sequence, byte for byte. The loop calls, once per tick::

    run_controller = sup.assess(now_s, map_mmhg, quality, K, T_s, tau_s, sched_valid,
                                sample_age_s, link_silence_s)
    raw = controller.step(...) if run_controller else None
    command = sup.finalize(raw)            # always finite and in [0, max_rate_ml_h]

States
------
STARTUP
    No good sample seen yet. Command 0 ml/h. The first good sample moves to AUTO *in the same tick*
    (no warm-up delay), so a clean run is tick-for-tick the in-process simulator's run.
AUTO
    Inputs good: the controller's command is passed through **unchanged** (the exact float) when it
    lies in [0, max]; an out-of-range or non-finite command is clamped / held and flagged.
HOLD
    A fault was detected: the last command is held and the alarm is raised. The controller is not
    stepped (bad inputs must not wind it up). A fault lasting longer than ``hold_max_s`` → FAILSAFE.
FAILSAFE
    Link loss (immediately) or a long fault: the command ramps at ``failsafe_ramp_ml_h_per_s`` to
    ``safe_rate_ml_h`` (``None``: keep the held rate). Alarm raised.
RECOVERING
    From HOLD or FAILSAFE once every input has been good for ``recover_after_s``: the controller is
    stepped again and the output slews towards its command by at most ``reentry_step_ml_h`` per tick
    (bumpless transfer); when the two meet the state is AUTO. A new fault → HOLD.

Fault kinds (bit flags, :class:`Fault`) and detection bounds (at 10 Hz, defaults):

- ``MAP_NAN`` non-finite MAP — same tick;
- ``MAP_RANGE`` MAP outside [``map_min_mmhg``, ``map_max_mmhg``] (catches line disconnect ~0 and
  flush ~300) — same tick;
- ``MAP_SPIKE`` |MAP_k − MAP_{k−1}| > ``spike_mmhg`` between consecutive plausible samples — same
  tick; a real level change is a single spike and is accepted after ``recover_after_s``;
- ``MAP_FLATLINE`` MAP within ±``flatline_eps_mmhg`` of an anchor for ``flatline_s`` — only when
  the sensor is known to be noisy (``flatline_enabled``): a noise-free simulator legitimately
  produces constant samples;
- ``SENSOR_QUALITY`` the monitor flags the sample (any bit of ``quality`` in ``quality_mask``);
- ``STALE_SAMPLE`` newest sample older than ``stale_after_s``;
- ``LINK_LOSS`` no frame at all for ``link_loss_after_s``;
- ``SCHED_INVALID`` scheduling marked invalid or non-finite (when ``sched_required``);
- ``SCHED_OUT_OF_BOX`` K, T or τ outside ``sched_box``;
- ``SCHED_RATE`` |Δρ|/Δt above ``sched_rate_tolerance`` × ``sched_rate_bounds``;
  with ``sched_action="advise"`` these two are advisory (flagged, counted, logged; the state and
  the command are unchanged) — for a generated controller that clamps ρ to its box and limits its
  rate itself (DESIGN.md §2), so that leaving the design envelope is reported, not fought;
- ``TARGET_INVALID`` the MAP target is non-finite or outside the plausible MAP range;
- ``COMMAND_INVALID`` the controller returned a non-finite command (held, → HOLD);
- ``COMMAND_CLAMPED`` the controller returned a command outside [0, max] (clamped; an alarm, not a
  state change);
- ``LINK_ERRORS`` the link layer discarded something since the last tick (bad CRC, junk bytes,
  sequence gaps, abandoned partial frames, incomplete ticks, refused signatures) - advisory:
  what got through passed its CRC (and signature), lockstep resends lost ticks; same tick;
- ``PUMP_ALARM`` the pump reports occlusion, empty reservoir or its own watchdog
  (``pump_alarm_mask``) - on the tick its status arrives (the status of tick k follows the
  advance to k, one tick after the cause). After a pump watchdog trip the held command is re-based
  on the pump's delivered (safe) rate, so re-entry slews from what the pump actually does;
- ``PUMP_MISMATCH`` the delivered rate differs from the command sent one tick earlier by more than
  max(``pump_mismatch_abs_ml_h``, ``pump_mismatch_rel`` × command) for ``pump_mismatch_s``.

The pump checks need a pump status of this tick (``pump_delivered_ml_h`` not NaN); a missing one is
not a fault (the link watchdogs cover silence).

Deviation from the paper: the paper has no supervisor; this is the IEC 60601-1-10 shell around it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum, IntFlag

from contracts.faults import PUMP_ALARM_OCCLUSION, PUMP_ALARM_RESERVOIR_EMPTY, PUMP_ALARM_WATCHDOG

#: slack (s) on time comparisons so that k·Ts sums reach a bound that is a whole number of ticks
_EPS_S = 1e-9


class State(IntEnum):
    """Supervisor states (the integer is what the recording logs under ``/safety/state``)."""

    STARTUP = 0
    AUTO = 1
    HOLD = 2
    FAILSAFE = 3
    RECOVERING = 4


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


#: faults that never change the state (the command is clamped and the event logged)
ADVISORY = Fault.COMMAND_CLAMPED | Fault.LINK_ERRORS
#: pump alarm bits that count as a pump fault
PUMP_ALARM_MASK = PUMP_ALARM_OCCLUSION | PUMP_ALARM_RESERVOIR_EMPTY | PUMP_ALARM_WATCHDOG
#: scheduling faults that are advisory when ``sched_action == "advise"``
SCHED_ENVELOPE = Fault.SCHED_OUT_OF_BOX | Fault.SCHED_RATE
#: fault name -> bit, as plain ints (IntFlag arithmetic runs Python-level enum code)
FAULT_BITS: dict[str, int] = {f.name: int(f) for f in Fault}
#: the faults that raise the alarm (plain int, for the per-tick path)
_ALARM_FAULTS = ~int(Fault.COMMAND_CLAMPED)


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
    flatline_enabled: bool = False
    flatline_s: float = 10.0
    flatline_eps_mmhg: float = 0.05
    quality_mask: int = 0xFFFFFFFF
    stale_after_s: float = 0.35
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
    pump_mismatch_s: float = 1.0
    pump_mismatch_abs_ml_h: float = 1.0
    pump_mismatch_rel: float = 0.05

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
        need("flatline_eps_mmhg", self.flatline_eps_mmhg >= 0.0, ">= 0 mmHg")
        need("stale_after_s", self.stale_after_s > 0.0, "> 0 s")
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
        need("pump_mismatch_s", self.pump_mismatch_s >= 0.0, ">= 0 s")
        need("pump_mismatch_abs_ml_h", self.pump_mismatch_abs_ml_h > 0.0, "> 0 ml/h")
        need("pump_mismatch_rel", 0.0 <= self.pump_mismatch_rel <= 1.0, "[0, 1]")
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


def detection_bounds(cfg: SupervisorConfig) -> list[tuple[str, str]]:
    """Each detectable fault kind with its detection rule and bound under ``cfg`` (for ``pressor faults``)."""
    ts = cfg.sample_period_s
    box = (
        "not checked (controller not scheduled)"
        if cfg.sched_box is None
        else f"K, T, tau outside {cfg.sched_box}; same tick"
    )
    rates = (
        "not checked"
        if cfg.sched_rate_bounds is None
        else f"|drho/dt| > {cfg.sched_rate_tolerance} x {cfg.sched_rate_bounds}; same tick"
    )
    return [
        ("MAP_NAN", f"non-finite MAP sample; same tick ({ts} s)"),
        (
            "MAP_RANGE",
            f"MAP outside [{cfg.map_min_mmhg}, {cfg.map_max_mmhg}] mmHg (line disconnect, flush);"
            " same tick",
        ),
        ("MAP_SPIKE", f"|MAP step| > {cfg.spike_mmhg} mmHg between samples; same tick"),
        (
            "MAP_FLATLINE",
            f"MAP within +/-{cfg.flatline_eps_mmhg} mmHg for {cfg.flatline_s} s"
            " (only when the device reports sensor noise > 0)",
        ),
        ("SENSOR_QUALITY", "monitor flags the sample (quality bits); same tick"),
        ("STALE_SAMPLE", f"newest sample older than {cfg.stale_after_s} s"),
        ("LINK_LOSS", f"no frame for {cfg.link_loss_after_s} s -> FAILSAFE at once"),
        ("SCHED_INVALID", "scheduling marked invalid or non-finite; same tick"),
        ("SCHED_OUT_OF_BOX", box),
        ("SCHED_RATE", rates),
        (
            "sched action",
            "SCHED_OUT_OF_BOX / SCHED_RATE "
            + (
                "advisory: flagged and logged, the controller clamps/rate-limits itself"
                if cfg.sched_action == "advise"
                else "hold like any other fault"
            ),
        ),
        ("TARGET_INVALID", "target non-finite or outside the MAP range; same tick"),
        ("COMMAND_INVALID", "controller returned a non-finite command; same tick, held"),
        ("COMMAND_CLAMPED", f"controller command outside [0, {cfg.max_rate_ml_h}] ml/h; clamped"),
        (
            "LINK_ERRORS",
            "bad CRC / junk / sequence gap / incomplete tick / refused signature since the last"
            " tick; same tick; advisory (bad frames are discarded, lost ticks resent)",
        ),
        (
            "PUMP_ALARM",
            "pump status reports occlusion, empty reservoir or pump watchdog; the tick the status"
            " arrives (1 tick after the cause)",
        ),
        (
            "PUMP_MISMATCH",
            f"|delivered - command| > max({cfg.pump_mismatch_abs_ml_h} ml/h,"
            f" {cfg.pump_mismatch_rel:g} x command) for {cfg.pump_mismatch_s} s",
        ),
        (
            "reaction",
            f"HOLD last command (alarm); FAILSAFE after {cfg.hold_max_s} s, ramping"
            f" {cfg.failsafe_ramp_ml_h_per_s} ml/h/s to "
            + ("the held rate" if cfg.safe_rate_ml_h is None else f"{cfg.safe_rate_ml_h} ml/h"),
        ),
        (
            "re-entry",
            f"inputs good for {cfg.recover_after_s} s -> RECOVERING, command slews"
            f" <= {cfg.reentry_step_ml_h} ml/h per tick to the controller's, then AUTO",
        ),
    ]


def _clamp(value: float, high: float) -> float:
    # NaN-safe: a non-finite value never reaches the pump.
    if value != value or value <= 0.0:
        return 0.0
    return high if value >= high else value


class Supervisor:
    """The state machine; see the module docstring.

    Parameters
    ----------
    config
        Limits and timings.

    Attributes
    ----------
    state
        Current :class:`State`.
    faults
        Fault bits found at the last :meth:`assess` / :meth:`finalize`.
    command_ml_h
        The last command output (ml/h), always in [0, max_rate_ml_h].
    transition
        ``(from_state, to_state, faults)`` if the last tick changed state, else ``None``.
    new_faults
        Fault bits that rose at the last tick (for event logs).
    detections
        Count of rising edges of each fault kind (by name) over the run.
    """

    def __init__(self, config: SupervisorConfig | None = None) -> None:
        self.config = config or SupervisorConfig()
        advisory = ADVISORY | (SCHED_ENVELOPE if self.config.sched_action == "advise" else 0)
        #: the faults that change the state (plain int, for the per-tick path)
        self._holding_faults = ~int(advisory)
        self.reset()

    def reset(self) -> None:
        """Back to STARTUP with command 0 and no history."""
        self.state = State.STARTUP
        self.faults = 0
        self.command_ml_h = 0.0
        self.transition: tuple[State, State, int] | None = None
        self.new_faults = 0
        self.detections: dict[str, int] = {}
        self._prev_faults = 0
        self._prev_map: float | None = None
        self._flat_anchor: float | None = None
        self._flat_since_s = 0.0
        self._prev_sched: tuple[float, float, float] | None = None
        self._prev_sched_s = 0.0
        self._fault_since_s: float | None = None
        self._good_since_s: float | None = None
        self._now_s = 0.0
        self._run_controller = False
        self._entry_state = State.STARTUP
        self._mismatch_since_s: float | None = None

    @property
    def alarm(self) -> bool:
        """True while the supervisor is not in normal automatic control or a fault is present."""
        return self.state in (State.HOLD, State.FAILSAFE) or bool(self.faults & _ALARM_FAULTS)

    # -- input checks ---------------------------------------------------------------------------
    def _check_map(self, now_s: float, map_mmhg: float, quality: int) -> int:
        cfg = self.config
        faults = 0
        if quality & cfg.quality_mask:
            faults |= Fault.SENSOR_QUALITY
        if not math.isfinite(map_mmhg):
            return faults | Fault.MAP_NAN
        if not cfg.map_min_mmhg <= map_mmhg <= cfg.map_max_mmhg:
            return faults | Fault.MAP_RANGE
        if self._prev_map is not None and abs(map_mmhg - self._prev_map) > cfg.spike_mmhg:
            faults |= Fault.MAP_SPIKE
        self._prev_map = map_mmhg
        if cfg.flatline_enabled:
            if (
                self._flat_anchor is None
                or abs(map_mmhg - self._flat_anchor) > cfg.flatline_eps_mmhg
            ):
                self._flat_anchor = map_mmhg
                self._flat_since_s = now_s
            elif now_s - self._flat_since_s >= cfg.flatline_s - _EPS_S:
                faults |= Fault.MAP_FLATLINE
        return faults

    def _check_sched(self, now_s: float, K: float, T_s: float, tau_s: float, valid: bool) -> int:
        cfg = self.config
        if not (cfg.sched_required or cfg.sched_box or cfg.sched_rate_bounds):
            return 0
        rho = (K, T_s, tau_s)
        if not valid or not all(math.isfinite(v) for v in rho):
            self._prev_sched = None
            return Fault.SCHED_INVALID
        faults = 0
        if cfg.sched_box is not None and any(
            not lo <= v <= hi for v, (lo, hi) in zip(rho, cfg.sched_box, strict=True)
        ):
            faults |= Fault.SCHED_OUT_OF_BOX
        if cfg.sched_rate_bounds is not None and self._prev_sched is not None:
            dt = now_s - self._prev_sched_s
            if dt > 0.0 and any(
                abs(v - p) > cfg.sched_rate_tolerance * b * dt
                for v, p, b in zip(rho, self._prev_sched, cfg.sched_rate_bounds, strict=True)
            ):
                faults |= Fault.SCHED_RATE
        if self._prev_sched is None or now_s > self._prev_sched_s:
            self._prev_sched = rho
            self._prev_sched_s = now_s
        return faults

    def _check_pump(self, now_s: float, delivered: float, alarms: int) -> int:
        cfg = self.config
        if delivered != delivered:  # no fresh status: neither fault nor evidence of health
            return 0
        faults = 0
        if alarms & cfg.pump_alarm_mask:
            faults |= Fault.PUMP_ALARM
            if alarms & PUMP_ALARM_WATCHDOG:
                # the pump fell back to its own safe rate: hold *that*, re-enter from it
                self.command_ml_h = _clamp(delivered, cfg.max_rate_ml_h)
        sent = self.command_ml_h
        if alarms & cfg.pump_alarm_mask or abs(delivered - sent) <= max(
            cfg.pump_mismatch_abs_ml_h, cfg.pump_mismatch_rel * abs(sent)
        ):
            self._mismatch_since_s = None
        else:
            if self._mismatch_since_s is None:
                self._mismatch_since_s = now_s
            if now_s - self._mismatch_since_s >= cfg.pump_mismatch_s - _EPS_S:
                faults |= Fault.PUMP_MISMATCH
        return faults

    # -- the two phases of a tick -----------------------------------------------------------------
    def assess(
        self,
        now_s: float,
        map_mmhg: float,
        quality: int = 0,
        K: float = math.nan,
        T_s: float = math.nan,
        tau_s: float = math.nan,
        sched_valid: bool = True,
        sample_age_s: float = 0.0,
        link_silence_s: float = 0.0,
        target_mmhg: float = 80.0,
        link_errors: int = 0,
        pump_delivered_ml_h: float = math.nan,
        pump_alarms: int = 0,
    ) -> bool:
        """Check this tick's inputs and update the state; return True if the controller is to run.

        Parameters
        ----------
        now_s
            Time (s) of this tick on the loop's clock.
        map_mmhg, quality
            Newest MAP sample (mmHg) and its monitor quality bits.
        K, T_s, tau_s, sched_valid
            Newest scheduling parameters (mmHg/(ml/h), s, s) and their validity flag.
        sample_age_s
            Time (s) since the newest sample was received; the MAP checks are skipped once stale.
        link_silence_s
            Time (s) since any frame was received from the device.
        target_mmhg
            The MAP target (mmHg) the controller will be given.
        link_errors
            Frames the link layer discarded since the last tick (advisory ``LINK_ERRORS``).
        pump_delivered_ml_h, pump_alarms
            This tick's pump status (delivered ml/h, alarm bits); NaN: no fresh status.
        """
        cfg = self.config
        self._now_s = now_s
        self.transition = None
        self._entry_state = self.state
        faults = 0
        if link_silence_s >= cfg.link_loss_after_s - _EPS_S:
            faults |= Fault.LINK_LOSS
        if sample_age_s > cfg.stale_after_s:
            faults |= Fault.STALE_SAMPLE
        else:
            faults |= self._check_map(now_s, map_mmhg, quality)
            faults |= self._check_sched(now_s, K, T_s, tau_s, sched_valid)
            if not cfg.map_min_mmhg <= target_mmhg <= cfg.map_max_mmhg:  # False for NaN too
                faults |= Fault.TARGET_INVALID
        if link_errors:
            faults |= Fault.LINK_ERRORS
        faults |= self._check_pump(now_s, pump_delivered_ml_h, pump_alarms)
        self.faults = faults
        state = self.state
        if faults & self._holding_faults:
            self._good_since_s = None
            if self._fault_since_s is None:
                self._fault_since_s = now_s
            if state in (State.AUTO, State.RECOVERING):
                state = State.FAILSAFE if faults & Fault.LINK_LOSS else State.HOLD
            elif state == State.HOLD and (
                faults & Fault.LINK_LOSS or now_s - self._fault_since_s >= cfg.hold_max_s - _EPS_S
            ):
                state = State.FAILSAFE
        else:
            self._fault_since_s = None
            if self._good_since_s is None:
                self._good_since_s = now_s
            if state == State.STARTUP:
                state = State.AUTO
            elif (
                state in (State.HOLD, State.FAILSAFE)
                and now_s - self._good_since_s >= cfg.recover_after_s - _EPS_S
            ):
                state = State.RECOVERING
        self.state = state
        self._run_controller = state in (State.AUTO, State.RECOVERING)
        return self._run_controller

    def finalize(self, raw_command_ml_h: float | None) -> float:
        """Turn the controller's command (``None`` if it did not run) into the pump command (ml/h).

        Returns a finite value in [0, max_rate_ml_h] on every path.
        """
        cfg = self.config
        high = cfg.max_rate_ml_h
        previous = self.command_ml_h
        state = self.state
        if self._run_controller:
            raw = math.nan if raw_command_ml_h is None else raw_command_ml_h
            if not math.isfinite(raw):
                self.faults |= Fault.COMMAND_INVALID
                self._good_since_s = None
                self._fault_since_s = self._now_s
                state = State.HOLD
                command = previous
            else:
                if not 0.0 <= raw <= high:
                    self.faults |= Fault.COMMAND_CLAMPED
                target = _clamp(raw, high)
                if state == State.AUTO:
                    command = target
                else:  # RECOVERING: bumpless slew towards the controller
                    step = cfg.reentry_step_ml_h
                    delta = target - previous
                    if abs(delta) <= step:
                        command = target
                        state = State.AUTO
                    else:
                        command = previous + (step if delta > 0.0 else -step)
        elif state == State.FAILSAFE:
            goal = previous if cfg.safe_rate_ml_h is None else cfg.safe_rate_ml_h
            step = cfg.failsafe_ramp_ml_h_per_s * cfg.sample_period_s
            delta = goal - previous
            command = goal if abs(delta) <= step else previous + (step if delta > 0.0 else -step)
        elif state == State.STARTUP:
            command = 0.0
        else:  # HOLD
            command = previous
        self.command_ml_h = _clamp(command, high)
        self.state = state
        if state != self._entry_state:
            self.transition = (self._entry_state, state, self.faults)
        rising = self.faults & ~self._prev_faults
        self.new_faults = rising
        if rising:
            for name in fault_names(rising):
                self.detections[name] = self.detections.get(name, 0) + 1
        self._prev_faults = self.faults
        return self.command_ml_h
