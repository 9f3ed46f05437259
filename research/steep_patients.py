"""The cautious start on steep dose-response patients: a second norepinephrine model, two guards.

The norepinephrine design was tuned and judged on its own patient model
(:mod:`pressor.hil_sim.patients.norepinephrine`: Hill exponents 1.2-1.8, an endogenous level that
starts the curve above zero). :class:`SteepNorepinephrine` is a second one, written apart from it:
the ``pkpd`` model's one-compartment variant (:mod:`pressor.hil_sim.patients.pkpd`, ``draw_patient(...,
"one-compartment")``: one compartment, an effect site, a Hill curve from zero with exponents
1.0-2.5, delays of 10-60 s) dosed with norepinephrine at 16 µg/ml, each µg counted as
:data:`PHENYLEPHRINE_UG_PER_NOREPINEPHRINE_UG` µg of phenylephrine (the norepinephrine-equivalent
dose counts phenylephrine at a tenth: Goradia et al., J Crit Care 2021;61:233; Kotani et al.,
Crit Care 2023;27:29). Its kinetics lie within those published for norepinephrine (clearance
1.5-4 l/min and volume 4-12 l; Beloeil et al., Br J Anaesth 2005: 0.9-3 l/min, 8.8 l), and its
EC50 of 15-80 ng/ml of phenylephrine is 1.5-8 ng/ml of norepinephrine (Joachim et al., Br J Clin
Pharmacol 2024: 2.5 ng/ml ×/÷ 3). ``benchmarks/independent_patients.py --drug norepinephrine``
plays the same patients over the link. :class:`SteepPhenylephrine` doses them with phenylephrine
at 100 µg/ml, for the phenylephrine design.

On a Hill curve that starts from zero the first doses answer far less than the gain near the
target (a patient of exponent 2.5 reads 0.02 mmHg/(ml/h) at 2 ml/h and 1.9 at 19), so the
evidence lowers K̂ below the gain the loop then meets. :class:`GuardedSchedule` adds guards
to the shipped source, to measure what each buys and costs (docs/notes/cautious-start.md, "Steep
patients"):

* ``convexity`` c: the evidence's bound is multiplied by c. A sigmoid Emax curve from zero has a
  local gain of at most n times its average (dE/dC = n·E·(1 − E/Emax)/C ≤ n·E/C), so for Hill
  exponents up to c K̂ stays at or above the patient's local gain wherever the evidence's bound
  holds for its average;
* ``hold_below_best``: K̂ does not fall while the MAP is below its best response so far (by more
  than the margin): a haemorrhage, or the low half of an oscillation, is not read as a less
  sensitive patient;
* ``hill`` n, a dose ceiling ("start low and titrate up", by construction): on a Hill curve from
  zero of exponent at most n, E(c)/c^n does not grow with c, and the effect site of a patient no
  slower than the evidence's slowest holds at least s_slow, so a response Δy now bounds every
  steady state above it, E(u) <= (Δy + m)(u/s_slow)^n (m the margin). The dose that could lift
  the MAP by the step and an ``allowance`` is then u_c = s_slow ((1 + allowance) step/(Δy +
  m))^(1/n), and K̂ is kept from falling below step/u_c, so the law's steady dose step/K̂ stays
  under it. The step here is the scenario's (``step_mmhg``, the sweep's 20 mmHg). Norepinephrine's
  default ships this ceiling at n = 2.5
  (:attr:`~pressor.runtime.estimation.caution.Caution.hill_ceiling`, on the target it is given;
  the same :func:`~pressor.runtime.estimation.caution.dose_ceiling_ml_h`); given here, ``hill``
  replaces it. ``ceiling_T_s`` reads the
  ceiling against a faster patient than the evidence's slowest, ``ceiling_margin`` with a
  smaller margin, and ``ceiling_on`` holds it as a cap on the generated law's command instead
  of (or besides) through K̂ (:func:`install_dose_cap`), to measure what each costs.

Usage (the table of :mod:`research.cautious_levels`, on this source)::

    python -m research.steep_patients --hill 2.5 \\
        --controller lpv:norepinephrine-cautious \\
        --patient-model research.steep_patients:SteepNorepinephrine \\
        --levels 0.5,1,2,10 --patients 20 --seed 3
    python -m research.steep_patients --convexity 2 --hold-below-best \\
        --controller lpv:norepinephrine-cautious \\
        --patient-model research.steep_patients:SteepNorepinephrine \\
        --levels 0.5,1,2,10 --patients 20 --seed 3
"""

from __future__ import annotations

import argparse
import inspect
import math
import sys
import textwrap
from typing import Any

