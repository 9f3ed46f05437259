"""What a label of :mod:`research.schedule_sources` runs: its controller and scheduling source
(:data:`RUNS`, :func:`make_source`) and the values a schedule on a patient's fit holds
(:func:`scheduled_values`). The labels are listed in that module's docstring.
"""

from __future__ import annotations

from typing import Any

from pressor.runtime.core.scheduling import NominalSchedule
from pressor.runtime.core.supervisor_config import sched_limits_of
from pressor.runtime.estimation.settings import NOMINAL_PLANT
from pressor.runtime.estimation.sources import CAUTION_SIGMA, SOURCES, make_schedule
from pressor.runtime.estimation.validated import ValidatedSchedule
from pressor.runtime.estimation.validation import ModelBank
from research.fit_schedules import KHandover, SecantK, clamped
from research.schedule_experiments import (
    BatchFit,
    GatedFit,
    LimitedFit,
    OnsetSwitch,
    wide_estimate,
)
from research.step_fit import (
    PUMP_MAX_ML_H,
    apparent_fopdt,
    incremental_gain,
    step_response_fit,
)
from research.step_fit import STEP_S as TS_S

#: the monitor's Gaussian noise in the harness and in a realistic device's fit (mmHg)
NOISE_MMHG = 0.3
#: label -> (controller spec, schedule source)
RUNS = {
    "lpv-nominal": ("lpv", "nominal"),
    "lpv-validated": ("lpv", "validated"),
    "lpv-estimated": ("lpv", "estimated"),
    "lpv-fit-hold": ("lpv", "fit-hold"),
    "lpv-fit-slew": ("lpv", "fit-slew"),
    "lpv-truth": ("lpv", "truth"),
    "lpv-stepfit": ("lpv", "stepfit"),
    "lpv-stepfit-inc": ("lpv", "stepfit-inc"),
    # held-out-validated fit (GatedFit): decided early on a T-100-ish start, or late from nominal
    "lpv-gate-early": ("lpv", "gate:start=1:H=4:L=4:min=4:zero=0.5:s0=0.55/120/40:latch=1:H2=60"),
    "lpv-gate-late": ("lpv", "gate:H=4:L=4:min=4:zero=0.5"),
    # the same, and an adopted fit revoked for good when its 60 s changes, fully held out, do
    # not beat the nominal model's; and the early decision from a K-only cautious start
    "lpv-gate-revoke": ("lpv", "gate:H=4:L=4:min=4:zero=0.5:H2=60"),
    "lpv-gate-kstart": ("lpv", "gate:start=1:H=4:L=4:min=4:zero=0.5:s0=0.65/150/40:latch=1:H2=60"),
    "pi": ("pi", "nominal"),
    "smith": ("smith", "estimated"),
    "smith-validated": ("smith", "validated"),
}
#: the prefixes of labels that carry their source's settings (``lpv-batchfit:decide=300``)
PARAMETRISED = (
    "lpv-gate:",
    "lpv-batchfit",
    "lpv-estwide",
    "lpv-stepfit-twok",
    "lpv-stepfit-device",
    "lpv-stepfit-secant",
    "lpv-onset",
)
#: the labels run when ``--runs`` is not given (the others are experiments)
DEFAULT_RUNS = ("lpv-nominal", "lpv-estimated", "lpv-validated", "pi", "smith", "smith-validated")


#: keyword arguments of the ``validated`` source and of its bank (``--sched``, ``--bank``)
VARIANT: dict[str, dict[str, Any]] = {"sched": {}, "bank": {}}


def options(source: str) -> dict[str, str]:
    """The ``key=value`` items after a source name's first ``:`` (``batchfit:decide=180``)."""
    return dict(item.partition("=")[::2] for item in source.split(":")[1:])


