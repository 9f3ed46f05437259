"""A supervisor driven tick by tick with good inputs and a fake controller command (the
supervisor, acknowledgement, monitor-rule and controller-fault tests share it)."""

from __future__ import annotations

import math

from pressor.runtime.core.supervisor import Supervisor, SupervisorInput, SupervisorOutput
from pressor.runtime.core.supervisor_config import SupervisorConfig

#: the loop period (s) the rig ticks at
TS = 0.1
GOOD_MAP = 80.0


def good_inputs(now_s: float) -> dict:
    """Every supervisor input at a good value (no pump status this tick)."""
    return dict(
        now_s=now_s,
        map_mmhg=GOOD_MAP,
        quality=0,
        K=0.55,
        T_s=150.0,
        tau_s=20.0,
        sched_valid=True,
        sample_age_s=0.0,
        link_silence_s=0.0,
        target_mmhg=80.0,
        link_errors=0,
        pump_delivered_ml_h=math.nan,
        pump_alarms=0,
        estimated=False,
        estimate_healthy=True,
        boundary_faults=0,
    )


class Rig:
    """Drives a supervisor with a fake 'controller command' one tick at a time."""

    def __init__(self, cfg: SupervisorConfig | None = None) -> None:
        self.sup = Supervisor(cfg or SupervisorConfig(sample_period_s=TS))
        self.k = 0
        self.out: SupervisorOutput | None = None

    def tick(self, controller_command: float = 30.0, **inputs) -> float:
        """One tick of good inputs except ``inputs``; returns the command (ml/h)."""
        args = good_inputs(self.k * TS)
        args.update(inputs)
        self.k += 1
        run = self.sup.assess(SupervisorInput(**args))
        self.out = self.sup.finalize(controller_command if run else None)
        return self.out.command_ml_h

    def ticks(self, n: int, **kw) -> list[float]:
        return [self.tick(**kw) for _ in range(n)]
