"""The opt-in ``--schedule validated`` source: adaptation that cannot leave the certificate.

It schedules on the nominal patient and moves T and τ (K stays nominal by default) toward the
model of a bank of fixed FOPDT models (:class:`pressor.runtime.estimation.validation.ModelBank`) only while
that model predicts the measured MAP's 60 s changes better than the nominal one by a relative and
a statistical margin, at a fraction of the certified rates and inside the design box, so the
source itself never raises ``SCHED_RATE`` or ``SCHED_OUT_OF_BOX``. The evidence behind it and the
reason it is not the default are in the class docstring and ``docs/notes/estimation.md``, "Adaptation
that cannot make things worse".
"""

from __future__ import annotations

import math

from pressor.contracts.checks import check_range
from pressor.runtime.core.estimate import Estimate
from pressor.runtime.core.scheduling import Schedule, ScheduleInput
from pressor.runtime.estimation.estimator import DelayBankEstimator
from pressor.runtime.estimation.settings import DESIGN_BOX, DESIGN_RATES, NOMINAL_PLANT
from pressor.runtime.estimation.validation import ModelBank

__all__ = ["DESIGN_RATES", "ValidatedSchedule"]


class ValidatedSchedule:
    """Schedule on a validated model, slew-limited inside the design box and its certified rates.

    Opt-in (``--schedule validated``; the default ``estimated`` is
    :class:`~pressor.runtime.estimation.sources.EstimatedSchedule`). Starts on ``start`` (default the
    nominal patient) and moves toward the model the
    :class:`~pressor.runtime.estimation.validation.ModelBank` has adopted (the nominal one until another
    predicts the measured MAP changes better by its margins), each of K, T, τ by at most
    ``rate_fraction`` of the certified rate per tick, and never outside the design box: the
    source itself can raise neither ``SCHED_RATE`` nor ``SCHED_OUT_OF_BOX``. The device's values
    are ignored. The online FOPDT fit (:class:`DelayBankEstimator`) still runs: its report is
    ``Schedule.estimate`` (what the recorder and the trials' error summaries show) and its health
    is ``healthy``; it does not set the schedule. Why (evidence in ``docs/notes/estimation.md``,
    "Adaptation that cannot make things worse"): on patients outside the FOPDT class the fit chased
    the unmodelled dynamics with K, T, τ, and scheduling on it
    (:class:`~pressor.runtime.estimation.sources.EstimatedSchedule`) was worse than the nominal schedule;
    this source is below nominal there. Why it is not the default: on the project's own cohort
    (paper-tracking, seed 11) its step overshoot is 33 %,
    :class:`~pressor.runtime.estimation.sources.EstimatedSchedule`'s 5 % (its start-up jump of K to the
    estimate, which no source within the certified rates can make).

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
    adapt_K
        Also move K toward the adopted model's (default False: K stays at ``start``'s; a moving K
        is a ramp the feedforward injects into a settled loop).
    """

    source = "validated"

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
        check_range("sample_period_s", sample_period_s, 0.0, lo_open=True, unit="s")
        check_range("rate_fraction", rate_fraction, 0.0, 1.0, lo_open=True)
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

    def update(self, inputs: ScheduleInput) -> Schedule:
        """Feed the estimator and the bank one tick; move the schedule one slew step."""
        est = self.estimator.update(inputs.map_mmhg, inputs.quality, inputs.delivered_ml_h)
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
            self._schedule = Schedule(rho[0], rho[1], rho[2], "validated", True, est.healthy,
                                      not adopted, "ok" if adopted else "prior", est)  # fmt: skip
        return self._schedule
