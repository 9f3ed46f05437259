"""A random policy through the Gymnasium environment ``pressor/MAP-v0``.

The smallest agent loop: make the environment (the simulated patient behind the runtime's
supervisor), reset it with a seed (the patient's), and step it with uniformly random infusion rates
until the episode is truncated at the scenario's duration. Prints each episode's return, the
share of its time with the true MAP within ±5 mmHg of the target and the drug used, from the reward
terms in ``info``. Needs gymnasium (``pip install -e ".[gym]"``)::

    python examples/gym_random_policy.py --episodes 3 --duration-s 600
"""

from __future__ import annotations

import argparse

import gymnasium

import pressor.gym  # noqa: F401  (registers pressor/MAP-v0)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="paper-disturbance")
    p.add_argument("--episodes", type=int, default=3)
    p.add_argument("--duration-s", type=float, default=None)
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args(argv)
    env = gymnasium.make("pressor/MAP-v0", scenario=args.scenario, duration_s=args.duration_s)
    env.action_space.seed(args.seed)
    for episode in range(args.episodes):
        obs, info = env.reset(seed=args.seed + episode)
        total, in_band_s, drug, truncated = 0.0, 0.0, 0.0, False
        while not truncated:
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
            total += reward
            in_band_s += info["reward_terms"]["in_band"]
            drug += info["reward_terms"]["drug"]
        print(
            f"patient {info['patient_seed']}: return {total:9.1f}, time in band"
            f" {100.0 * in_band_s / info['t_s']:5.1f} %, drug term {drug:7.1f}"
        )
    env.close()


if __name__ == "__main__":
    main()
