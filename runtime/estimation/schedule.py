"""Scheduling sources: where the controller's K, T, τ come from, one tick at a time.

Every source has the same method::

    update(map_mmhg, quality, delivered_ml_h, device_K, device_T_s, device_tau_s, device_valid)
        -> Schedule

with the tick's MAP sample (mmHg) and monitor quality bits, the pump's delivered rate (ml/h, from
PUMP_STATUS) and whatever scheduling parameters the device sent (K mmHg/(ml/h), T s, τ s; NaN and
``device_valid=False`` when it sent none). Units and ranges of the result: K > 0 mmHg/(ml/h),
T > 0 s, τ ≥ 0 s (the controller clamps to its design box, as it always has).

:class:`OracleSchedule`
    The device's values, exactly as sent (a simulator's truth; research comparisons only).
    ``valid`` is False when the device sent none, flagged them invalid or sent non-finite values
    (NaN when it sent none); the supervisor and the controller's own invalid-input handling then
    apply, exactly as before this module existed.
:class:`NominalSchedule`
    Constant prior values (default: the nominal patient, :data:`NOMINAL_PLANT`); always valid.
:class:`EstimatedSchedule`
    Adaptation that cannot leave the certificate (issue 25): starts on the nominal patient and
    moves T and τ (K stays nominal by default) toward the model of a bank of fixed FOPDT models
    (:class:`runtime.estimation.validation.ModelBank`) only while that model predicts the measured
    MAP's 60 s changes better than the nominal model by a relative and a statistical margin, at
    0.9x the certified rates and inside the design box: the source itself never raises
    ``SCHED_RATE`` or ``SCHED_OUT_OF_BOX``. The online FOPDT fit still runs and is reported
    (``Schedule.estimate``, ``healthy``), but no longer sets the schedule.

    Why this method, on evidence (``docs/ESTIMATION.md``, "Adaptation that cannot make things
    worse"; tuned on cohort seed 11 and the independent models' seed 2026): scheduling on the fit
    itself (now :class:`runtime.estimation.fitted.FittedSchedule`) was 1.24-1.58x the nominal
    schedule's IAE on patients outside the FOPDT class, chasing their higher-order dynamics with
    K, T, τ. A slew-limited K is a ramp the 2-DOF feedforward (u_ff ∝ 1/K) injects into a settled
    loop, which the slow certified integral follows with a steady error: moving K at the certified
    2e-4 /s was 1.16x nominal on the project's own cohort; a one-time jump to the bank's first
    choice was far worse (overshoot 80-110 %). T and τ leave a settled loop's feedforward
    unchanged, so adapting only them was below nominal on every model (0.94-0.97x median).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from runtime.estimation.estimate import Estimate
from runtime.estimation.estimator import DESIGN_BOX, NOMINAL_PLANT, DelayBankEstimator
from runtime.estimation.validation import ModelBank

SOURCES = ("oracle", "estimated", "nominal")
#: the default design's certified rates (synthesis/data/default_design.toml; the generated
#: module's RATE_BOUNDS): K mmHg/(ml/h) per s, T s per s, τ s per s
DESIGN_RATES: tuple[float, float, float] = (2e-4, 0.06, 0.1)


@dataclass(frozen=True, slots=True)
class Schedule:
    """The scheduling parameters of one tick.

    Attributes
    ----------
    K, T_s, tau_s
        Sensitivity (mmHg/(ml/h)), lag (s), delay (s); NaN only from an oracle without values.
    source
        ``"oracle"``, ``"estimated"`` or ``"nominal"``.
    valid
        Whether K, T, τ are usable (finite, positive).
    healthy
        False when the estimator's health check rejected its latest estimate (always True for the
        other sources).
    from_prior
        True when the values are the prior's (the nominal source, or the estimator learning or
        falling back).
    reason
        ``"ok"``, or why the values are not a fresh estimate (``"learning"``, ``"diverged"``,
        ``"K implausible"``, ``"T implausible"``, ``"no device values"``, ``"prior"``).
    estimate
        The estimator's full report (uncertainty, confidence, design-box flag); None for the
        other sources.
    """

    K: float
    T_s: float
    tau_s: float
    source: str
    valid: bool
    healthy: bool
    from_prior: bool
    reason: str
    estimate: Estimate | None = None


class ScheduleSource(Protocol):
    """What the closed-loop core (:mod:`runtime.core`) calls once per tick."""

    source: str

    def update(
        self,
        map_mmhg: float,
        quality: int,
        delivered_ml_h: float,
        device_K: float,
        device_T_s: float,
        device_tau_s: float,
        device_valid: bool,
    ) -> Schedule:
        """The tick's scheduling parameters (see the module docstring)."""
        ...


