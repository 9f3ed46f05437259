"""Experimental scheduling sources of :mod:`research.schedule_sources` (run when named in its
``--runs``): not shipped, kept so that the figures docs/notes/estimation.md gives for them reproduce.

:class:`LimitedFit` (``lpv-fit-hold`` / ``lpv-fit-slew``) box-clamps the ``estimated`` source's
schedule, jumps once and then slews; :class:`GatedFit` (``lpv-gate-*``) schedules on the fit only
while its held-out predictions beat the nominal model's ("A held-out gate on the fit").
:class:`BatchFit` (``batchfit:...``) holds a start schedule, fits a first-order-plus-delay model to
the closed-loop data by batch least squares once, and holds the fit; :func:`wide_estimate`
(``estwide:...``) is the ``estimated`` source on an estimator whose delay range reaches a wider
box ("The frontier, revisited"). :class:`OnsetSwitch` (``onset:...``) picks a first-order or a
long-delay schedule once, by when the MAP starts to move ("The start schedule decides before any
data"). Schedules on a fit from outside the loop: :mod:`research.fit_schedules`.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from pressor.runtime.core.scheduling import Schedule, ScheduleInput
from pressor.runtime.estimation.estimator import DelayBankEstimator
from pressor.runtime.estimation.settings import EstimatorSettings
from pressor.runtime.estimation.sources import EstimatedSchedule
from pressor.runtime.estimation.validated import ValidatedSchedule

__all__ = [
    "EXPERIMENT_BOX",
    "EXPERIMENT_RATES",
    "BatchFit",
    "GatedFit",
    "LimitedFit",
    "OnsetSwitch",
    "fit_closed_loop",
    "wide_estimate",
]

#: the box ((K mmHg/(ml/h)), (T s), (τ s)) and rates (per s) the experiments' own slew limits use:
#: the shipped design's when their figures were measured (before the box became K 0.15-3,
#: T 100-400 s, K rate 6e-4), kept so that those figures reproduce
EXPERIMENT_BOX = ((0.25, 1.0), (100.0, 200.0), (10.0, 45.0))
EXPERIMENT_RATES = (2e-4, 0.06, 0.1)


class LimitedFit:
    """Experiment: the ``estimated`` source's schedule, box-clamped; one jump at the first learned
    estimate, then slewed at 0.9x the certified rates (``hold``: frozen after the jump)."""

    source = "estimated"

    def __init__(self, hold: bool, sample_period_s: float) -> None:
        self.fit = EstimatedSchedule(sample_period_s=sample_period_s)
        self.hold, self.jumped, self.rho = hold, False, None
        self.box = EXPERIMENT_BOX
        self.step_ = tuple(0.9 * r * sample_period_s for r in EXPERIMENT_RATES)

    def update(self, inputs: ScheduleInput) -> Any:
        s = self.fit.update(inputs)
        goal = [
            min(max(v, lo), hi) for v, (lo, hi) in zip((s.K, s.T_s, s.tau_s), self.box, strict=True)
        ]
        if self.rho is None or (not self.jumped and not s.from_prior):
            self.jumped = self.rho is not None
            self.rho = goal
        elif not (self.jumped and self.hold):
            for i in range(3):
                d = goal[i] - self.rho[i]
                self.rho[i] += max(-self.step_[i], min(self.step_[i], d))
        return replace(s, K=self.rho[0], T_s=self.rho[1], tau_s=self.rho[2])


class _Sim:
    """One fixed FOPDT model simulated from the delivered rate's window means (``ModelBank``'s
    recursion), from the first window on."""

    def __init__(self, K: float, T: float, tau: float, W: float, u: list[float]) -> None:
        self.a = math.exp(-W / T)
        self.b = K * (1.0 - self.a)
        self.d = max(1, round(tau / W))
        self.x: list[float] = []
        for _j in range(len(u)):
            self.add(u)
        self.params = (K, T, tau)

    def add(self, u: list[float]) -> None:
        j = len(self.x)
        ud = u[j - self.d] if j >= self.d else 0.0
        self.x.append(self.a * (self.x[-1] if self.x else 0.0) + self.b * ud)


class GatedFit:
    """Experiment: the ``estimated`` source's schedule only while the fit's held-out predictions of
    the MAP's H-second changes beat the nominal model's by margins (prequential: the error at
    window j is the one of the newest snapshot of the fit taken at least ``L`` windows before j,
    simulated from the delivered rate alone, so with L >= H both ends of the change are held out
    for it); otherwise the ``validated`` source's schedule (reached at 0.9x the certified rates).

    Keywords (label ``lpv-gate:key=value:...``): H horizon s, L lag s (default H), P snapshot period
    s, rel / sig relative and statistical margins (sig in variances of a window-mean difference),
    mem score memory s, drop: "refute" (drop only when nominal beats the fit by the
    margins), "half" (drop when the fit no longer beats nominal by half the margins), "never";
    min s of scores before a decision; zero f: also S_fit < f x the sum of the squared changes;
    start 1: the fit's schedule (``s0`` K/T/tau while it reports its prior) until one decision;
    latch 1: no adoption after that decision rejects; H2 s: revoke an adopted fit for good when
    its fully held-out H2-second changes do not beat the nominal model's; trust 1: adopt at the
    learn time with no test (a timing experiment). An adopted fit is scheduled as ``estimated``
    schedules it (cautiously).
    """

    source = "estimated"

    def __init__(self, sample_period_s: float, **kw: Any) -> None:
        self.val = ValidatedSchedule(sample_period_s=sample_period_s)
        self.est = self.val.estimator
        self.fit = EstimatedSchedule(estimator=self.est)
        W = self.W = self.est.window_s
        self.H = max(1, round(kw.get("H", 20.0) / W))
        self.L = max(1, round(kw.get("L", kw.get("H", 20.0)) / W))
        self.P = max(1, round(kw.get("P", 10.0) / W))
        self.rel, self.sig = kw.get("rel", 0.25), kw.get("sig", 20.0)
        self.forget = math.exp(-W / kw.get("mem", 600.0))
        self.drop_mode = kw.get("drop", "refute")
        self.min_n = max(1, round(kw.get("min", 10.0) / W))
        self.zero = kw.get("zero", 0.0)  # also S_fit < zero * sum of dy^2 (0: off)
        self.start_fit = bool(kw.get("start", 0.0))  # the fit's schedule until the first decision
        self.decided = False
        self.trust = bool(kw.get("trust", 0.0))
        self.latch = bool(kw.get("latch", 0.0))  # one decision: never adopt after a rejection
        self.H2 = round(kw.get("H2", 0.0) / W)  # revocation horizon (0: off), fully held out
        self.S2f = self.S2n = 0.0
        self.n2 = 0
        self.revoked = False
        s0 = kw.get("s0", "")  # start=1: the schedule while the fit reports its prior, K/T/tau
        self.s0 = tuple(float(v) for v in s0.split("/")) if s0 else None
        self.S_zero = 0.0
        self.u: list[float] = []
        self.y: list[float] = []
        self.nom = _Sim(*self.val._rho, W, self.u)
        self.snaps: list[tuple[int, _Sim]] = []
        self.S_fit = self.S_nom = 0.0
        self.n = 0
        self.adopted = False
        self.ever = False
        self.rho = list(self.val._rho)
        self.step_ = tuple(0.9 * r * sample_period_s for r in EXPERIMENT_RATES)
        self.var2 = math.nan

    def _window(self) -> None:
        y, u, var = self.est.last_window()
        self.u.append(u if u == u else 0.0)
        self.y.append(y)
        self.var2 = 2.0 * var
        j = len(self.u) - 1
        self.nom.add(self.u)
        for _, sm in self.snaps:
            sm.add(self.u)
        e = self.est.estimate
        if self.trust and not e.from_prior and not self.ever:
            self.adopted = self.ever = self.decided = True  # timing experiment: no test
        if not e.from_prior and (not self.snaps or j - self.snaps[-1][0] >= self.P):
            self.snaps.append((j, _Sim(e.K, e.T_s, e.tau_s, self.W, self.u)))
        # keep only what can still be used
        keep = max(self.L, self.H2)
        while len(self.snaps) > 1 and self.snaps[1][0] <= j - keep:
            self.snaps.pop(0)
        self._revoke(j)
        errors = self._errors(j, self.L, self.H)
        if errors is None:
            return
        dy, ef, en = errors
        f = self.forget
        self.S_fit = f * self.S_fit + ef * ef
        self.S_nom = f * self.S_nom + en * en
        self.S_zero = f * self.S_zero + dy * dy
        self.n += 1
        if self.n < self.min_n:
            return
        if not self.decided:
            self.decided = True
            if self.start_fit:
                self.adopted = True  # as the fit so far: the drop rule below decides
                if not self._good(1.0):
                    self.adopted = False
                    self.rho = [self.val._rho[0], self.val._rho[1], self.val._rho[2]]
                return
        if not self.adopted:
            if not self.revoked and not (self.latch and self.decided) and self._good(1.0):
                self.adopted = self.ever = True
        elif self.drop_mode == "refute":
            if self._beats(self.S_nom, self.S_fit, 1.0):
                self.adopted = False
        elif self.drop_mode == "half":
            if not self._beats(self.S_fit, self.S_nom, 0.5):
                self.adopted = False

    def _errors(self, j: int, lag: int, horizon: int) -> tuple[float, float, float] | None:
        """(the MAP's change over ``horizon`` windows to window j, the error of the newest snapshot
        at least ``lag`` windows old predicting it, the nominal model's error); None when there is
        no such snapshot or sample."""
        y = self.y
        if j < horizon or y[j] != y[j] or y[j - horizon] != y[j - horizon]:
            return None
        use = None
        for c, sm in self.snaps:
            if c <= j - lag:
                use = sm
        if use is None:
            return None
        dy = y[j] - y[j - horizon]
        ef = dy - (use.x[j] - use.x[j - horizon])
        return dy, ef, dy - (self.nom.x[j] - self.nom.x[j - horizon])

    def _revoke(self, j: int) -> None:
        """Long horizon, fully held out: the newest snapshot at least H2 windows old predicts the
        change over the last H2 windows; revoke (for good) when it does not beat nominal."""
        if not self.H2 or not self.adopted:
            return
        errors = self._errors(j, self.H2, self.H2)
        if errors is None:
            return
        _, ef, en = errors
        f = self.forget
        self.S2f = f * self.S2f + ef * ef
        self.S2n = f * self.S2n + en * en
        self.n2 += 1
        if self.n2 >= self.min_n and not self._beats(self.S2f, self.S2n, 1.0):
            self.adopted, self.revoked = False, True
            self.rho = [self.val._rho[0], self.val._rho[1], self.val._rho[2]]

    def _good(self, scale: float) -> bool:
        ok = self._beats(self.S_fit, self.S_nom, scale)
        return ok and (not self.zero or self.S_fit < self.zero * self.S_zero)

    def _beats(self, s: float, ref: float, scale: float) -> bool:
        return s < (1.0 - self.rel * scale) * ref and ref - s >= scale * self.sig * self.var2

    def update(self, inputs: ScheduleInput) -> Any:
        vs = self.val.update(inputs)
        if self.est.windows_closed != len(self.u):
            self._window()
        e = self.est.estimate
        if self.start_fit and not self.decided:
            K, T = self.fit.keep_slope(*self.fit.cautious(e))
            if e.from_prior and self.s0:
                K, T = self.s0[:2]
            self.rho = [K, T, e.tau_s]
            return replace(vs, K=K, T_s=T, tau_s=e.tau_s)
        if self.adopted and not e.from_prior:
            K, T = self.fit.keep_slope(*self.fit.cautious(e))
            self.rho = [K, T, e.tau_s]
            return replace(vs, K=K, T_s=T, tau_s=e.tau_s)
        goal = [vs.K, vs.T_s, vs.tau_s]
        for i in range(3):
            d = goal[i] - self.rho[i]
            self.rho[i] += max(-self.step_[i], min(self.step_[i], d))
        return replace(vs, K=self.rho[0], T_s=self.rho[1], tau_s=self.rho[2])


#: :func:`fit_closed_loop`'s grids: delays (s, whole seconds) and lags (s)
BATCH_TAU_S = np.arange(0, 201, 2)
BATCH_T_S = np.arange(20.0, 1001.0, 20.0)


def fit_closed_loop(map_mmhg: np.ndarray, rate_ml_h: np.ndarray) -> tuple[float, float, float]:
    """Least-squares (K, T s, τ s) of MAP = β + K·x, x the unit-gain first-order-plus-delay response
    to the delivered rate, over the grids (β and K in closed form; samples 1 s apart). K > 0 only;
    (nan, nan, nan) when no grid point gives one."""
    y = np.asarray(map_mmhg, dtype=float)
    u = np.asarray(rate_ml_h, dtype=float)
    n, a = y.size, np.exp(-1.0 / BATCH_T_S)
    yc = y - y.mean()
    best: tuple[float, tuple[float, float, float]] = (np.inf, (math.nan,) * 3)
    for tau in BATCH_TAU_S:
        ud = np.concatenate([np.zeros(tau), u[: n - tau]]) if tau else u
        x, xs = np.empty((n, BATCH_T_S.size)), np.zeros(BATCH_T_S.size)
        for k in range(n):
            x[k] = xs
            xs = a * xs + (1.0 - a) * ud[k]
        xc = x - x.mean(axis=0)
        pp, py = np.einsum("ij,ij->j", xc, xc), xc.T @ yc
        gain = np.divide(py, pp, out=np.zeros_like(py), where=pp > 0.0)
        sse = np.where(gain > 0.0, yc @ yc - gain * py, np.inf)
        j = int(np.argmin(sse))
        if sse[j] < best[0]:
            best = (float(sse[j]), (float(gain[j]), float(BATCH_T_S[j]), float(tau)))
    return best[1]


class BatchFit:
    """Experiment: hold ``start`` (K, T s, τ s) for ``decide_s`` s, then fit the closed-loop data
    seen so far (:func:`fit_closed_loop`, 1 s means of the MAP and the delivered rate) once and
    hold that fit, clamped to ``box``, for the rest of the run (one jump)."""

    source = "estimated"

    def __init__(
        self,
        box: tuple[tuple[float, float], ...],
        start: tuple[float, float, float],
        decide_s: float,
        sample_period_s: float,
    ) -> None:
        self.box, self.per_s = box, round(1.0 / sample_period_s)
        self.decide = round(decide_s / sample_period_s)
        self.k, self.y, self.u = 0, [], []
        self.sum_y = self.sum_u = 0.0
        self.n_y = 0
        self.schedule = Schedule(*start, "estimated", True, True, True, "learning")

    def update(self, inputs: ScheduleInput) -> Schedule:
        if inputs.map_mmhg == inputs.map_mmhg:  # a NaN sample adds nothing
            self.sum_y += inputs.map_mmhg
            self.n_y += 1
        self.sum_u += inputs.delivered_ml_h
        self.k += 1
        if self.k % self.per_s == 0:
            last = self.y[-1] if self.y else math.nan
            self.y.append(self.sum_y / self.n_y if self.n_y else last)
            self.u.append(self.sum_u / self.per_s)
            self.sum_y = self.sum_u = 0.0
            self.n_y = 0
        if self.k == self.decide:
            fit = fit_closed_loop(np.array(self.y), np.array(self.u))
            if fit[0] == fit[0]:
                rho = (min(max(v, lo), hi) for v, (lo, hi) in zip(fit, self.box, strict=True))
                self.schedule = Schedule(*rho, "estimated", True, True, False, "ok")
        return self.schedule


def wide_estimate(
    box: tuple[tuple[float, float], ...],
    prior: tuple[float, float, float],
    tau_prior_s: tuple[float, float],
    caution_sigma: float,
    sample_period_s: float,
) -> EstimatedSchedule:
    """Experiment: the ``estimated`` source on a :class:`DelayBankEstimator` whose delay range,
    prior and estimate box are ``box``'s (a design with a wider delay box), with the τ prior
    ``tau_prior_s`` (mode s, std s) and the caution ``caution_sigma``."""
    settings = EstimatorSettings(tau_range_s=box[2], box=box, prior=prior, tau_prior_s=tau_prior_s)
    return EstimatedSchedule(
        DelayBankEstimator(sample_period_s, settings), caution_sigma=caution_sigma
    )


class OnsetSwitch:
    """Experiment: the first-order-plus-delay hypothesis or a long-delay one, decided once by when
    the MAP starts to move. Schedules on ``start`` (default: the source ``short``) until the
    decision; if the MAP (a 2 s moving mean) has risen ``rise_mmhg`` above its value when the
    infusion started within ``by_s`` s of that start, on the source ``short`` (fed every tick) for
    good; otherwise, from ``by_s`` s on, on the fixed ``long`` (K, T s, τ s) for good: a patient
    whose response starts late is scheduled as one with the lags in τ. At most two jumps (start to
    short, or start to long). ``rise_time_s`` is when the rise came (NaN if not)."""

    source = "nominal"

    def __init__(
        self,
        short: Any,
        long: tuple[float, float, float],
        by_s: float,
        rise_mmhg: float,
        sample_period_s: float,
        start: tuple[float, float, float] | None = None,
    ) -> None:
        self.short = short
        self.long = Schedule(*long, "nominal", True, True, True, "prior")
        self.start = (
            None if start is None else Schedule(*start, "nominal", True, True, True, "prior")
        )
        self.by_s, self.rise, self.ts = by_s, rise_mmhg, sample_period_s
        self.alpha = sample_period_s / 2.0
        self.mean = math.nan
        self.base = math.nan
        self.t_on = -1.0
        self.t = 0.0
        self.rise_time_s = math.nan
        self.decided: bool | None = None  # True: short for good, False: long for good

    def update(self, inputs: ScheduleInput) -> Schedule:
        self.t += self.ts
        if math.isfinite(inputs.map_mmhg):
            y = inputs.map_mmhg
            self.mean = y if math.isnan(self.mean) else self.mean + self.alpha * (y - self.mean)
        short = self.short.update(inputs)
        if self.decided is None:
            if self.t_on < 0.0 and inputs.delivered_ml_h > 0.0:
                self.t_on, self.base = self.t, self.mean
            if self.t_on >= 0.0:
                if self.mean - self.base >= self.rise:
                    self.decided, self.rise_time_s = True, self.t - self.t_on
                elif self.t - self.t_on >= self.by_s:
                    self.decided = False
        if self.decided is None and self.start is not None:
            return self.start
        return self.long if self.decided is False else short