def make_source(source: str, controller: Any = None, truth: tuple[float, ...] = ()) -> Any:
    """The scheduling source ``source``: a name of ``make_schedule``, ``fixed:K/T/tau``,
    ``truth``, ``stepfit`` or ``stepfit-inc`` (the patient's ``truth`` K, T, τ clamped to
    ``controller``'s box), or an experiment (``stepfit-twok:...``, ``fit-hold``, ``fit-slew``,
    ``batchfit:...``, ``estwide:...``, ``gate...``; module docstring)."""
    if source.startswith("stepfit-secant"):
        kw = options(source)
        box = sched_limits_of(controller)[0]
        return SecantK(box, truth[:3], truth[3], float(kw.get("rate", "5e-5")), TS_S)
    if source.startswith("stepfit-twok"):
        kw = options(source)
        box = sched_limits_of(controller)[0]
        switch, rate = float(kw.get("switch", "600")), float(kw.get("rate", "5e-4"))
        return KHandover(box, truth, switch, rate, TS_S)
    if source.startswith(("fixed:", "stepfit-device")) or source in (
        "truth",
        "stepfit",
        "stepfit-inc",
    ):
        if not source.startswith("fixed:"):
            return NominalSchedule(*clamped(truth, sched_limits_of(controller)[0]))
        return NominalSchedule(*(float(v) for v in source[6:].split("/")))
    if source.startswith("onset"):
        kw = options(source)
        short = kw.get("short", "0.55/150/40")
        first = (make_schedule(short, TS_S) if short in SOURCES
                 else NominalSchedule(*(float(v) for v in short.split("/"))))  # fmt: skip
        long = tuple(float(v) for v in kw.get("long", "0.55/200/80").split("/"))
        start = tuple(float(v) for v in kw["start"].split("/")) if "start" in kw else None
        by, rise = float(kw.get("by", "48")), float(kw.get("rise", "2"))
        return OnsetSwitch(first, long, by, rise, TS_S, start)
    if source in ("fit-hold", "fit-slew"):
        return LimitedFit(source == "fit-hold", TS_S)
    if source.startswith(("batchfit", "estwide")):
        kw = options(source)
        box = sched_limits_of(controller)[0]
        start = tuple(float(v) for v in kw.get("start", "0.55/150/40").split("/"))
        if source.startswith("batchfit"):
            return BatchFit(box, start, float(kw.get("decide", "180")), TS_S)
        tau_prior = tuple(float(v) for v in kw.get("tau_prior", "40/20").split("/"))
        caution = float(kw.get("caution", CAUTION_SIGMA))
        return wide_estimate(box, start, tau_prior, caution, TS_S)
    if source.startswith("gate"):
        opts = options(source)
        return GatedFit(
            TS_S, **{k: v if k in ("drop", "s0") else float(v) for k, v in opts.items()}
        )
    if source == "validated" and (VARIANT["sched"] or VARIANT["bank"]):
        kw = dict(VARIANT["sched"])
        start = kw.get("start", (0.55, 150.0, 40.0))
        bank = ModelBank(2.0, round(2.0 / TS_S), start, **VARIANT["bank"])
        return ValidatedSchedule(sample_period_s=TS_S, bank=bank, **kw)
    return make_schedule(source, TS_S)


def scheduled_values(
    source: str, params: Any, target_mmhg: float, seed: int = 0
) -> tuple[float, ...]:
    """The values a ``truth``, ``stepfit``, ``stepfit-inc``, ``stepfit-twok`` or
    ``stepfit-device`` run schedules on (K, T, τ; ``stepfit-twok`` also the incremental K); () for
    any other source. ``seed`` draws ``stepfit-device``'s monitor noise."""
    if source == "truth":
        return apparent_fopdt(params, target_mmhg)
    if source.startswith(("stepfit-device", "stepfit-secant")):
        # a realistic device: the nominal patient's rate for the step, a noisy monitor
        kw = options(source)
        rate = (target_mmhg - params.baseline_mmhg) / float(kw.get("k", str(NOMINAL_PLANT[0])))
        rate = min(max(rate, 1.0), PUMP_MAX_ML_H)
        fit = step_response_fit(params, target_mmhg, rate_ml_h=rate, noise_mmhg=NOISE_MMHG,
                                seed=seed)  # fmt: skip
        return fit if source.startswith("stepfit-device") else (*fit, target_mmhg)
    if source.startswith("stepfit"):
        fit = step_response_fit(params, target_mmhg)
        if source == "stepfit":
            return fit
        k_inc = incremental_gain(params, target_mmhg)
        return (k_inc, *fit[1:]) if source == "stepfit-inc" else (*fit, k_inc)
    return ()