class OracleSchedule:
    """Schedule on the device's K, T, τ (the simulator's truth), passed through as sent."""

    source = "oracle"

    def update(
        self,
        map_mmhg: float,
        quality: int,
        delivered_ml_h: float,
        device_K: float,
        device_T_s: float,
        device_tau_s: float,
        device_valid: bool,
    ) -> Schedule:
        """The device's values as sent; ``valid`` only if finite and flagged valid."""
        ok = device_valid and math.isfinite(device_K + device_T_s + device_tau_s)
        return Schedule(device_K, device_T_s, device_tau_s, "oracle", ok, True, False,
                        "ok" if ok else "no device values")  # fmt: skip


class NominalSchedule:
    """Schedule on constant values (a fixed-gain controller at that point).

    Parameters
    ----------
    K, T_s, tau_s
        Sensitivity (mmHg/(ml/h)) > 0, lag (s) > 0, delay (s) >= 0; default the nominal patient.
    """

    source = "nominal"

    def __init__(
        self,
        K: float = NOMINAL_PLANT[0],
        T_s: float = NOMINAL_PLANT[1],
        tau_s: float = NOMINAL_PLANT[2],
    ) -> None:
        if not (math.isfinite(K) and K > 0.0):
            raise ValueError(f"K={K!r} mmHg/(ml/h) must be finite and > 0")
        if not (math.isfinite(T_s) and T_s > 0.0):
            raise ValueError(f"T_s={T_s!r} s must be finite and > 0")
        if not (math.isfinite(tau_s) and tau_s >= 0.0):
            raise ValueError(f"tau_s={tau_s!r} s must be finite and >= 0")
        self._schedule = Schedule(float(K), float(T_s), float(tau_s), "nominal", True, True, True,
                                  "prior")  # fmt: skip

    def update(
        self,
        map_mmhg: float,
        quality: int,
        delivered_ml_h: float,
        device_K: float,
        device_T_s: float,
        device_tau_s: float,
        device_valid: bool,
    ) -> Schedule:
        """The constant values (the same object every tick)."""
        return self._schedule


