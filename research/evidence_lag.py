"""What knowing the patient's lag would buy the cautious start: the ceiling of any lag estimator.

The cautious source (:mod:`pressor.runtime.estimation.cautious`) reads the MAP's response against
the box's slowest patient (its longest T and τ, behind them the drug's effect site): K̂ falls only
to the largest sensitivity that patient is compatible with, which for a faster patient is above
its own, so the law closes the last part of the step on a K̂ up to twice the patient's. This
research source reads the same evidence against the patient's *own* T and τ, as the simulated
device sends them (the simulator's truth: a bedside device has no such values), and can keep the
drug's effect site behind them. It is the best any estimator of the lag could do with that
evidence, so its time to the target is the frontier of the cautious start's: measured in
docs/notes/cautious-start.md, "What knowing the lag would buy".

Usage (the table of :mod:`research.cautious_levels`, on this source)::

    python -m research.evidence_lag --effect-site keep --controller lpv:cautious \\
        --patient-model pkpd --levels 0.5,1,2,10 --patients 10 --seed 3
    python -m research.evidence_lag --effect-site 60 --controller lpv:norepinephrine-cautious \\
        --patient-model norepinephrine --levels 0.5,1,2,10 --patients 10 --seed 3

``--effect-site`` is ``none`` (the patient's first-order lag alone), ``keep`` (the drug's effect
site of :data:`~pressor.runtime.estimation.caution.CAUTION_FOR_DRUG` behind it, if it names one)
or a lag in s. ``--lag SECONDS`` reads the evidence against a slowest patient of that T (and the
box's longest τ) instead of the patient's own: how much of the box's lag range the evidence must
cover::

    python -m research.evidence_lag --lag 550 --controller lpv:norepinephrine-cautious \
        --patient-model norepinephrine --levels 0.5,1,2,10 --patients 10 --seed 3
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable

from pressor.contracts.drug import DoseScale
from pressor.runtime.core.scheduling import Schedule, ScheduleInput
from pressor.runtime.estimation.cautious import CautiousSchedule
from pressor.runtime.estimation.design_envelope import DesignEnvelope
from pressor.runtime.estimation.unit_lag import UnitLag
from research import cautious_levels

#: the longest delay (s) the source can read the rate history back by (the shipped models' are
#: at most a few minutes)
MAX_DELAY_S = 600.0


class KnownLagSchedule(CautiousSchedule):
    """:class:`~pressor.runtime.estimation.cautious.CautiousSchedule` whose evidence reads the
    device's T and τ (s), or a slowest patient of a given lag, instead of the box's slowest and
    fastest patients.

    Parameters
    ----------
    envelope, sample_period_s, dose
        As :class:`~pressor.runtime.estimation.cautious.CautiousSchedule`.
    effect_lag_s
        A lag (s, > 0) behind the patient's own (an effect site); ``None``: none. Default: the
        drug's effect site (:data:`~pressor.runtime.estimation.caution.CAUTION_FOR_DRUG`).
    lag_T_s
        ``None`` (default): the device's T and τ. A lag (s, > 0): the evidence's slowest patient
        has this T (and the box's longest τ) in place of the box's longest T; the fastest stays
        the box's, and the device's values are not read.

    Until the device sends finite T and τ the evidence stays the box's. When they change the
    lags are retuned in place, keeping their state (the paper model's T and τ move slowly with
    the infusion; the PK/PD models' do not move).
    """

    def __init__(
        self,
        envelope: DesignEnvelope,
        sample_period_s: float = 0.1,
        dose: DoseScale | None = None,
        effect_lag_s: float | None | str = "drug",
        lag_T_s: float | None = None,
    ) -> None:
        super().__init__(envelope, sample_period_s, dose)
        lag2 = self.effect_lag_s if effect_lag_s == "drug" else effect_lag_s
        for name, value in (("effect_lag_s", lag2), ("lag_T_s", lag_T_s)):
            if value is not None and not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name}={value!r} must be finite and > 0 (s), or None")
        self._ts = float(sample_period_s)
        self._hist = [0.0] * (int(math.ceil(MAX_DELAY_S / self._ts)) + 3)
        self._lag2 = lag2
        self._device: tuple[float, float] | None = None
        self._fixed = lag_T_s is not None
        if lag_T_s is not None:
            self._retune(self._slow, lag_T_s, envelope.box[2][1], lag2)

    def _retune(self, lag: object, T_s: float, tau_s: float, lag2_s: float | None) -> None:
        fresh = UnitLag(T_s, min(tau_s, MAX_DELAY_S), self._ts, lag2_s)
        for name in ("a", "b", "k", "f", "a2", "b2"):
            setattr(lag, name, getattr(fresh, name))

    def update(self, inputs: ScheduleInput) -> Schedule:
        """Retune the evidence's lags to the device's T and τ, then the cautious source's tick."""
        T_s, tau_s = inputs.device_T_s, inputs.device_tau_s
        if (
            not self._fixed
            and math.isfinite(T_s)
            and math.isfinite(tau_s)
            and T_s > 0.0
            and tau_s >= 0.0
            and (T_s, tau_s) != self._device
        ):
            self._device = (T_s, tau_s)
            self._retune(self._slow, T_s, tau_s, self._lag2)
            self._retune(self._fast, T_s, tau_s, None)
        return super().update(inputs)


def _seconds_or(words: dict[str, object], flag: str) -> Callable[[str], object]:
    """An argparse type: one of ``words`` (mapped to its value) or a positive number of s."""

    def parse(text: str) -> object:
        if text in words:
            return words[text]
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0.0):
            allowed = " or ".join(f"'{w}'" for w in words)
            raise argparse.ArgumentTypeError(
                f"{flag} {text!r}: allowed {allowed} or a lag in s (> 0)"
            )
        return value

    return parse


_lag = _seconds_or({"device": None}, "--lag")
_effect_site = _seconds_or({"none": None, "keep": "drug"}, "--effect-site")


def main(argv: list[str] | None = None) -> int:
    """``--effect-site`` here, every other argument :mod:`research.cautious_levels`'s."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0], add_help=False)
    p.add_argument(
        "--effect-site",
        type=_effect_site,
        default="drug",
        help="behind the patient's lag: 'none', 'keep' (the drug's effect site; default) or s",
    )
    p.add_argument(
        "--lag",
        type=_lag,
        default=None,
        help="the evidence's lag: 'device' (the patient's T and tau; default) or the slowest"
        " patient's T in s",
    )
    a, rest = p.parse_known_args(argv)
    cautious_levels.use_cautious_source(KnownLagSchedule, effect_lag_s=a.effect_site, lag_T_s=a.lag)
    return cautious_levels.main(rest)


if __name__ == "__main__":
    sys.exit(main())
