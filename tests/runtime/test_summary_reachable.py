"""The runtime's ``reachable`` (inferred from the run) is judged against the metrics' band."""

from __future__ import annotations

import numpy as np
import pytest

from pressor.link import LinkCounters
from pressor.runtime.shell.trajectory import LoopResult
from pressor.runtime.summary import build_summary

UMAX = 120.0


def _pinned_run(short_mmhg: float) -> LoopResult:
    """A 20 mmHg target step at 10 s; MAP rises to ``short_mmhg`` below it with the pump at its
    limit for the rest of the run."""
    t = np.arange(0.0, 600.0, 0.1)
    target = np.where(t >= 10.0, 90.0, 70.0)
    rise = np.clip((t - 10.0) / 300.0, 0.0, 1.0)
    map_mmhg = 70.0 + (20.0 - short_mmhg) * rise
    cmd = np.where(t >= 10.0, UMAX, 0.0)
    traj = {
        "sim_time_s": t,
        "map_mmhg": map_mmhg,
        "target_mmhg": target,
        "command_ml_h": cmd,
        "delivered_ml_h": cmd,
    }
    return LoopResult(traj, {}, LinkCounters().as_dict(), {}, {}, [], 0, "completed")


@pytest.mark.parametrize(
    ("short_mmhg", "noisy", "reachable"),
    [
        (4.4, False, False),  # noise-free band: 2 % of 20 = 0.4 mmHg; pinned 4.4 short
        (0.3, False, True),  # inside the 0.4 mmHg band
        (4.4, True, True),  # noisy band 5 mmHg: within it
        (5.6, True, False),
    ],
)
def test_a_run_pinned_at_the_pump_limit_is_unreachable_only_outside_the_metrics_band(
    short_mmhg, noisy, reachable
):
    s = build_summary(_pinned_run(short_mmhg), {}, UMAX, noisy=noisy)
    assert s["metrics"]["reachable"] is reachable
