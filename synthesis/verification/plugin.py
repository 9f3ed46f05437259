"""``pressor verify --controller SPEC``: the nominal step of a plugin controller.

A plugin (``MODULE:CLASS[:ARGS]``, ``FILE.py:CLASS[:ARGS]``, a ``pressor.controllers`` entry
point; :mod:`pressor.runtime.inputs.controller_plugin`) comes without an artifact, so there is nothing to
certify: no analysis LMI, no frozen-parameter delay stability. What can be checked is the
nominal step of docs/DESIGN-CHOICES.md (K = 0.55 mmHg/(ml/h), T = 150 s, τ = 40 s, a +20 mmHg
target step from rest, no noise): the plugin is stepped every Ts against the exact zero-order-hold
plant (:mod:`pressor.synthesis.verification.discrete_step`) from a MAP of :data:`BASELINE_MMHG` (the
``nominal-step`` scenario's), its command clamped to [0, its ``max_rate_ml_h``] as the supervisor
clamps it, and reported beside the PI and the scheduled Smith predictor of the shipped verification
(:func:`pressor.synthesis.verification.verify.verify_artifact`). It passes when the step is stable and
settles inside the 2 % band within the horizon, the rule the shipped design's step is held to; an
exception or a non-finite command fails it.

The caller resolves the spec (``synthesis`` does not import the runtime's loader): the ``pressor``
front door (:mod:`pressor.verify`) passes the loaded controller in.
"""

from __future__ import annotations

from typing import Any

from pressor.contracts.controller import Controller
from pressor.synthesis.verification.discrete_step import StepFailed, discrete_step_response
from pressor.synthesis.verification.step_response import (
    NOMINAL_K,
    NOMINAL_STEP_MMHG,
    NOMINAL_T_S,
    NOMINAL_TAU_S,
    response_metrics,
)
from pressor.synthesis.verification.verify import STEP_HORIZON_S, baseline_steps

__all__ = ["BASELINE_MMHG", "CERTIFICATE_NOT_APPLICABLE", "verify_plugin_step"]

#: the MAP (mmHg) the plugin's step starts from: the nominal-step scenario's baseline (a plugin
#: sees absolute pressures, as it does at the bedside)
BASELINE_MMHG = 60.0
#: what the report says of the certificate
CERTIFICATE_NOT_APPLICABLE = (
    "not applicable (plugin controller): no artifact, so no analysis LMI and no delay-stability"
    " check; only the nominal step is checked"
)


def verify_plugin_step(controller: Controller, spec: str) -> dict[str, Any]:
    """The nominal-step report of the plugin ``controller`` loaded from ``spec`` (JSON-ready).

    Returns
    -------
    dict
        ``passed`` (the step is stable and settles), ``controller`` (``spec``, ``class``,
        ``kind``, ``sample_period_s``, ``max_rate_ml_h``), ``certificate`` (``applicable``
        false, ``text``) and ``nominal_step`` (``rho``, ``step_mmhg``, ``baseline_mmhg``,
        ``horizon_s``, and the metrics of docs/METRICS.md for ``plugin`` - with
        ``commands_clamped`` (ticks), or ``error`` when it raised or returned a non-finite
        command - ``pi`` and ``smith``).
    """
    max_rate = float(controller.max_rate_ml_h)
    try:
        response, clamped = discrete_step_response(
            controller,
            NOMINAL_K,
            NOMINAL_T_S,
            NOMINAL_TAU_S,
            NOMINAL_STEP_MMHG,
            STEP_HORIZON_S,
            baseline_mmhg=BASELINE_MMHG,
        )
    except StepFailed as exc:
        plugin: dict[str, Any] = {"error": str(exc)}
    except Exception as exc:  # the plugin's own error: the check fails, naming it
        plugin = {"error": f"step() raised {exc!r}"}
    else:
        plugin = response_metrics(response, max_rate)
        plugin["commands_clamped"] = clamped
    passed = "error" not in plugin and plugin["settling_time_s"] is not None
    passed = passed and bool(plugin["stable"])
    pi, smith = baseline_steps(max_rate)
    return {
        "passed": passed,
        "controller": {
            "spec": spec,
            "class": type(controller).__qualname__,
            "kind": "plugin",
            "sample_period_s": float(controller.sample_period_s),
            "max_rate_ml_h": max_rate,
        },
        "certificate": {"applicable": False, "text": CERTIFICATE_NOT_APPLICABLE},
        "nominal_step": {
            "rho": [NOMINAL_K, NOMINAL_T_S, NOMINAL_TAU_S],
            "step_mmhg": NOMINAL_STEP_MMHG,
            "baseline_mmhg": BASELINE_MMHG,
            "horizon_s": STEP_HORIZON_S,
            "plugin": plugin,
            "pi": pi,
            "smith": smith,
        },
    }
