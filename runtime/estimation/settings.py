"""The online estimator's tuning, one immutable value checked once when it is made.

:class:`EstimatorSettings` holds everything :class:`pressor.runtime.estimation.estimator.DelayBankEstimator`
can be tuned by; the estimator itself takes only the settings, the loop's tick period and the
sample gate (which are the loop's, not the estimator's). What each setting does to the fit: the
estimator's module docstring; the tuning evidence: ``docs/notes/estimation.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

from pressor.baselines.smith import INITIAL_SCHEDULE
from pressor.contracts.checks import check_range
from pressor.runtime.generated import lpv_map_controller as shipped

__all__ = [
    "DEFAULT_SETTINGS",
    "DESIGN_BOX",
    "DESIGN_RATES",
    "ESTIMATE_BOX",
    "NOMINAL_PLANT",
    "T_DRIFT_PER_ML_H",
    "EstimatorSettings",
]

#: the prior: the nominal patient the design and the PI were tuned for (K mmHg/(ml/h), T s, τ s)
NOMINAL_PLANT: tuple[float, float, float] = INITIAL_SCHEDULE
#: the shipped design's certified box, (low, high) of K (mmHg/(ml/h)), T (s), τ (s), and rate
#: bounds (K mmHg/(ml/h) per s, T s per s, τ s per s), read from its generated module (as
#: pressor.runtime.core.supervisor_config.sched_limits_of does for any controller; estimation stays free
#: of that module's numpy)
DESIGN_BOX: tuple[tuple[float, float], ...] = tuple(
    (float(lo), float(hi)) for lo, hi in zip(shipped.GRID_LO, shipped.GRID_HI, strict=True)
)
DESIGN_RATES: tuple[float, float, float] = tuple(float(r) for r in shipped.RATE_BOUNDS)  # type: ignore[assignment]
#: the estimator's range (the default ``EstimatorSettings.box``): (low, high) of K (mmHg/(ml/h)),
#: T (s), τ (s). Its estimates' ``in_box`` and the estimated source's caution (which stops at its K
#: high and T low edges) refer to it; it clamps nothing (the controller clamps to its box). It is
#: the box the estimator was tuned in, narrower in K and T than the certified box: widened to it,
#: the estimated schedule measured worse on both independent models (docs/notes/estimation.md, "The
#: estimator's range and the certified box").
ESTIMATE_BOX: tuple[tuple[float, float], ...] = ((0.25, 1.0), (100.0, 200.0), (10.0, 45.0))
#: the T-drift prior: T rises this many s per (ml/h)·s of infusion (the literature patient model's
#: b_T, middle of its [1e-4, 3e-4] range; hil_sim/patients/patient.py)
T_DRIFT_PER_ML_H = 2e-4


@dataclass(frozen=True, slots=True)
class EstimatorSettings:
    """The tuning of the delay-bank estimator (immutable; checked in :meth:`__post_init__`).

    Attributes
    ----------
    window_s
        Averaging window (s), > 0; the estimator also needs it to be a whole number (>= 2) of its
        tick period.
    tau_range_s
        (low, high) of the delay bank (s), 0 < low < high; members every ``window_s`` from low.
    prior
        (K mmHg/(ml/h), T s, τ s), each > 0: reported until learned and on a rejected estimate.
    prior_rel_std
        Relative standard deviation of the prior's K and T (1), > 0.
    q_a, q_b, q_c
        Random-walk standard deviations per window of a (1), b (mmHg/(ml/h)) and c (mmHg), > 0.
    r_mmhg
        Floor of the standard deviation of a window's output error (mmHg), > 0; the filters use
        the larger monitor noise the window means show.
    jump_sigma
        Innovation (standard deviations) above which it is taken as a baseline jump, > 0.
    baseline_std_mmhg
        Standard deviation of the baseline offset at a (re)start (mmHg), > 0.
    reseed_nll
        Log-likelihood lag behind the best model at which a model restarts from it (1), > 0.
    min_age_s
        Data (s) a model needs after a restart from the prior before it is reported, >= 0.
    memory_s
        Memory of the delay selection's log-likelihoods (s), finite and > ``window_s``.
    learn_rel_std
        K and T relative standard deviations (1) below which the estimate is reported, > 0.
    tau_prior_s
        (mode s, standard deviation s), each > 0: the Gaussian prior on τ weighing the bank's
        log-likelihoods.
    K_plausible
        Plausible (low, high) of K (mmHg/(ml/h)), 0 < low < high; outside, the estimate is
        rejected.
    T_plausible_s
        Plausible (low, high) of T (s), 0 < low < high; outside, the estimate is rejected.
    box
        The estimator's range ((K low, high) mmHg/(ml/h), (T low, high) s, (τ low, high) s), each
        0 < low < high, for the estimate's ``in_box`` (default :data:`ESTIMATE_BOX`, inside the
        certified :data:`DESIGN_BOX`).
    T_drift_per_ml_h
        The T-drift prior: s of T per (ml/h)·s of delivered infusion, finite and >= 0 (0: off).

    Raises
    ------
    ValueError
        When a setting is outside its range; the message names the setting, its value and the
        allowed range.
    """

    window_s: float = 2.0
    tau_range_s: tuple[float, float] = (10.0, 46.0)
    prior: tuple[float, float, float] = NOMINAL_PLANT
    prior_rel_std: float = 0.6
    q_a: float = 2e-5
    q_b: float = 2e-5
    q_c: float = 0.1
    r_mmhg: float = 0.05
    jump_sigma: float = 4.0
    baseline_std_mmhg: float = 2.0
    reseed_nll: float = 100.0
    min_age_s: float = 300.0
    memory_s: float = 200.0
    learn_rel_std: float = 0.5
    tau_prior_s: tuple[float, float] = (15.0, 10.0)
    K_plausible: tuple[float, float] = (0.02, 5.0)
    T_plausible_s: tuple[float, float] = (20.0, 1000.0)
    box: tuple[tuple[float, float], ...] = ESTIMATE_BOX
    T_drift_per_ml_h: float = T_DRIFT_PER_ML_H

    def __post_init__(self) -> None:
        """Check every setting against its range (see the class docstring)."""
        for name, unit in _POSITIVE:
            check_range(name, getattr(self, name), 0.0, lo_open=True, unit=unit)
        check_range("T_drift_per_ml_h", self.T_drift_per_ml_h, 0.0, unit="s per (ml/h)·s")
        check_range("min_age_s", self.min_age_s, 0.0, unit="s")
        check_range("memory_s", self.memory_s, self.window_s, lo_open=True, unit="s")
        _check_interval("tau_range_s", self.tau_range_s, "s")
        if len(self.tau_prior_s) != 2:
            raise ValueError(f"tau_prior_s={self.tau_prior_s!r} must be (mode s, std s)")
        check_range("tau_prior_mode_s", self.tau_prior_s[0], 0.0, lo_open=True, unit="s")
        check_range("tau_prior_std_s", self.tau_prior_s[1], 0.0, lo_open=True, unit="s")
        _check_interval("K_plausible", self.K_plausible, "mmHg/(ml/h)")
        _check_interval("T_plausible_s", self.T_plausible_s, "s")
        if len(self.prior) != 3:
            raise ValueError(f"prior={self.prior!r} must be (K, T_s, tau_s)")
        for name, value, unit in zip(_PRIOR, self.prior, _UNITS, strict=True):
            check_range(name, value, 0.0, lo_open=True, unit=unit)
        if len(self.box) != 3:
            raise ValueError(f"box={self.box!r} must be ((K lo, hi), (T lo, hi), (tau lo, hi))")
        for name, pair, unit in zip(
            ("box K", "box T_s", "box tau_s"), self.box, _UNITS, strict=True
        ):
            _check_interval(name, pair, unit)


#: the settings that must be > 0, with their units ("" for a pure number)
_POSITIVE = (
    ("window_s", "s"),
    ("prior_rel_std", ""),
    ("q_a", ""),
    ("q_b", "mmHg/(ml/h)"),
    ("q_c", "mmHg"),
    ("r_mmhg", "mmHg"),
    ("jump_sigma", ""),
    ("baseline_std_mmhg", "mmHg"),
    ("reseed_nll", ""),
    ("learn_rel_std", ""),
)
_PRIOR = ("prior_K", "prior_T_s", "prior_tau_s")
_UNITS = ("mmHg/(ml/h)", "s", "s")


def _check_interval(name: str, pair: tuple[float, float], unit: str) -> None:
    """``pair`` = (low, high) with 0 < low < high, both finite; ValueError naming the end."""
    lo = check_range(f"{name} low", pair[0], 0.0, lo_open=True, unit=unit)
    check_range(f"{name} high", pair[1], lo, lo_open=True, unit=unit)


#: the shipped tuning (every default above); one shared value, since settings are immutable
DEFAULT_SETTINGS = EstimatorSettings()