from pressor.contracts.drug import DoseScale
from pressor.hil_sim.patients.pkpd import PkpdPatient
from pressor.runtime.core.scheduling import Schedule, ScheduleInput
from pressor.runtime.estimation import design_envelope
from pressor.runtime.estimation.caution import dose_ceiling_ml_h
from pressor.runtime.estimation.cautious import CautiousSchedule
from pressor.runtime.estimation.design_envelope import DesignEnvelope
from pressor.runtime.estimation.unit_lag import UnitLag
from research import cautious_levels

#: the generated modules (their ``LPV_DESIGNS`` names) :func:`install_dose_cap` gives a dose cap
CAPPED_DESIGNS = ("cautious", "norepinephrine-cautious")
#: the controller the last schedule source was built for (set by :func:`install_dose_cap`'s
#: ``envelope_of``; a trial builds the controller, then its source, one patient at a time)
_LAST_CONTROLLER: list[object] = []


def _capped_step(step: object) -> object:
    """The generated module's float step with its pump maximum read from ``self._dose_cap`` (ml/h)
    in the feedforward's cap, the reference model's shortfall and the anti-windup's upper bound."""
    src = textwrap.dedent(inspect.getsource(step))  # type: ignore[arg-type]
    src = src.replace(
        "cap = _PF_UMAX", "cap = _PF_UMAX if _PF_UMAX < self._dose_cap else self._dose_cap"
    )
    src = src.replace(
        "cap = MAX_RATE_ML_H if need > MAX_RATE_ML_H else need",
        "cap = self._dose_cap if need > self._dose_cap else need",
    )
    src = src.replace("sh = rr - kp * MAX_RATE_ML_H", "sh = rr - kp * self._dose_cap")
    src = src.replace("uhi = _U_MAX_S - uffs", "uhi = self._dose_cap * _INV_U_SCALE - uffs")
    if src.count("self._dose_cap") != 6:
        raise RuntimeError("the generated module's float step changed shape: no dose cap fits it")
    ns: dict[str, object] = {}
    exec(compile(src, "<capped step>", "exec"), step.__globals__, ns)  # type: ignore[attr-defined]
    return ns["_step_float"]


def install_dose_cap() -> None:
    """Give the generated log-K modules' float controllers a per-instance dose cap (``_dose_cap``,
    ml/h, default the pump maximum), run them in Python rather than as their compiled twins, and
    remember each controller a cautious source is built for, in this process and the workers
    forked from it."""
    from pressor.runtime.inputs.controller_loader import LPV_DESIGNS, load_generated_module

    for name in CAPPED_DESIGNS:
        mod = load_generated_module(LPV_DESIGNS[name])
        ctl = mod.Controller
        if "_dose_cap" not in vars(ctl):
            ctl._dose_cap = mod.MAX_RATE_ML_H
            ctl._step_float = _capped_step(ctl._step_float)
    from pressor.hil_sim.trials import trial

    if not hasattr(trial.native_twin, "__wrapped__"):  # the capped step runs in Python
        twin = trial.native_twin

        def native_twin(controller: object) -> object:
            return controller if hasattr(controller, "_dose_cap") else twin(controller)

        native_twin.__wrapped__ = twin  # type: ignore[attr-defined]
        trial.native_twin = native_twin  # type: ignore[assignment]
    shipped = design_envelope.envelope_of

    def envelope_of(controller: object) -> DesignEnvelope:
        _LAST_CONTROLLER[:] = [controller]
        return shipped(controller)

    if not hasattr(design_envelope.envelope_of, "__wrapped__"):
        envelope_of.__wrapped__ = shipped  # type: ignore[attr-defined]
        design_envelope.envelope_of = envelope_of  # type: ignore[assignment]


#: µg of phenylephrine one µg of norepinephrine counts as (module docstring: the sources)
PHENYLEPHRINE_UG_PER_NOREPINEPHRINE_UG = 10.0
#: the norepinephrine syringe (µg/ml): 4 mg in 250 ml, the drug library's standard
NOREPINEPHRINE_UG_ML = 16.0


class SteepNorepinephrine(PkpdPatient):
    """The ``pkpd`` one-compartment variant as a norepinephrine patient (module docstring): a
    :class:`~pressor.hil_sim.patients.patient_model.PatientModel` plugin whose ml/h count a
    16 µg/ml syringe of norepinephrine."""

    DRUG = "norepinephrine"
    DRUG_CONCENTRATION_UG_ML = NOREPINEPHRINE_UG_ML
    #: the patient model counts phenylephrine: 16 µg/ml of norepinephrine is 160 of it
    SYRINGE_UG_ML = NOREPINEPHRINE_UG_ML * PHENYLEPHRINE_UG_PER_NOREPINEPHRINE_UG
    COHORT = "one-compartment"


