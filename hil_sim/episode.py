"""One patient's episode in process: :func:`simulate` steps a World with the runtime's closed-loop
core, no I/O, and returns its :class:`Trajectory` (named ``episode``, not ``closed_loop``: the
closed loop itself is :mod:`pressor.runtime.core.closed_loop`, the one the bedside runs).

Per tick k: ``obs = world.observe()`` → ``rec = core.step(obs, ...)`` (the runtime's
:class:`~pressor.runtime.core.closed_loop.ClosedLoopCore`: the supervisor, then the controller if allowed,
given the pump status of tick k and a clean link) → ``world.apply_command(rec.command_ml_h)`` →
``world.advance()``: exactly the order and the core the serial SIL uses, on the same
float32-rounded numbers, so both give the same trajectory and the same supervisor states - with any
scheduling source (``schedule``: the core feeds it, as in the runtime).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pressor.contracts.controller import Controller
from pressor.hil_sim.world import World
from pressor.runtime.core.closed_loop import CLEAN_LINK, ClosedLoopCore
from pressor.runtime.core.scheduling import ScheduleSource
from pressor.runtime.core.supervisor import Supervisor
from pressor.runtime.core.supervisor_config import supervisor_config_for


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
        Command sent to the pump (ml/h, float32 as received).
    rate_ml_h
        Mean delivered rate over the tick (ml/h).
    delivered_ml_h
        Delivered rate (ml/h) the pump reports after the tick (the next tick's pump status).
    K, T_s, tau_s
        True scheduling parameters at the tick.
    sched_K, sched_T_s, sched_tau_s
        The K (mmHg/(ml/h)), T (s), τ (s) the controller was scheduled on at the tick (the
        scheduling source's report; the truth with the oracle).
    quality, alarms
        Monitor quality flags at the tick; pump alarms after the tick.
    state, faults
        Supervisor state (:class:`pressor.runtime.core.supervisor_config.State`) and fault bits at the tick.
    """

    t_s: np.ndarray
    map_mmhg: np.ndarray
    map_true_mmhg: np.ndarray
    target_mmhg: np.ndarray
    command_ml_h: np.ndarray
    rate_ml_h: np.ndarray
    delivered_ml_h: np.ndarray
    K: np.ndarray
    T_s: np.ndarray
    tau_s: np.ndarray
    sched_K: np.ndarray
    sched_T_s: np.ndarray
    sched_tau_s: np.ndarray
    quality: np.ndarray
    alarms: np.ndarray
    state: np.ndarray
    faults: np.ndarray


def simulate(
    world: World,
    controller: Controller,
    duration_s: float | None = None,
    supervisor: Supervisor | None = None,
    schedule: ScheduleSource | None = None,
) -> Trajectory:
    """Run ``world`` under ``controller`` and its supervisor for ``duration_s``.

    Parameters
    ----------
    world
        A fresh :class:`~pressor.hil_sim.world.World` (its tick 0 is the first sample).
    controller
        Any :class:`~pressor.contracts.controller.Controller` at the world's sample period.
    duration_s
        Simulated time (s); ``round(duration / Ts)`` ticks; default the scenario's duration.
    supervisor
        A fresh supervisor; default the one ``pressor sil`` builds for this controller and the
        scenario's sensor (:func:`pressor.runtime.core.supervisor_config.supervisor_config_for`).
    schedule
        A fresh scheduling source (:func:`pressor.runtime.estimation.sources.make_schedule`); default
        the oracle (the world's true K, T, τ).

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
    if supervisor is None:
        noise = world.scenario.sensor.noise_std_mmhg
        supervisor = Supervisor(supervisor_config_for(controller, noise))
    core = ClosedLoopCore(controller, supervisor, schedule)
    n = int(round(duration / ts))
    names = ("map", "true", "target", "cmd", "rate", "delivered", "K", "T", "tau", "sK", "sT", "sd")
    cols = {name: [0.0] * n for name in names}
    ints = {name: [0] * n for name in ("quality", "alarms", "state", "faults")}
    m, tr, tg, cm = cols["map"], cols["true"], cols["target"], cols["cmd"]
    rt, dl = cols["rate"], cols["delivered"]
    kk, tt, ta = cols["K"], cols["T"], cols["tau"]
    sk, st, sd = cols["sK"], cols["sT"], cols["sd"]
    quality, alarms, state, faults = ints["quality"], ints["alarms"], ints["state"], ints["faults"]
    observe, apply_command, advance = world.observe, world.apply_command, world.advance
    step = core.step
    status = None  # no pump status before the first advance
    for k in range(n):
        obs = observe()
        rec = step(obs, obs.sim_time_s, status, CLEAN_LINK)
        out = rec.supervisor
        apply_command(out.command_ml_h)  # rec.command_ml_h, without the property's call
        m[k] = obs.map_mmhg
        tr[k] = world.true_map_mmhg()
        tg[k] = obs.target_mmhg
        kk[k] = obs.K
        tt[k] = obs.T_s
        ta[k] = obs.tau_s
        sched = rec.schedule
        sk[k] = sched.K
        st[k] = sched.T_s
        sd[k] = sched.tau_s
        quality[k] = obs.quality
        state[k] = out.state
        faults[k] = out.faults
        status = advance()
        cm[k] = world.last_command_ml_h
        rt[k] = world.last_mean_rate_ml_h
        dl[k] = status.delivered_ml_h
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
        delivered_ml_h=arr["delivered"],
        K=arr["K"],
        T_s=arr["T"],
        tau_s=arr["tau"],
        sched_K=arr["sK"],
        sched_T_s=arr["sT"],
        sched_tau_s=arr["sd"],
        **{name: np.asarray(v, dtype=np.int64) for name, v in ints.items()},
    )
