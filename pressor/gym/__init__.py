"""Gymnasium environment ``pressor/MAP-v0`` (needs ``pip install -e ".[gym]"``).

Importing this package registers the environment with :func:`gymnasium.register`::

    import gymnasium
    import pressor.gym  # noqa: F401  (registers pressor/MAP-v0)

    env = gymnasium.make("pressor/MAP-v0", scenario="paper-disturbance", ticks_per_action=10)
    obs, info = env.reset(seed=3)             # patient seed 3, as pressor trial / api.simulate
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

(``gymnasium.make("pressor.gym:pressor/MAP-v0")`` imports it on the way.) ``pressor`` itself
never imports this package, so it works without gymnasium.

The agent's action takes the controller's place in the runtime's closed-loop core
(:mod:`pressor.gym.env`): the supervisor, its clamps and the pump's limits apply to it exactly
as to a controller's command.

Spaces (N = ``ticks_per_action``, default 10; the loop runs at ``rate_hz``, default 10 Hz):

action, ``Box(0, max_rate_ml_h, (1,), float32)``
    The infusion rate (ml/h), held for N ticks (N/rate_hz s, default 1 s). The pump limit is the
    scenario's (120 ml/h for the shipped ones). The supervisor clamps an action outside it (fault
    ``COMMAND_CLAMPED``), answers a non-finite one with HOLD and ignores the action while it holds.
observation, ``Dict``, what a device sends
    ``map_mmhg`` (N,) float32 mmHg
        The monitor's MAP samples of the N ticks since the previous action, oldest first, the last
        one the current tick's. A sample without a value (NaN on the link) is 0 here with
        ``QUALITY_INVALID`` set. After :meth:`reset` the N − 1 earlier entries repeat tick 0's
        sample with ``QUALITY_HELD``.
    ``quality`` (N,) uint8
        The samples' quality bits (:mod:`pressor.contracts.faults`: 1 invalid, 2 waveform, 4 held).
    ``target_mmhg`` (1,) float32 mmHg
        The clinician's target at the current tick.
    ``delivered_ml_h`` (1,) float32 ml/h
        The pump's latest reported delivered rate (0 before the first tick).
    ``pump_alarms`` (1,) uint8
        The pump's latest alarm bits (:mod:`pressor.contracts.faults`).

``gymnasium.wrappers.FlattenObservation`` turns it into one vector for agents that need one.

Reward: :class:`MapReward` by default (time in the ±5 mmHg band, hypotension and overshoot
penalties, drug used; formula in :mod:`pressor.gym.reward`); any ``reward(ticks) -> float`` replaces
it (``gymnasium.make(..., reward=my_reward)``). ``info`` holds ``t_s`` (s), ``patient_seed``,
``state`` and ``faults`` (the supervisor's state at the step's last tick and the fault bits of all
its ticks), ``command_ml_h`` (the pump's last command), ``map_true_mmhg`` (the true MAP now),
the simulator's ``K`` (mmHg/(ml/h)), ``T_s`` and ``tau_s`` (s) (for scheduled policies; not in
the observation, a bedside monitor does not know them) and, for the default reward,
``reward_terms``. ``env.unwrapped.episode()`` returns every tick of the episode so far.

Episodes: ``reset(seed=s)`` simulates patient seed ``s`` (``options={"patient_seed": p}`` picks
one explicitly); the same seed gives the same episode, bit for bit. An episode is truncated at
the scenario's ``duration_s`` (or ``duration_s=``); it never terminates earlier.
"""

from __future__ import annotations

import gymnasium

from pressor.gym.env import AgentController, MapEnv
from pressor.gym.reward import MapReward, Ticks

__all__ = ["ENV_ID", "AgentController", "MapEnv", "MapReward", "Ticks"]

#: the registered environment id
ENV_ID = "pressor/MAP-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="pressor.gym.env:MapEnv")