class SteepPhenylephrine(PkpdPatient):
    """The same patients dosed with phenylephrine at the ``pkpd`` model's 100 µg/ml: the
    phenylephrine design on steep curves."""

    DRUG = "phenylephrine"
    DRUG_CONCENTRATION_UG_ML = PkpdPatient.SYRINGE_UG_ML
    COHORT = "one-compartment"


class _Scaled:
    """The evidence's slowest patient with its answer divided by ``factor`` (the convexity)."""

    def __init__(self, lag: object, factor: float) -> None:
        self.lag, self.factor = lag, factor

    @property
    def response(self) -> float:
        return self.lag.response / self.factor  # type: ignore[attr-defined]

    def step(self, hist: list[float], head: int) -> float:
        return self.lag.step(hist, head) / self.factor  # type: ignore[attr-defined]


class GuardedSchedule(CautiousSchedule):
    """:class:`~pressor.runtime.estimation.cautious.CautiousSchedule` with the guards of the
    module docstring.

    Parameters
    ----------
    envelope, sample_period_s, dose
        As :class:`~pressor.runtime.estimation.cautious.CautiousSchedule`.
    convexity
        The factor (>= 1) on the evidence's bound; 1: none.
    hold_below_best
        Keep K̂ from falling while the MAP is below its best response by more than the margin.
    hill
        The dose ceiling's Hill exponent (>= 1); None: no ceiling.
    step_mmhg
        The target's rise over the first MAP the ceiling sizes its dose for (mmHg).
    allowance
        The rise above the step the ceiling allows, a fraction of the step (0.1: 10 %).
    ceiling_T_s
        The lag (s) of the patient the ceiling is read against; None: the evidence's slowest.
    ceiling_margin
        The margin m (mmHg, >= 0) in the ceiling; None: the evidence's ``margin_mmhg``.
    ceiling_on
        Where the ceiling holds: ``k`` (K̂ kept at or above step/u_c), ``command`` (the
        controller's dose cap, :func:`install_dose_cap`, held at ``cap_factor`` u_c, and no less
        than the allowed rise on the population's top) or ``both``.
    cap_factor
        The dose cap's multiple (>= 1) of the ceiling u_c.
    """

    def __init__(
        self,
        envelope: DesignEnvelope,
        sample_period_s: float = 0.1,
        dose: DoseScale | None = None,
        convexity: float = 1.0,
        hold_below_best: bool = False,
        hill: float | None = None,
        step_mmhg: float = 20.0,
        allowance: float = 0.1,
        ceiling_T_s: float | None = None,
        ceiling_margin: float | None = None,
        ceiling_on: str = "k",
        cap_factor: float = 1.0,
    ) -> None:
        # this ceiling replaces the shipped one (CautiousSchedule's hill_ceiling) when it is given
        super().__init__(envelope, sample_period_s, dose, hill_ceiling=0.0 if hill else None)
        if ceiling_on not in ("k", "command", "both"):
            raise ValueError(f"ceiling_on={ceiling_on!r} must be k, command or both")
        if ceiling_on != "k" and hill is None:
            raise ValueError(f"ceiling_on={ceiling_on!r} needs a ceiling (hill)")
        self._on_k = ceiling_on != "command"
        self._controller = _LAST_CONTROLLER[0] if ceiling_on != "k" else None
        self._cap_floor = 0.0
        if not (math.isfinite(cap_factor) and cap_factor >= 1.0):
            raise ValueError(f"cap_factor={cap_factor!r} must be finite and >= 1")
        self._cap_factor = float(cap_factor)
        if hill is not None and not (math.isfinite(hill) and hill >= 1.0):
            raise ValueError(f"hill={hill!r} must be finite and >= 1")
        if ceiling_margin is not None and not (
            math.isfinite(ceiling_margin) and ceiling_margin >= 0.0
        ):
            raise ValueError(f"ceiling_margin={ceiling_margin!r} mmHg must be finite and >= 0")
        self._hill = hill
        self._ceiling_m = self._m if ceiling_margin is None else float(ceiling_margin)
        self._dr = float(step_mmhg)
        self._allowance = float(allowance)
        if self._controller is not None:
            self._cap_floor = self._dr * (1.0 + allowance) / self.k_top
            self._controller._dose_cap = self._cap_floor  # type: ignore[attr-defined]
        # the ceiling's patient: the evidence's slowest unless a lag is given
        self._ceiling = (
            None
            if ceiling_T_s is None
            else UnitLag(ceiling_T_s, envelope.box[2][1], sample_period_s, self.effect_lag_s)
        )
        if not (math.isfinite(convexity) and convexity >= 1.0):
            raise ValueError(f"convexity={convexity!r} must be finite and >= 1")
        if convexity != 1.0:
            self._slow = _Scaled(self._slow, float(convexity))  # type: ignore[assignment]
        self._hold = bool(hold_below_best)
        self._best = -math.inf

    def update(self, inputs: ScheduleInput) -> Schedule:
        """The shipped tick, then the dose ceiling, then undo a fall of K̂ while the MAP is below
        its best response."""
        before_k, before = self.K, self._schedule
        out = super().update(inputs)
        y = inputs.map_mmhg
        s_ceiling = (
            self._ceiling.step(self._hist, self._head) if self._ceiling is not None else None
        )
        good = y == y and not inputs.quality and self._anchor is not None
        if self._hill is not None and self._on_k and self.K < before_k and good:
            out = self._hold_to_the_ceiling(before_k, y, s_ceiling) or out
        if self._controller is not None and good:
            u_c = self._dose_ceiling(y, s_ceiling)
            cap = self._cap_floor if u_c is None or u_c < self._cap_floor else u_c
            ctl: Any = self._controller
            ctl._dose_cap = min(cap * self._cap_factor, ctl.max_rate_ml_h)
        if not self._hold or self._anchor is None or y != y or inputs.quality:
            return out
        dy = y - self._anchor
        if dy < self._best - self._m and self.K < before_k:
            self.K, self._schedule = before_k, before
            return before
        self._best = max(self._best, dy)
        return out

    def _dose_ceiling(self, y: float, s: float | None) -> float | None:
        """u_c (ml/h) of the module docstring for the MAP ``y`` (mmHg); None before any dose."""
        if s is None:
            s = self._slow.response
        if s <= 0.0:
            return None
        dy = y - self._anchor  # type: ignore[operator]
        inv_n = 1.0 / self._hill  # type: ignore[operator]  # not None: the caller checked
        return dose_ceiling_ml_h(s, self._dr, dy, self._ceiling_m, inv_n, self._allowance)

    def _hold_to_the_ceiling(self, before_k: float, y: float, s: float | None) -> Schedule | None:
        """Keep K̂ at or above step / u_c, u_c the dose ceiling of the module docstring; the new
        schedule if that held K̂ this tick, else None."""
        u_c = self._dose_ceiling(y, s)
        if u_c is None:
            return None
        floor = self._dr / u_c
        if self.K >= floor:
            return None
        self.K = k = min(before_k, floor)
        self._schedule = Schedule(k, self.T_s, self.tau_s, "cautious", True, True, False,
                                  "evidence")  # fmt: skip
        return self._schedule