class EstimatedSchedule:
    """Schedule on a validated model, slew-limited inside the design box and its certified rates.

    Starts on ``start`` (default the nominal patient) and moves toward the model the
    :class:`~runtime.estimation.validation.ModelBank` has adopted (the nominal one until another
    predicts the measured MAP changes better by its margins), each of K, T, τ by at most
    ``rate_fraction`` of the certified rate per tick, and never outside the design box: the
    source itself can raise neither ``SCHED_RATE`` nor ``SCHED_OUT_OF_BOX``. The device's values
    are ignored. The online FOPDT fit (:class:`DelayBankEstimator`) still runs: its report is
    ``Schedule.estimate`` (what the recorder and the trials' error summaries show) and its health
    is ``healthy``; it no longer sets the schedule. Why (evidence in ``docs/ESTIMATION.md``,
    "Adaptation that cannot make things worse"): on patients outside the FOPDT class the fit chased
    the unmodelled dynamics with K, T, τ, and scheduling on it was worse than the nominal schedule.

    Parameters
    ----------
    estimator
        The FOPDT fit to run and report (default: :class:`DelayBankEstimator` at
        ``sample_period_s``); its windows feed the bank.
    sample_period_s
        Tick period (s), > 0.
    bank
        The validating model bank (default: :class:`ModelBank` with the nominal patient first).
    start
        (K mmHg/(ml/h), T s, τ s) of the first tick, inside ``box``; default the nominal patient.
    box
        The design box ((K lo, hi), (T lo, hi) s, (τ lo, hi) s) the schedule stays in.
    rate_bounds
        The certified rates (K mmHg/(ml/h) per s, T s per s, τ s per s), each > 0.
    rate_fraction
        Fraction of the certified rates the schedule moves at, in (0, 1].
    """

    source = "estimated"

    def __init__(
        self,
        estimator: DelayBankEstimator | None = None,
        sample_period_s: float = 0.1,
        bank: ModelBank | None = None,
        start: tuple[float, float, float] = NOMINAL_PLANT,
        box: tuple[tuple[float, float], ...] = DESIGN_BOX,
        rate_bounds: tuple[float, float, float] = DESIGN_RATES,
        rate_fraction: float = 0.9,
        adapt_K: bool = False,
    ) -> None:
        if not (math.isfinite(sample_period_s) and sample_period_s > 0.0):
            raise ValueError(f"sample_period_s={sample_period_s!r} s must be finite and > 0")
        if not (math.isfinite(rate_fraction) and 0.0 < rate_fraction <= 1.0):
            raise ValueError(f"rate_fraction={rate_fraction!r} must be in (0, 1]")
        if len(rate_bounds) != 3 or not all(math.isfinite(r) and r > 0.0 for r in rate_bounds):
            raise ValueError(f"rate_bounds={rate_bounds!r} must be 3 finite values > 0 (per s)")
        if len(box) != 3 or not all(math.isfinite(lo) and lo < hi for lo, hi in box):
            raise ValueError(f"box={box!r} must be ((K lo, hi), (T lo, hi), (tau lo, hi))")
        if len(start) != 3 or not all(
            lo <= v <= hi for v, (lo, hi) in zip(start, box, strict=True)
        ):
            raise ValueError(f"start={start!r} must be (K, T_s, tau_s) inside box={box!r}")
        self.estimator = estimator if estimator is not None else DelayBankEstimator(sample_period_s)
        n_win = round(self.estimator.window_s / sample_period_s)
        self.bank = bank if bank is not None else ModelBank(self.estimator.window_s, n_win, start)
        self._box = tuple((float(lo), float(hi)) for lo, hi in box)
        self._step = tuple(rate_fraction * r * sample_period_s for r in rate_bounds)
        self._rho = [float(v) for v in start]
        self._windows = 0
        self._adapt_K = bool(adapt_K)
        self._last: Estimate | None = None
        self._schedule: Schedule | None = None

    def update(
        self,
        map_mmhg: float,
        quality: int,
        delivered_ml_h: float,
        device_K: float,
        device_T_s: float,
        device_tau_s: float,
        device_valid: bool,
    ) -> Schedule:
        """Feed the estimator and the bank one tick; move the schedule one slew step."""
        est = self.estimator.update(map_mmhg, quality, delivered_ml_h)
        bank = self.bank
        closed = self.estimator.windows_closed
        if closed != self._windows:
            self._windows = closed
            bank.close_window(*self.estimator.last_window())
        bank.step()
        target = bank.target
        rho, moved = self._rho, False
        if not self._adapt_K:
            target = (rho[0], target[1], target[2])
        for i in range(3):
            lo, hi = self._box[i]
            goal = min(max(target[i], lo), hi)
            now = rho[i]
            if goal != now:
                s = self._step[i]
                rho[i] = goal if abs(goal - now) <= s else (now + s if goal > now else now - s)
                moved = True
        if moved or est is not self._last or self._schedule is None:
            self._last = est
            adopted = bank.adopted != 0
            self._schedule = Schedule(rho[0], rho[1], rho[2], "estimated", True, est.healthy,
                                      not adopted, "ok" if adopted else "prior", est)  # fmt: skip
        return self._schedule


def make_schedule(
    source: str, sample_period_s: float = 0.1
) -> OracleSchedule | NominalSchedule | EstimatedSchedule:
    """The scheduling source named ``source`` (one of :data:`SOURCES`) at ``sample_period_s`` (s)."""
    if source == "oracle":
        return OracleSchedule()
    if source == "nominal":
        return NominalSchedule()
    if source == "estimated":
        return EstimatedSchedule(sample_period_s=sample_period_s)
    raise ValueError(f"schedule source {source!r} not one of {SOURCES}")
