"""The drug library's limits on the final pump command (the last step of the supervisor).

:class:`DoseGuard` sees every command the supervisor is about to output - after the controller,
any plugin controller, the supervisor's own state logic and its [0, max_rate_ml_h] clamp - and:

1. cuts it to what the hourly dose maximum still allows over the sliding hour, tapered
   (``DOSE_HOUR_LIMIT``, below);
2. cuts it to the hard dose maximum ``hard_max_ml_h`` (``DOSE_HARD_LIMIT``);
3. cuts it to the soft maximum ``soft_max_ml_h`` unless the clinician confirmed doses above it
   (``confirm_above_soft``; then a command above it is only flagged) (``DOSE_SOFT_LIMIT``);
4. raises ``DOSE_SHORTFALL`` once a cut has held for ``shortfall_after_s`` (10 min) of run time
   while MAP stayed below the target by more than ``shortfall_mmhg`` (5 mmHg): the patient cannot
   be brought to target within the library's limits, and the clinician must be told which limit
   and by how much (:attr:`DoseGuard.reason`). The pump's maximum counts as such a limit when it
   is the lower one (a dilute syringe, a small pump): a command held there is as short of the
   target as one a dose limit cut.

All raise the alarm and are counted as detections; none changes the supervisor's state (the
command is cut, the loop keeps running). The limits are the library's dose limits converted to
ml/h once (:meth:`pressor.runtime.inputs.drug_library.DrugEntry.limits`, rounded down).

**Elapsed time.** The hour is counted on the run clock, not in ticks: each call charges the
previous command for the time that passed since the previous call (the pump runs a command until
the next one), so a loop that stalled, skipped periods or jumped ticks is charged what the pump
delivered meanwhile. The window is a queue of (start, end, volume) segments with its running sum
(O(1) per call, amortised; exact sums every hour of calls against drift).

**Taper.** A cap that is simply the room left in the hour is a cliff: a patient on 120 ml/h hits
it at full rate and drops to 0 until the first minutes of the hour slide out. The guard instead
limits the command to the largest constant rate that the hour allows for the next ``taper_s``
(10 min) without running out on the way - what is left of the hour plus what leaves the window
by each instant of those 10 minutes. Far from the limit this is far above any command; near it
the command declines smoothly to the rate the room can sustain until the old doses start
leaving, then to the rate at which they leave. The cap on this tick's volume (room / period)
stays as the hard guarantee: the commanded volume over any hour, the pump running each command
one period, never exceeds ``max_ml_per_hour``.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

#: fault bits, the same values as :class:`pressor.runtime.core.supervisor_config.Fault` (no import cycle)
DOSE_HARD_LIMIT = 1 << 18
DOSE_SOFT_LIMIT = 1 << 19
DOSE_HOUR_LIMIT = 1 << 20
DOSE_SHORTFALL = 1 << 25

_HOUR_S = 3600.0


@dataclass(frozen=True)
class DoseLimits:
    """One drug's limits at one concentration and weight, in ml/h (what the supervisor compares).

    Defined here, with the guard that enforces it, not in :mod:`pressor.runtime.inputs.drug_library` (which
    builds it): the core imports nothing from the inputs above it.

    Attributes
    ----------
    hard_max_ml_h
        Largest command (ml/h): the hard dose maximum, rounded down.
    soft_max_ml_h
        Commands above it (ml/h) are cut to it, or with ``confirm_above_soft`` flagged
        (``DOSE_SOFT_LIMIT``).
    max_ml_per_hour
        Largest volume (ml) commanded over any sliding hour: the hourly dose maximum.
    concentration_ug_ml
        The syringe (µg/ml).
    weight_kg
        The patient's weight (kg), or ``None`` when not given (limits in µg/min).
    confirm_above_soft
        The clinician confirmed doses above the soft maximum (``pressor run
        --confirm-above-soft-limit``): the soft maximum then only raises the advisory.
    """

    hard_max_ml_h: float
    soft_max_ml_h: float
    max_ml_per_hour: float
    concentration_ug_ml: float
    weight_kg: float | None = None
    confirm_above_soft: bool = False


class DoseGuard:
    """Hard, soft and hourly dose limits on the pump command (see the module docstring).

    Parameters
    ----------
    limits
        The limits in ml/h (:class:`DoseLimits`).
    sample_period_s
        The loop period (s): each command runs at least this long.
    taper_s
        The horizon (s) the hourly limit is approached over.
    shortfall_after_s
        How long (s of run time) a cut may hold with MAP short of the target before
        ``DOSE_SHORTFALL``.
    shortfall_mmhg
        MAP below the target by more than this (mmHg) is short of it.

    Attributes
    ----------
    reason
        What cuts the command now, one line naming the limit, the command asked and given (ml/h)
        and, for a shortfall, the MAP missing (mmHg); ``""`` when nothing does.
    """

    def __init__(
        self,
        limits: DoseLimits,
        sample_period_s: float,
        taper_s: float = 600.0,
        shortfall_after_s: float = 600.0,
        shortfall_mmhg: float = 5.0,
    ) -> None:
        self.limits = limits
        self.period_s = float(sample_period_s)
        self.taper_s = float(taper_s)
        self.shortfall_after_s = float(shortfall_after_s)
        self.shortfall_mmhg = float(shortfall_mmhg)
        self.reset()

    def reset(self) -> None:
        """Forget the hour's history."""
        # (start s, end s, ml): older than now - hour + taper in _leaving, newer in _recent
        self._leaving: deque[tuple[float, float, float]] = deque()
        self._recent: deque[tuple[float, float, float]] = deque()
        self._leaving_ml = 0.0
        self._recent_ml = 0.0
        self._last_s: float | None = None
        self._last_ml_h = 0.0
        self._calls = 0
        self._short_since_s: float | None = None
        self.reason = ""

    @property
    def hour_volume_ml(self) -> float:
        """Volume (ml) charged over the last hour (as of the last call)."""
        return max(self._leaving_ml + self._recent_ml, 0.0)

    def _charge(self, now_s: float) -> None:
        """Charge the previous command for the time since the previous call; drop what left the
        hour; move what leaves within ``taper_s`` to the leaving queue."""
        last = self._last_s
        if last is not None and now_s > last:  # time never runs backwards here
            ml = self._last_ml_h * (now_s - last) / _HOUR_S
            if ml > 0.0:
                self._recent.append((last, now_s, ml))
                self._recent_ml += ml
        start = now_s - _HOUR_S
        leaving, recent = self._leaving, self._recent
        while leaving and leaving[0][1] <= start:
            self._leaving_ml -= leaving.popleft()[2]
        edge = start + self.taper_s
        while recent and recent[0][0] < edge:
            seg = recent.popleft()
            self._recent_ml -= seg[2]
            if seg[1] > start:
                leaving.append(seg)
                self._leaving_ml += seg[2]
        self._calls += 1
        if self._calls % 36000 == 0:  # no drift of the running sums over long runs
            self._leaving_ml = math.fsum(s[2] for s in leaving)
            self._recent_ml = math.fsum(s[2] for s in recent)

    def _window_ml(self, now_s: float) -> float:
        """The volume (ml) charged in the hour ending at ``now_s``, the oldest segment counted for
        its part inside the hour."""
        start = now_s - _HOUR_S
        partial = 0.0
        if self._leaving:
            t0, t1, ml = self._leaving[0]
            if t0 < start < t1:
                partial = ml * (start - t0) / (t1 - t0)
        return max(self._leaving_ml - partial, 0.0) + max(self._recent_ml, 0.0)

    def _leaving_by(self, now_s: float, tau_s: float) -> float:
        """The volume (ml) that leaves the hour within ``tau_s`` after ``now_s`` (the head of
        the leaving segments only)."""
        start = now_s - _HOUR_S
        end = start + tau_s
        out = 0.0
        for t0, t1, ml in self._leaving:
            if t0 >= end:
                break
            lo, hi = max(t0, start), min(t1, end)
            if hi > lo:
                out += ml * (hi - lo) / (t1 - t0)
        return out

    def _taper_cap(self, now_s: float, room_ml: float) -> float:
        """The largest constant rate (ml/h) the hour allows for the next ``taper_s`` without
        running out on the way: at every instant within it, what was given stays within the room
        plus what has left the window by then (the smallest of (room + left by tau) / tau over the
        times tau a segment starts leaving, and over the whole horizon).

        Infinite far from the limit (the room alone lasts the horizon at the hard maximum); else
        one pass over the segments that leave within the horizon.
        """
        if room_ml * _HOUR_S / self.taper_s >= self.limits.hard_max_ml_h:
            return math.inf
        start = now_s - _HOUR_S
        cap = math.inf
        left_ml = 0.0
        for t0, t1, ml in self._leaving:
            if t1 <= start:
                continue
            if t0 > start:  # nothing of it leaves before start + tau: last until then
                cap = min(cap, (room_ml + left_ml) / (t0 - start))
                left_ml += ml
            else:
                left_ml += ml * (t1 - start) / (t1 - t0)
        cap = min(cap, (room_ml + left_ml) / self.taper_s)
        return cap * _HOUR_S

    def _hour(self, now_s: float) -> tuple[float, float]:
        """Charge the time since the previous call; the volume (ml) in the hour ending at
        ``now_s`` and the rate (ml/h) the hourly maximum allows now.

        The one step of :meth:`limit` that walks the hour's segments (the simulator's compiled
        twin, :mod:`pressor.hil_sim.native.dose_guard`, replaces it).
        """
        self._charge(now_s)
        used = self._window_ml(now_s)
        room = max(self.limits.max_ml_per_hour - used, 0.0)
        # this tick's volume fits the room plus what leaves the hour during the tick (exact: the
        # window one period on never holds more than the maximum), and the taper
        tick_ml = room + self._leaving_by(now_s, self.period_s)
        hour_cap = min(tick_ml / (self.period_s / _HOUR_S), self._taper_cap(now_s, room))
        return used, hour_cap * (1.0 - 1e-12)

    def limit(
        self,
        command_ml_h: float,
        now_s: float | None = None,
        short_mmhg: float = math.nan,
        chosen: bool = False,
        pump_max_ml_h: float = math.inf,
    ) -> tuple[float, int]:
        """The command (ml/h) cut to the limits, and the fault bits raised; charges the time since
        the previous call.

        Parameters
        ----------
        command_ml_h
            The supervisor's command, finite and >= 0.
        now_s
            The run clock (s); ``None``: one period after the previous call.
        short_mmhg
            How far MAP is below the target now (mmHg; NaN when unknown).
        chosen
            The clinician chose this rate (MANUAL): above the soft maximum it is only flagged, as
            with ``confirm_above_soft``; the hard and hourly maxima cut it as any command.
        pump_max_ml_h
            The pump's maximum (ml/h), the supervisor's clamp: a command there that no dose limit
            cut counts towards ``DOSE_SHORTFALL`` as a cut one does (module docstring).
        """
        if now_s is None:
            now_s = 0.0 if self._last_s is None else self._last_s + self.period_s
        used, hour_cap = self._hour(now_s)
        lim = self.limits
        faults = 0
        asked = command = command_ml_h
        limit = ""
        if command > hour_cap:
            command = hour_cap
            faults |= DOSE_HOUR_LIMIT
            limit = (
                f"the hourly maximum {lim.max_ml_per_hour:g} ml ({used:.2f} ml in the last hour)"
            )
        if command > lim.hard_max_ml_h:
            command = lim.hard_max_ml_h
            faults |= DOSE_HARD_LIMIT
            limit = f"the hard maximum {lim.hard_max_ml_h:g} ml/h"
        if command > lim.soft_max_ml_h:
            faults |= DOSE_SOFT_LIMIT
            if not (lim.confirm_above_soft or chosen):
                command = lim.soft_max_ml_h
                limit = f"the soft maximum {lim.soft_max_ml_h:g} ml/h (not confirmed above)"
        self._last_s, self._last_ml_h = now_s, command
        at_pump_max = not limit and command >= pump_max_ml_h  # the pump holds it, no limit cut
        faults |= self._shortfall(now_s, bool(limit) or at_pump_max, short_mmhg)
        self.reason = (
            f"dose cut to {command:.2f} ml/h (asked {asked:.2f}) by {limit}" if limit else ""
        )
        if faults & DOSE_SHORTFALL:
            within = "the pump's maximum" if at_pump_max else "the drug library's limits"
            held = f"dose held at the pump's maximum {pump_max_ml_h:g} ml/h"
            self.reason = (self.reason or held) + (
                f"; MAP {short_mmhg:.1f} mmHg below the target for"
                f" {now_s - self._short_since_s:.0f} s: the patient cannot be brought to target"
                f" within {within}"
            )
        return command, faults

    def _shortfall(self, now_s: float, held: bool, short_mmhg: float) -> int:
        """``DOSE_SHORTFALL`` once a cut has held with MAP short of the target long enough."""
        if not (held and short_mmhg > self.shortfall_mmhg):  # False for NaN
            self._short_since_s = None
            return 0
        if self._short_since_s is None:
            self._short_since_s = now_s
        return DOSE_SHORTFALL if now_s - self._short_since_s >= self.shortfall_after_s else 0
