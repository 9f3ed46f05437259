"""A user-written controller in a cohort trial, next to the shipped PI baseline.

``ScheduledPI`` is a PI controller re-tuned every tick from the K, T, τ it is given (IMC/lambda
tuning of a first order plus delay: kp = T / (K (λ + τ)), ki = kp / T), clamped to the pump and
with conditional-integration anti-windup. It is a plain class: it satisfies
``pressor.contracts.controller.Controller`` by having the members, nothing to inherit. The same class runs
from the command line, supervised like the shipped controllers::

    pressor trial --controller examples/custom_controller.py:ScheduledPI:lambda_s=60 \\
        --scenario examples/scenario_early_hemorrhage.toml --patients 20 --out out/
    pressor sil --controller examples/custom_controller.py:ScheduledPI --duration 600

Run this file for a trial through the Python API (``python examples/custom_controller.py
--patients 8``); ``--duration-s`` shortens every patient's run.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent


@dataclass
class Status:
    """The flags of the last step (pressor.contracts.controller.ControllerStatus)."""

    saturated: bool = False
    rho_clamped: bool = False
    rho_rate_limited: bool = False


class ScheduledPI:
    """PI on MAP error (mmHg -> ml/h), lambda-tuned from the scheduling K, T, τ at every tick.

    Parameters
    ----------
    sample_period_s
        Loop period (s); the runtime passes it.
    lambda_s
        Desired closed-loop time constant (s), [10, 600].
    max_rate_ml_h
        Pump limit (ml/h); commands are clamped to [0, max_rate_ml_h].
    """

    def __init__(
        self, sample_period_s: float = 0.1, lambda_s: float = 90.0, max_rate_ml_h: float = 120.0
    ) -> None:
        if not 10.0 <= lambda_s <= 600.0:
            raise ValueError(f"lambda_s = {lambda_s!r}: allowed [10, 600] s")
        self.sample_period_s = float(sample_period_s)
        self.lambda_s = float(lambda_s)
        self.max_rate_ml_h = float(max_rate_ml_h)
        self.status = Status()
        self.reset()

    def reset(self) -> None:
        """Zero infusion, empty integrator."""
        self.integral_ml_h = 0.0
        self.last_ml_h = 0.0

    def step(self, map_mmhg: float, target_mmhg: float, K: float, T: float, tau: float) -> float:
        """One tick: the infusion command (ml/h) for MAP ``map_mmhg`` and target ``target_mmhg``
        (mmHg), scheduled on K (mmHg/(ml/h)), T (s) and τ (s)."""
        if not (math.isfinite(map_mmhg) and K > 0.0 and T > 0.0 and tau >= 0.0):
            return self.last_ml_h  # hold on a bad sample or schedule
        kp = T / (K * (self.lambda_s + tau))  # ml/h per mmHg
        error = target_mmhg - map_mmhg
        increment = kp / T * error * self.sample_period_s
        u = kp * error + self.integral_ml_h + increment
        self.status.saturated = not 0.0 <= u <= self.max_rate_ml_h
        if not self.status.saturated:
            self.integral_ml_h += increment
        self.last_ml_h = min(max(u, 0.0), self.max_rate_ml_h)
        return self.last_ml_h


def main(argv: list[str] | None = None) -> None:
    from pressor import api

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--patients", type=int, default=8)
    p.add_argument("--duration-s", type=float, default=None)
    p.add_argument("--jobs", type=int, default=1)
    args = p.parse_args(argv)
    scenario = HERE / "scenario_early_hemorrhage.toml"
    for controller, options in ((ScheduledPI, {"lambda_s": 60.0}), ("pi", None)):
        result = api.trial(
            controller,
            scenario,
            n_patients=args.patients,
            seed=7,
            controller_args=options,
            duration_s=args.duration_s,
            jobs=args.jobs,
        )
        m = result.summary["metrics"]["reachable"]
        print(
            f"{result.controller.rsplit('/', 1)[-1]:<40} median IAE"
            f" {m['iae_mmhg_s']['median']:.4g} mmHg*s, median time in band"
            f" {m['time_in_band_pct']['median']:.4g} %"
        )


if __name__ == "__main__":
    main()