def main(argv: list[str] | None = None) -> int:
    """The guards' options here (``--convexity``, ``--hill``, ``--allowance``, ``--ceiling-T``,
    ``--ceiling-margin``, ``--hold-below-best``), every other argument
    :mod:`research.cautious_levels`'s."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0], add_help=False)
    p.add_argument("--convexity", type=float, default=1.0, help="factor on the bound (default 1)")
    p.add_argument(
        "--hill", type=float, default=None, help="the dose ceiling's Hill exponent (default: none)"
    )
    p.add_argument(
        "--allowance",
        type=float,
        default=0.1,
        help="the ceiling's allowed rise above the step, a fraction of it (default 0.1)",
    )
    p.add_argument(
        "--ceiling-T",
        type=float,
        default=None,
        help="lag (s) of the ceiling's patient (default: the evidence's slowest)",
    )
    p.add_argument(
        "--hold-below-best",
        action="store_true",
        help="K-hat does not fall while the MAP is below its best response (default: off)",
    )
    p.add_argument(
        "--ceiling-margin",
        type=float,
        default=None,
        help="the ceiling's margin m (mmHg; default: the evidence's, 1)",
    )
    p.add_argument(
        "--ceiling-on",
        choices=("k", "command", "both"),
        default="k",
        help="where the ceiling holds: K-hat, the controller's dose cap, or both (default k)",
    )
    p.add_argument(
        "--cap-factor",
        type=float,
        default=1.0,
        help="the dose cap's multiple of the ceiling, with --ceiling-on command/both (default 1)",
    )
    a, rest = p.parse_known_args(argv)
    if a.ceiling_on != "k":
        install_dose_cap()
    cautious_levels.use_cautious_source(
        GuardedSchedule,
        convexity=a.convexity,
        hold_below_best=a.hold_below_best,
        hill=a.hill,
        allowance=a.allowance,
        ceiling_T_s=a.ceiling_T,
        ceiling_margin=a.ceiling_margin,
        ceiling_on=a.ceiling_on,
        cap_factor=a.cap_factor,
    )
    return cautious_levels.main(rest)


if __name__ == "__main__":
    sys.exit(main())
