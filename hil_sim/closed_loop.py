"""Pure in-process closed-loop simulator: World + controller, ticked in lockstep, no I/O.

Per tick k: ``obs = world.observe()`` → ``u = controller.step(obs.map_mmhg, obs.target_mmhg, obs.K,
obs.T_s, obs.tau_s)`` → ``world.apply_command(u)`` → ``world.advance()``: exactly the order the
serial SIL uses, on the same float32-rounded numbers, so both give the same trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from contracts.controller import Controller
from hil_sim.world import World


@dataclass(frozen=True)
class Trajectory:
    """One run, one entry per tick k = 0 … n−1 (sampled at the tick, command held over it).

    Attributes
    ----------
    t_s
        Tick times (s).
    map_mmhg
        Measured MAP as the controller saw it (mmHg, float32 values; NaN when invalid).
    map_true_mmhg
        True MAP (mmHg).
    target_mmhg
        Target (mmHg).
    command_ml_h
        Controller command (ml/h, float32 as received).
    rate_ml_h
        Mean delivered rate over the tick (ml/h).
    K, T_s, tau_s
        True scheduling parameters at the tick.
    quality, alarms
        Monitor quality flags at the tick; pump alarms after the tick.
    """

    t_s: np.ndarray
    map_mmhg: np.ndarray
    map_true_mmhg: np.ndarray
    target_mmhg: np.ndarray
    command_ml_h: np.ndarray
    rate_ml_h: np.ndarray
    K: np.ndarray
    T_s: np.ndarray
    tau_s: np.ndarray
    quality: np.ndarray
    alarms: np.ndarray


def simulate(world: World, controller: Controller, duration_s: float | None = None) -> Trajectory:
    """Run ``world`` under ``controller`` for ``duration_s`` (default: the scenario's duration).

    Parameters
    ----------
    world
        A fresh :class:`~hil_sim.world.World` (its tick 0 is the first sample).
    controller
        Any :class:`~contracts.controller.Controller` at the world's sample period.
    duration_s
        Simulated time (s); ``round(duration / Ts)`` ticks.

    Returns
    -------
    Trajectory
    """
    ts = world.sample_period_s
    if abs(controller.sample_period_s - ts) > 1e-12:
        raise ValueError(
            f"controller sample_period_s={controller.sample_period_s} s differs from the world's {ts} s"
        )
    duration = world.scenario.duration_s if duration_s is None else duration_s
    n = int(round(duration / ts))
    cols = {name: [0.0] * n for name in ("map", "true", "target", "cmd", "rate", "K", "T", "tau")}
    quality = [0] * n
    alarms = [0] * n
    m, tr, tg, cm, rt = cols["map"], cols["true"], cols["target"], cols["cmd"], cols["rate"]
    kk, tt, ta = cols["K"], cols["T"], cols["tau"]
    observe, apply_command, advance = world.observe, world.apply_command, world.advance
    step = controller.step
    for k in range(n):
        obs = observe()
        u = step(obs.map_mmhg, obs.target_mmhg, obs.K, obs.T_s, obs.tau_s)
        apply_command(u)
        m[k] = obs.map_mmhg
        tr[k] = world.true_map_mmhg()
        tg[k] = obs.target_mmhg
        kk[k] = obs.K
        tt[k] = obs.T_s
        ta[k] = obs.tau_s
        quality[k] = obs.quality
        status = advance()
        cm[k] = world.last_command_ml_h
        rt[k] = world.last_mean_rate_ml_h
        alarms[k] = status.alarms
    t = np.arange(n, dtype=float) * ts
    arr = {k: np.asarray(v, dtype=float) for k, v in cols.items()}
    return Trajectory(
        t_s=t,
        map_mmhg=arr["map"],
        map_true_mmhg=arr["true"],
        target_mmhg=arr["target"],
        command_ml_h=arr["cmd"],
        rate_ml_h=arr["rate"],
        K=arr["K"],
        T_s=arr["T"],
        tau_s=arr["tau"],
        quality=np.asarray(quality, dtype=np.int64),
        alarms=np.asarray(alarms, dtype=np.int64),
    )
