"""The estimated scheduling source, and every source by name.

:class:`EstimatedSchedule`
    The online estimator (:class:`pressor.runtime.estimation.estimator.DelayBankEstimator`); always valid:
    it reports the prior until it has learned and whenever its health check rejects an estimate,
    with ``healthy`` and ``reason`` saying so. K and T are scheduled *cautiously*: on the low-gain
    side of the estimate's credible region (higher K, shorter T: the feedforward expects a faster,
    stronger response and stops pushing sooner), by a shift that shrinks as the estimate's
    relative standard deviation falls (:meth:`EstimatedSchedule.cautious`). On the prior (σ 60 %)
    the shift is 0.75 σ: K 0.80, T 100 s (the box's low edge), τ the prior's 40 s, so the start-up
    step does not overshoot a sensitive patient; once learned (σ_K ≈ 2–5 %, σ_T ≈ 5–10 %) it is
    at most 0.06 σ_K and 0.13 σ_T. A T below the design box is then projected onto the box's low
    edge at the same K/T (:meth:`EstimatedSchedule.keep_slope`). Tuned on cohort seed 11
    (``docs/notes/estimation.md``; the held-out figures are in ``docs/notes/cohort-evidence.md``).
:func:`make_schedule`
    The source named by ``--schedule``: oracle and nominal from :mod:`pressor.runtime.core.scheduling`
    (the protocol, :class:`~pressor.runtime.core.scheduling.Schedule`), estimated from here, validated
    from :mod:`pressor.runtime.estimation.validated`, cautious (the population's most sensitive patient
    first, lowered on evidence) from :mod:`pressor.runtime.estimation.cautious`.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from pressor.runtime.core.estimate import Estimate
from pressor.runtime.core.scheduling import (
    NominalSchedule,
    OracleSchedule,
    Schedule,
    ScheduleInput,
    ScheduleSource,
)

if TYPE_CHECKING:  # the estimator's settings load the shipped design (~0.7 MB): not for --help
    from pressor.contracts.drug import DoseScale
    from pressor.runtime.estimation.estimator import DelayBankEstimator
    from pressor.runtime.estimation.settings import EstimatorSettings

SOURCES = ("oracle", "estimated", "nominal", "validated", "cautious")
#: the cautious rule's full shift (standard deviations) and the relative standard deviation from
#: which it applies in full (below, the shift shrinks in proportion): tuned on cohort seed 11
CAUTION_SIGMA = 0.75
CAUTION_REL_STD = 0.6


class EstimatedSchedule:
    """Schedule on the online estimate, cautiously; the device's values are ignored.

    Parameters
    ----------
    estimator
        The estimator to feed (default: :class:`DelayBankEstimator` at ``sample_period_s``).
    sample_period_s
        Tick period (s), > 0; used only to build the default estimator.
    caution_sigma
        Largest shift of K up and T down, in standard deviations, >= 0 (0: the estimate as is).
    caution_rel_std
        Relative standard deviation from which the full shift applies, > 0 (below, the shift
        shrinks in proportion to it).
    keep_slope
        Project a T below the design box onto the box's low edge at the same K/T (default); False
        leaves K as is and the controller clamps T alone (the ablation).
    """

    source = "estimated"

    def __init__(
        self,
        estimator: DelayBankEstimator | None = None,
        sample_period_s: float = 0.1,
        caution_sigma: float = CAUTION_SIGMA,
        caution_rel_std: float = CAUTION_REL_STD,
        keep_slope: bool = True,
    ) -> None:
        for name, value in (("caution_sigma", caution_sigma), ("caution_rel_std", caution_rel_std)):
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name}={value!r} must be finite and >= 0")
        if caution_rel_std == 0.0 and caution_sigma > 0.0:
            raise ValueError("caution_rel_std must be > 0 when caution_sigma > 0")
        if estimator is None:
            from pressor.runtime.estimation.estimator import DelayBankEstimator

            estimator = DelayBankEstimator(sample_period_s)
        self.estimator = estimator
        self._z = float(caution_sigma)
        self._z_per_rel = self._z / caution_rel_std if caution_sigma > 0.0 else 0.0
        (_, self._K_hi), (self._T_lo, _), _ = self.estimator.box
        self._keep_slope = bool(keep_slope)
        self._last: Estimate | None = None
        self._schedule: Schedule | None = None

    def cautious(self, est: Estimate) -> tuple[float, float]:
        """The (K mmHg/(ml/h), T s) to schedule on for ``est``: the low-gain side of its credible
        region, K̂ + z_K·σ_K and T̂ − z_T·σ_T, with z_X = ``caution_sigma`` · min(1, (σ_X/X̂) /
        ``caution_rel_std``), never moved beyond the design box's K high / T low edge."""
        z, zr = self._z, self._z_per_rel
        zk = min(z, zr * est.K_std / est.K)
        zt = min(z, zr * est.T_std_s / est.T_s)
        K = min(est.K + zk * est.K_std, max(est.K, self._K_hi))
        T = max(est.T_s - zt * est.T_std_s, min(est.T_s, self._T_lo))
        return K, T

    def keep_slope(self, K: float, T_s: float) -> tuple[float, float]:
        """(K mmHg/(ml/h), T s) with a T below the design box's low edge T_lo moved onto it at the
        same K/T: (K·T_lo/T, T_lo); within the box, unchanged.

        The first minute of data identifies the response's initial slope K/T, not K and T apart
        (a fast, weak plant and a slow, strong one rise alike at first), and an early fit often
        lands at a T below the box with K low by the same factor. The controller clamps T to the
        box; scheduling it on that low K as well makes it push as if the patient were T_lo/T
        times less sensitive than the data say: too hard, into the pump's limit and an overshoot.
        Moving along the line of constant K/T keeps what the data say and gives the smallest K a
        patient with T ≥ T_lo can have: always towards the low-gain side. Cohort seed 11: step
        overshoot 9.9 % → 6.4 % (45 patients), IAE unchanged; bedside monitor IAE ÷ oracle
        1.67 → 1.54 (``docs/notes/estimation.md``).
        """
        if self._keep_slope and T_s < self._T_lo:
            return K * self._T_lo / T_s, self._T_lo
        return K, T_s

    def update(self, inputs: ScheduleInput) -> Schedule:
        """Feed the estimator one tick and schedule on its report."""
        est = self.estimator.update(inputs.map_mmhg, inputs.quality, inputs.delivered_ml_h)
        if est is not self._last or self._schedule is None:
            self._last = est
            K, T = self.keep_slope(*self.cautious(est))
            self._schedule = Schedule(K, T, est.tau_s, "estimated", True, est.healthy,
                                      est.from_prior, est.reason, est)  # fmt: skip
        return self._schedule


