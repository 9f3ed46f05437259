"""Online K, T, τ estimator: a bank of delay models, each an output-error Kalman filter.

Plant (mmHg, ml/h, s): MAP = β + ΔMAP, ΔMAP = K·e^(−τs)/(Ts + 1)·i, with the baseline β unknown and
shifting (haemorrhage, bolus) and K, T drifting. The estimator averages the accepted MAP samples (ȳ)
and the delivered rate (ū) over windows of ``window_s`` (default 2 s: 20 ticks at 10 Hz). For each
candidate delay d·window_s of the bank it *simulates* the drug response from the rate alone and
fits, by the recursive prediction-error method (a Kalman filter on θ = (a, b, c) as random walks,
with the output-error gradient ψ = (∂x̂/∂a, ∂x̂/∂b, 1))::

    x̂_j = a·x̂_{j−1} + b·ū_{j−d},      ȳ_j − y_ref = x̂_j + c + e_j,
    a = e^(−Δ/T), b = K·(1 − a), c = β − y_ref (the baseline's shift, mmHg)

``y_ref`` is the first valid window (the MAP before the drug acts). Per window the random walks
have standard deviations ``q_a``, ``q_b`` and ``q_c`` (mmHg: a haemorrhage of 10 mmHg over 5 min is
≈ 0.07 mmHg per window); the output error's variance is ``r_mmhg``² or, when larger, the monitor
noise the window means show (:class:`pressor.runtime.estimation.noise.WindowNoise`). An innovation beyond
``jump_sigma`` standard deviations is taken as a baseline jump (the offset's variance is raised by
its square, so c absorbs it rather than a, b).
Each model keeps an exponentially forgotten negative log-likelihood of its innovations (memory
``memory_s``, default 200 s); the best model (log-likelihood plus the τ prior's −2 log-density,
below) gives K = b/(1 − a) and T = −Δ/ln a, and τ is refined between bank members by a parabola
through those sums, minus half a window (the averaged MAP lags the window's end by Δ/2, which
biases τ on synthetic data). Models that fall more than ``reseed_nll`` behind the best, or fail the
health check, restart from the best healthy model's θ, covariance and simulation (only the delay
then differs, so the comparison of delays stays fair). Uncertainty: K and T standard deviations
from the filter covariance (first order); τ an interval holding ~90 % of the bank's posterior
weight.

Two priors from the literature patient model this project simulates (the paper's Table 1,
``hil_sim/patients/patient.py``) stand in where a settled loop carries no information. The τ prior
(``tau_prior_s``, Gaussian, mode 15 s, std 10 s: a held infusion's delay) weighs the delays where
the data do not: after a rate change the likelihood differences between delays are hundreds of
units and the prior (at most 9) does not matter; once the loop has settled the forgetting shrinks
them and τ̂ returns to the prior's mode. The T-drift prior (``T_drift_per_ml_h``): the lag rises
with the infused volume, T = T_min + b_T·∫i dt, b_T in [1e-4, 3e-4] s per (ml/h)·s; before each
fitted window every model's T moves by b_T·ū·Δ at the same K (ū the window's delivered rate),
and the data correct it whenever the rate moves (without it T̂ kept the start-up's ≈ 100 s while
T rose 10–30 s an hour). 0 disables it, for a patient whose lag does not follow this law.

Why this method (evidence: ``benchmarks/estimator.py`` and ``tests/runtime/estimation/test_estimator.py``):

* Output error, not equation error (ARX): an ARX fit ``ȳ_j = a ȳ_{j−1} + b ū_{j−d} + c`` carries the
  monitor noise in its regressor and the baseline's ramps in the coefficient of a constant; on the
  cohort's ``paper-disturbance`` runs it gave median K errors of 40–235 % (the haemorrhage read as a
  change of K and T), and its differenced form was biased to T ≈ 25 s by the noise. Simulating x̂
  from the rate keeps noise out of the regressors, and c is the baseline itself, so a haemorrhage is
  a level shift of c.
* Linear in θ for a given delay: each filter is a 3×3 update (a few µs in pure Python), far cheaper
  and more robust than the cubature filter on (x, K, T) states of arXiv 1910.01022, whose delay bank
  we keep. The bank's updates are staggered (``ceil(models/window ticks)`` per tick), so no tick
  pays for the whole bank.
* Averaging to 2 s conditions the problem (at 10 Hz, a = e^(−0.1/150) ≈ 0.9993 and K = b/(1 − a)
  amplifies errors ~1500×; at 2 s ~75×) and divides white monitor noise by √20.
* Random walks rather than exponential forgetting: with no excitation the covariance grows only by
  the small process noise instead of winding up, so the estimate stays bounded and its uncertainty
  grows honestly.

Start-up and health: until the K and T relative standard deviations have fallen below
``learn_rel_std`` (≈ 40–80 s after the first rate step has reached the MAP) the prior (the nominal
patient, :data:`NOMINAL_PLANT`) is reported with reason ``"learning"``; the scheduling source
schedules cautiously around it (:class:`pressor.runtime.estimation.sources.EstimatedSchedule`). Every
estimate is checked (finite parameters and covariance, 0 < a < 1, K and T in the plausible ranges)
before it is reported; when the bank's best model fails, the prior is reported with the reason
(``"diverged"``, ``"K implausible"``, ``"T implausible"``) and ``healthy=False``; once an estimate
has been reported it stays so until a model with ``min_age_s`` of data since a restart from the
prior passes (before, the learning gate already holds the prior: an ill-conditioned fit in the
step's first minute does not lock the estimate out for ``min_age_s``). Bad samples are
kept out by :class:`pressor.runtime.estimation.gate.SampleGate`; a window with fewer than half its samples
accepted is not fitted (the models still simulate through it).

The tuning evidence (q_c, memory, drift prior) and the known limits (what a settled loop cannot
tell): ``docs/notes/estimation.md``.
"""

