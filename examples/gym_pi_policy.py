"""The paper's PI baseline as a policy of the Gymnasium environment ``pressor/MAP-v0``.

A policy is any function from an observation to an action. This one feeds the newest MAP sample
(no value when its ``QUALITY_INVALID`` bit is set) and the target to
:class:`pressor.baselines.pi.PIController`, discretised at the action period, and returns its command.

At one tick per action (``--ticks-per-action 1``) the episode is tick for tick the one
``pressor trial --controller pi`` simulates for that patient seed (same supervisor, same pump, same
numbers), which the script checks against :func:`pressor.api.simulate`. At the default 10 ticks
(one action per second) it is a 1 Hz PI. Needs gymnasium (``pip install -e ".[gym]"``)::

    python examples/gym_pi_policy.py --episodes 2 --duration-s 600 --ticks-per-action 1
"""

from __future__ import annotations

import argparse
import math

import gymnasium
import numpy as np

import pressor.gym  # noqa: F401  (registers pressor/MAP-v0)
from pressor import api
from pressor.baselines.pi import PIController
from pressor.contracts.faults import QUALITY_INVALID


class PIPolicy:
    """The PI baseline on the newest sample of each observation.

    Parameters
    ----------
    action_period_s
        Time (s) one action is held: the PI's sample period.
    """

    def __init__(self, action_period_s: float) -> None:
        self.pi = PIController(sample_period_s=action_period_s)

    def __call__(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """The command (ml/h) for this observation."""
        invalid = int(obs["quality"][-1]) & QUALITY_INVALID
        map_mmhg = math.nan if invalid else float(obs["map_mmhg"][-1])
        u = self.pi.step(map_mmhg, float(obs["target_mmhg"][0]), math.nan, math.nan, math.nan)
        return np.array([u], np.float32)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="paper-disturbance")
    p.add_argument("--episodes", type=int, default=2)
    p.add_argument("--duration-s", type=float, default=None)
    p.add_argument("--ticks-per-action", type=int, default=10)
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args(argv)
    env = gymnasium.make(
        "pressor/MAP-v0",
        scenario=args.scenario,
        duration_s=args.duration_s,
        ticks_per_action=args.ticks_per_action,
    )
    action_period_s = args.ticks_per_action * env.unwrapped.period_s
    for episode in range(args.episodes):
        seed = args.seed + episode
        policy = PIPolicy(action_period_s)
        obs, info = env.reset(seed=seed)
        total, truncated = 0.0, False
        while not truncated:
            obs, reward, terminated, truncated, info = env.step(policy(obs))
            total += reward
        line = f"patient {seed}: return {total:9.1f}"
        if args.ticks_per_action == 1:
            run = api.simulate("pi", args.scenario, seed, duration_s=args.duration_s)
            same = np.array_equal(env.unwrapped.episode().command_ml_h, run.trajectory.command_ml_h)
            line += f", commands identical to pressor trial's: {same}"
            if not same:
                raise SystemExit(line)
        print(line)
    env.close()


if __name__ == "__main__":
    main()
