"""Overhead of the Gymnasium environment (``pressor/MAP-v0``) over the simulator's own tick.

Usage: python -m benchmarks.gym_step [--scenario NAME] [--duration-s S] [--episodes E]

In one process, on the same scenario, patient and constant action, in CPU time of the process (a
busy host's preemptions do not count), prints µs per tick of :func:`pressor.hil_sim.episode.simulate`
and, at 1 and at 10 ticks per action, over blocks of 100 ticks run alternately through
``env.step`` and through the bare closed loop (``world.observe`` → ``ClosedLoopCore.step`` →
``world.apply_command`` → ``world.advance``, the body of ``simulate`` without its recording): the
lower deciles of µs per ``env.step`` and per core tick, and the overhead, ``env.step`` minus the
core ticks it runs (the issue's bound: ≤ 50 µs per step), as the median over the block pairs of
each pair's difference (a pair shares the host's state: clock frequency, other jobs).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from pressor.api import _scenario
from pressor.gym import AgentController, MapEnv
from pressor.hil_sim.episode import simulate
from pressor.hil_sim.world import World
from pressor.runtime.core.closed_loop import CLEAN_LINK, ClosedLoopCore
from pressor.runtime.core.supervisor import Supervisor
from pressor.runtime.core.supervisor_config import supervisor_config_for

SEED = 3
ACTION_ML_H = 12.0
PERIOD_S = 0.1
BLOCK_TICKS = 100


class BareLoop:
    """The closed loop alone: world, agent adapter, core, supervisor; no recording, no env."""

    def __init__(self, scenario) -> None:
        self.scenario = scenario
        self.reset()

    def reset(self) -> None:
        sc = self.scenario
        self.world = World(sc, SEED, PERIOD_S)
        agent = AgentController(PERIOD_S, sc.pump.max_rate_ml_h)
        agent.action_ml_h = ACTION_ML_H
        config = supervisor_config_for(agent, sc.sensor.noise_std_mmhg)
        self.core = ClosedLoopCore(agent, Supervisor(config))
        self.status = None

    def run(self, n: int) -> None:
        world = self.world
        observe, apply_command, advance = world.observe, world.apply_command, world.advance
        step, true_map, status = self.core.step, world.true_map_mmhg, self.status
        for _ in range(n):
            obs = observe()
            rec = step(obs, obs.sim_time_s, status, CLEAN_LINK)
            apply_command(rec.supervisor.command_ml_h)
            true_map()
            status = advance()
        self.status = status


def simulate_us(scenario) -> float:
    """µs per tick of :func:`pressor.hil_sim.episode.simulate` (what a trial runs), one episode."""
    world = World(scenario, SEED, PERIOD_S)
    agent = AgentController(PERIOD_S, scenario.pump.max_rate_ml_h)
    agent.action_ml_h = ACTION_ML_H
    t0 = time.process_time()
    simulate(world, agent)
    return (time.process_time() - t0) / round(scenario.duration_s / PERIOD_S) * 1e6


def interleaved(scenario, ticks_per_action: int, episodes: int) -> tuple[float, float, float]:
    """Blocks of BLOCK_TICKS ticks run alternately through the env and the bare loop (so both
    see the same host); the lower deciles of µs per env.step and per bare tick, and the median
    over block pairs of the overhead per step."""
    env = MapEnv(scenario, ticks_per_action=ticks_per_action)
    bare = BareLoop(scenario)
    action = np.array([ACTION_ML_H], np.float32)
    steps = BLOCK_TICKS // ticks_per_action
    clock = time.process_time
    env_us, bare_us, over_us = [], [], []
    for _ in range(episodes):
        env.reset(seed=SEED)
        bare.reset()
        for _ in range(env.n_ticks // BLOCK_TICKS - 1):
            t0 = clock()
            for _ in range(steps):
                env.step(action)
            t1 = clock()
            bare.run(BLOCK_TICKS)
            t2 = clock()
            step_us = (t1 - t0) / steps * 1e6
            tick_us = (t2 - t1) / BLOCK_TICKS * 1e6
            env_us.append(step_us)
            bare_us.append(tick_us)
            over_us.append(step_us - ticks_per_action * tick_us)
    # the lower decile: the least disturbed blocks of a busy host, each for itself
    low = statistics.quantiles
    return low(env_us, n=10)[0], low(bare_us, n=10)[0], statistics.median(over_us)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="paper-disturbance")
    p.add_argument("--duration-s", type=float, default=600.0)
    p.add_argument("--episodes", type=int, default=3)
    args = p.parse_args(argv)
    sc = _scenario(args.scenario, args.duration_s)
    n = int(round(sc.duration_s / PERIOD_S))
    print(
        f"scenario {sc.name}, {args.episodes} episode(s) of {sc.duration_s:g} s ({n} ticks);"
        f" blocks of {BLOCK_TICKS} ticks, CPU time of this process; step and tick: lower deciles,"
        " overhead: median of the block pairs' differences"
    )
    print(f"pressor.hil_sim.episode.simulate, per tick:  {simulate_us(sc):8.2f} us")
    for tpa in (1, 10):
        step, tick, over = interleaved(sc, tpa, args.episodes)
        print(
            f"{tpa:2d} tick(s) per action: env.step {step:8.2f} us, core tick {tick:6.2f} us,"
            f" overhead {over:6.2f} us per step ({over / tpa:5.2f} us per tick)"
        )


if __name__ == "__main__":
    main()