from __future__ import annotations

import math

from pressor.contracts.checks import check_range
from pressor.runtime.core.estimate import Estimate
from pressor.runtime.estimation.bank import DelayModel, FilterSettings
from pressor.runtime.estimation.gate import SampleGate
from pressor.runtime.estimation.noise import WindowNoise
from pressor.runtime.estimation.settings import DEFAULT_SETTINGS, EstimatorSettings


class DelayBankEstimator:
    """Online estimator of K (mmHg/(ml/h)), T (s), τ (s); call :meth:`update` once per tick.

    Parameters
    ----------
    sample_period_s
        Tick period (s), > 0 (10 Hz: 0.1): the loop's, not a tuning.
    settings
        The tuning (:class:`~pressor.runtime.estimation.settings.EstimatorSettings`; units, ranges and
        defaults there); its ``window_s`` must be a whole number (>= 2) of ``sample_period_s``.
    gate
        The sample gate (default: :class:`SampleGate` at ``sample_period_s``).
    """

    def __init__(
        self,
        sample_period_s: float = 0.1,
        settings: EstimatorSettings = DEFAULT_SETTINGS,
        gate: SampleGate | None = None,
    ) -> None:
        check_range("sample_period_s", sample_period_s, 0.0, lo_open=True, unit="s")
        window_s, tau_range_s, prior = settings.window_s, settings.tau_range_s, settings.prior
        T_plausible_s, rel_std = settings.T_plausible_s, settings.prior_rel_std
        n_win = round(window_s / sample_period_s)
        if n_win < 2 or abs(n_win * sample_period_s - window_s) > 1e-9 * window_s:
            raise ValueError(
                f"window_s={window_s!r} must be a whole number (>= 2) of sample_period_s="
                f"{sample_period_s!r}"
            )
        self.window_s = float(window_s)
        self._n_win = n_win
        d_lo = max(1, math.ceil(tau_range_s[0] / window_s - 1e-9))
        d_hi = max(d_lo + 2, math.floor(tau_range_s[1] / window_s + 1e-9))
        self.delays_s = tuple(d * self.window_s for d in range(d_lo, d_hi + 1))
        self.prior = (float(prior[0]), float(prior[1]), float(prior[2]))
        filters = FilterSettings(
            window_s=self.window_s,
            prior_K=self.prior[0],
            prior_T_s=self.prior[1],
            prior_rel_std=rel_std,
            baseline_std_mmhg=settings.baseline_std_mmhg,
            q_a2=settings.q_a * settings.q_a,
            q_b2=settings.q_b * settings.q_b,
            q_c2=settings.q_c * settings.q_c,
            jump2=settings.jump_sigma * settings.jump_sigma,
            forget=math.exp(-window_s / settings.memory_s),
            # a kept within T in [T_lo / 2, 2 T_hi]: beyond the plausible range, so the check sees it
            a_lo=math.exp(-window_s / (T_plausible_s[0] * 0.5)),
            a_hi=math.exp(-window_s / (T_plausible_s[1] * 2.0)),
        )
        self._bank = tuple(DelayModel(d, filters) for d in range(d_lo, d_hi + 1))
        n = len(self._bank)
        self._per_tick = -(-n // n_win)
        self._reseed = settings.reseed_nll
        self._min_age = round(settings.min_age_s / window_s)
        self._tau_offset = 0.5 * window_s  # averaged MAP lags the window's end by half a window
        # the τ prior as −2 log-density per bank member, added to its log-likelihood when selecting
        mode, std = settings.tau_prior_s
        self._pen = [((d - self._tau_offset - mode) / std) ** 2 for d in self.delays_s]
        self._learn = settings.learn_rel_std
        self._K_pl, self._T_pl, self.box = settings.K_plausible, T_plausible_s, settings.box
        self.gate = gate if gate is not None else SampleGate(sample_period_s)
        # decimation: sums of the open window; ring of closed windows' rates (preallocated)
        self._phase = 0
        self._ysum = self._usum = 0.0
        self._ny = self._nu = 0
        self._uring = [math.nan] * (d_hi + 1)
        self._j = -1  # index of the newest closed window
        self._y_dev = math.nan  # newest window's ȳ − y_ref (mmHg)
        # s of T per ml/h of a window's rate
        self._drift = settings.T_drift_per_ml_h * self.window_s
        self._dT = 0.0  # the newest window's expected rise of T (s)
        self._noise = WindowNoise(settings.r_mmhg, self.window_s)  # the output-error variance
        self._y_ref = math.nan
        self._next = n  # next model to update (n: none pending)
        self._w = [0.0] * n
        self._order = list(range(n))
        self._learned = False
        self._rejection = ""  # the last health-check rejection, until a mature model passes
        self.updates = 0  # filter updates done (all models)
        self._prior_estimate = Estimate(
            *self.prior, rel_std * self.prior[0], rel_std * self.prior[1],
            self.delays_s[0] - self._tau_offset, self.delays_s[-1] - self._tau_offset, 0.0, True,
            True, "learning", self._inside(*self.prior),
        )  # fmt: skip
        self.estimate = self._prior_estimate

    # -- per tick ---------------------------------------------------------------------------------
    def update(self, map_mmhg: float, quality: int, delivered_ml_h: float) -> Estimate:
        """Take one tick's MAP sample (mmHg, monitor quality bits) and delivered rate (ml/h).

        Returns
        -------
        Estimate
            The current report (the same object until a window's bank update completes).
        """
        if self.gate.accept(map_mmhg, quality):
            self._ysum += map_mmhg
            self._ny += 1
        if math.isfinite(delivered_ml_h) and delivered_ml_h >= 0.0:
            self._usum += delivered_ml_h
            self._nu += 1
        self._phase += 1
        if self._phase == self._n_win:
            self._close_window()
        bank = self._bank
        n = len(bank)
        if self._next < n and self._y_ref == self._y_ref:
            stop = min(n, self._next + self._per_tick)
            ring, j, y = self._uring, self._j, self._y_dev
            dT, r2 = self._dT, self._noise.variance
            for m in range(self._next, stop):
                model = bank[m]
                u_d = ring[(j - model.delay_windows) % len(ring)]
                self.updates += model.step(u_d, y, dT, r2)
            self._next = stop
            if stop == n:
                self.estimate = self._select()
        return self.estimate

    def _close_window(self) -> None:
        nw = self._n_win
        y = self._ysum / self._ny if 2 * self._ny >= nw else math.nan
        u = self._usum / nw if self._nu == nw else math.nan
        self._phase = self._ny = self._nu = 0
        self._ysum = self._usum = 0.0
        self._j += 1
        self._uring[self._j % len(self._uring)] = u
        self._dT = self._drift * u if u == u else 0.0
        self._noise.update(y)
        if self._y_ref != self._y_ref and y == y:
            self._y_ref = y
        self._y_dev = y - self._y_ref
        self._next = 0

    @property
    def windows_closed(self) -> int:
        """How many windows have closed (the newest one's index plus 1)."""
        return self._j + 1

    def last_window(self) -> tuple[float, float, float]:
        """Newest window: (MAP mean − reference mmHg, rate mean ml/h, NaN if unknown; var mmHg²)."""
        if self._j < 0:
            return math.nan, math.nan, self._noise.variance
        return self._y_dev, self._uring[self._j % len(self._uring)], self._noise.variance

    # -- report -----------------------------------------------------------------------------------
    def _inside(self, K: float, T_s: float, tau_s: float) -> bool:
        (k0, k1), (t0, t1), (d0, d1) = self.box
        return k0 <= K <= k1 and t0 <= T_s <= t1 and d0 <= tau_s <= d1

    def _fallback(self, reason: str, healthy: bool) -> Estimate:
        p = self._prior_estimate
        if p.reason == reason and p.healthy == healthy:
            return p
        return Estimate(
            p.K, p.T_s, p.tau_s, p.K_std, p.T_std_s, p.tau_lo_s, p.tau_hi_s, 0.0, healthy, True,
            reason, p.in_box,
        )  # fmt: skip

    def _restart_failing(self) -> None:
        """Restart the models that fail the check or lag far behind the best healthy one."""
        bank, K_pl, T_pl = self._bank, self._K_pl, self._T_pl
        order = self._order
        order.sort(key=lambda m: bank[m].nll)
        donor = next((bank[m] for m in order if bank[m].verdict(K_pl, T_pl) == "ok"), None)
        worst = bank[order[-1]].nll
        for model in bank:
            if model is donor:
                continue
            if donor is None:
                if model.verdict(K_pl, T_pl) != "ok":
                    model.reset(self._y_dev, worst)
            elif model.verdict(K_pl, T_pl) != "ok" or model.nll - donor.nll > self._reseed:
                model.copy_from(donor, donor.nll + 0.5 * self._reseed)

    def _select(self) -> Estimate:
        """Pick the bank's best delay and check its estimate (once per window).

        Failing or far-behind models restart from the best healthy one (from the prior if none);
        when the best one fails, the prior is reported with the reason.
        """
        bank = self._bank
        n = len(bank)
        pen = self._pen
        best = min(range(n), key=lambda m: bank[m].nll + pen[m])
        verdict = bank[best].verdict(self._K_pl, self._T_pl)
        self._restart_failing()
        if verdict != "ok":
            self._rejection = verdict
            return self._fallback(verdict, False)
        model = bank[best]
        if self._rejection and self._learned and model.age < self._min_age:
            return self._fallback(self._rejection, False)  # restarted after a rejection
        self._rejection = ""
        lmin = model.nll + pen[best]
        w, total = self._w, 0.0
        for m in range(n):
            w[m] = math.exp(-0.5 * min(bank[m].nll + pen[m] - lmin, 700.0))
            total += w[m]
        lo_i, hi_i, acc = 0, n - 1, 0.0
        for m in range(n):  # 5 % tails of the posterior weight
            acc += w[m] / total
            if acc < 0.05:
                lo_i = m + 1
        acc = 0.0
        for m in range(n - 1, -1, -1):
            acc += w[m] / total
            if acc < 0.05:
                hi_i = m - 1
        tau = self.delays_s[best] - self._tau_offset
        if 0 < best < n - 1:  # parabola through the three log-likelihoods around the best
            l0, l2 = bank[best - 1].nll + pen[best - 1], bank[best + 1].nll + pen[best + 1]
            curv = l0 - 2.0 * lmin + l2
            if curv > 0.0:
                tau += 0.5 * self.window_s * (l0 - l2) / curv
        a, b, _ = model.theta
        P = model.P
        one_a = 1.0 - a
        K = b / one_a
        la = math.log(a)
        T = -self.window_s / la
        dKa, dKb = K / one_a, 1.0 / one_a
        K_std = math.sqrt(max(dKa * dKa * P[0] + 2.0 * dKa * dKb * P[1] + dKb * dKb * P[3], 0.0))
        T_std = math.sqrt(P[0]) * T / (a * abs(la))
        rel = max(K_std / K / 0.05, T_std / T / 0.1)
        confidence = 1.0 / (1.0 + rel * rel)
        if max(K_std / K, T_std / T) < self._learn:
            self._learned = True
        if not self._learned:
            return self._fallback("learning", True)
        return Estimate(
            K, T, tau, K_std, T_std, self.delays_s[lo_i] - self._tau_offset,
            self.delays_s[max(hi_i, lo_i)] - self._tau_offset, confidence, True, False, "ok",
            self._inside(K, T, tau),
        )  # fmt: skip