def _design_of(controller: object | None) -> tuple[Any, Any] | None:
    """The box and rates ``controller`` declares when they are not the shipped phenylephrine
    design's (whose sources keep their tuned defaults), else None."""
    if controller is None:
        return None
    from pressor.runtime.core.supervisor_config import sched_limits_of
    from pressor.runtime.estimation.settings import DESIGN_BOX, DESIGN_RATES

    box, rates = sched_limits_of(controller)  # type: ignore[arg-type]
    if box is None or rates is None:
        return None
    if tuple(box) == tuple(DESIGN_BOX) and tuple(rates) == tuple(DESIGN_RATES):
        return None
    return box, rates


def settings_for_box(box: Any) -> EstimatorSettings:
    """The estimator's settings for a design whose box is ``box`` (((K lo, hi) mmHg/(ml/h), (T lo,
    hi) s, (τ lo, hi) s)): the prior at the box's geometric-mean K and T and its delay range's
    lower end + 5 s (the shipped prior's place in its box, τ 15 s in 10-45 s), the plausible K
    within 5x of the box, the delay bank and the caution's edges on the box, no T drift (the
    paper model's law is phenylephrine's). The shipped phenylephrine design keeps
    :data:`pressor.runtime.estimation.settings.DEFAULT_SETTINGS`."""
    from pressor.runtime.estimation.settings import DEFAULT_SETTINGS

    (k_lo, k_hi), (t_lo, t_hi), (d_lo, d_hi) = ((float(a), float(b)) for a, b in box)
    base = DEFAULT_SETTINGS
    return replace(
        base,
        prior=(math.sqrt(k_lo * k_hi), math.sqrt(t_lo * t_hi), d_lo + 5.0),
        tau_range_s=(d_lo, d_hi + 1.0),
        tau_prior_s=(d_lo + 5.0, base.tau_prior_s[1]),
        K_plausible=(k_lo / 5.0, k_hi * 5.0),
        T_plausible_s=(
            min(base.T_plausible_s[0], t_lo / 5.0),
            max(base.T_plausible_s[1], 2.5 * t_hi),
        ),
        box=((k_lo, k_hi), (t_lo, t_hi), (d_lo, d_hi)),
        T_drift_per_ml_h=0.0,
    )


def make_schedule(
    source: str,
    sample_period_s: float = 0.1,
    controller: object | None = None,
    dose: DoseScale | None = None,
) -> ScheduleSource:
    """The scheduling source named ``source`` (one of :data:`SOURCES`) at ``sample_period_s`` (s).

    ``controller`` is the controller the source schedules: ``cautious`` reads its design (box,
    certified ln K rates, patient population:
    :func:`pressor.runtime.estimation.design_envelope.envelope_of`;
    required); ``estimated`` and ``validated`` take its box and rates when they are not the
    shipped phenylephrine design's (:func:`settings_for_box`: another drug's design schedules
    inside its own box, not phenylephrine's); ``dose`` the syringe and patient to convert the
    population's doses with (default: the design's syringe and the reference adult).
    """
    if source == "oracle":
        return OracleSchedule()
    if source == "nominal":
        return NominalSchedule()
    design = _design_of(controller)
    if source == "estimated":
        if design is None:
            return EstimatedSchedule(sample_period_s=sample_period_s)
        from pressor.runtime.estimation.estimator import DelayBankEstimator

        settings = settings_for_box(design[0])
        est = DelayBankEstimator(sample_period_s, settings)
        return EstimatedSchedule(est, sample_period_s)
    if source == "validated":
        # imported here: only this opt-in source needs the model bank and the generated module
        from pressor.runtime.estimation.estimator import DelayBankEstimator
        from pressor.runtime.estimation.validated import ValidatedSchedule

        if design is None:
            return ValidatedSchedule(sample_period_s=sample_period_s)
        box, rates = design
        settings = settings_for_box(box)
        est = DelayBankEstimator(sample_period_s, settings)
        return ValidatedSchedule(
            est, sample_period_s, start=settings.prior, box=box, rate_bounds=rates
        )
    if source == "cautious":
        from pressor.runtime.estimation.cautious import CautiousSchedule
        from pressor.runtime.estimation.design_envelope import envelope_of

        if controller is None:
            raise ValueError("--schedule cautious needs the controller it schedules (its design)")
        return CautiousSchedule(envelope_of(controller), sample_period_s, dose)
    raise ValueError(f"schedule source {source!r} not one of {SOURCES}")
