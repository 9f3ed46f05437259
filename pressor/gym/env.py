"""``pressor/MAP-v0``: the simulated patient and the runtime's supervised loop as a Gymnasium env.

The agent sits where a controller sits. :class:`AgentController` is a
:class:`pressor.contracts.controller.Controller` whose ``step`` returns the agent's latest action; the
environment drives :class:`pressor.hil_sim.world.World` and the runtime's
:class:`pressor.runtime.core.closed_loop.ClosedLoopCore` tick by tick exactly as
:func:`pressor.hil_sim.episode.simulate` (and so ``pressor trial`` and :func:`pressor.api.simulate`) does, with the supervisor
:func:`pressor.runtime.core.supervisor_config.supervisor_config_for` builds for a controller. So the action
passes the same supervisor (STARTUP/AUTO/HOLD/FAILSAFE/RECOVERING, clamp to [0, pump limit],
bumpless re-entry) and the same float32 pump link a controller's command does; in HOLD or
FAILSAFE the supervisor does not ask the agent and the pump gets the supervisor's command.

One :meth:`MapEnv.step` holds the action for ``ticks_per_action`` control ticks (default 10: one
action per second at the 10 Hz loop; the last step of an episode may run fewer). With
``ticks_per_action=1`` a policy that returns a controller's command for each observation replays
that controller tick for tick, as long as the supervisor steps it every tick (no fault holds it).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from itertools import chain
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from pressor.api import _scenario
from pressor.contracts.checks import check_int_range, check_range
from pressor.contracts.faults import QUALITY_HELD, QUALITY_INVALID, FaultSpec, parse_fault
from pressor.gym.reward import COLUMNS, MapReward, Ticks
from pressor.hil_sim.patients.patient_model import DEFAULT_PATIENT_MODEL, check_model_for_scenario
from pressor.hil_sim.scenarios.scenario import Scenario
from pressor.hil_sim.world import World
from pressor.runtime.core.closed_loop import CLEAN_LINK, ClosedLoopCore
from pressor.runtime.core.supervisor import Supervisor
from pressor.runtime.core.supervisor_config import supervisor_config_for

__all__ = ["AgentController", "MapEnv"]


class _Status:
    saturated = False
    rho_clamped = False
    rho_rate_limited = False


class AgentController:
    """The agent in the controller's seat: ``step`` returns :attr:`action_ml_h`.

    Parameters
    ----------
    sample_period_s
        Loop period (s).
    max_rate_ml_h
        Pump limit (ml/h) the supervisor clamps to.
    """

    def __init__(self, sample_period_s: float, max_rate_ml_h: float) -> None:
        self.sample_period_s = float(sample_period_s)
        self.max_rate_ml_h = float(max_rate_ml_h)
        #: the agent's latest action (ml/h), as it set it: the supervisor clamps and checks it
        self.action_ml_h = 0.0
        self.status = _Status()

    def step(self, map_mmhg: float, target_mmhg: float, K: float, T: float, tau: float) -> float:
        """The agent's action (ml/h); the arguments are what a controller would be given."""
        return self.action_ml_h

    def reset(self) -> None:
        """Back to a zero action."""
        self.action_ml_h = 0.0


def _faults(faults: Sequence[str | FaultSpec]) -> tuple[FaultSpec, ...]:
    specs = []
    for i, f in enumerate(faults):
        spec = f if isinstance(f, FaultSpec) else parse_fault(f, i, src="faults")
        if spec.info.group == "link":
            raise ValueError(
                f"faults: {spec.kind!r} is a link fault; the environment's link is perfect"
                " (sensor-*, pump-* and sched-* faults apply)"
            )
        specs.append(spec)
    return tuple(specs)


class MapEnv(gymnasium.Env):
    """Closed-loop vasopressor infusion: MAP from the monitor in, infusion rate out.

    Parameters
    ----------
    scenario
        A scenario name (``pressor scenarios``), a ``.toml`` path or a :class:`Scenario`.
    patient_model
        A patient model name or ``MODULE:CLASS`` (:mod:`pressor.hil_sim.patients.patient_model`).
    faults
        Extra faults, ``--fault`` texts (``"sensor-nan:300,5"``) or :class:`FaultSpec`, after the
        scenario's own; sensor, pump and scheduling faults (the link is perfect).
    ticks_per_action
        Control ticks one action is held for, [1, 10000]; also the number of MAP samples in an
        observation.
    rate_hz
        Control loop rate (Hz), [0.1, 1000]; a whole multiple of the scenario's patient step.
    duration_s
        Episode length (s of patient time), [1, 604800]; default the scenario's ``duration_s``.
    reward
        ``reward(ticks: Ticks) -> float`` per step; default :class:`MapReward` ``()``. A reward
        with a ``terms(ticks) -> dict`` method also gets its terms reported in ``info``.
    max_rate_ml_h
        The pump limit (ml/h) of the action space and the supervisor; default the scenario pump's.
    supervisor
        Overrides of the supervisor's configuration (:class:`pressor.runtime.core.supervisor_config.
        SupervisorConfig` fields, e.g. ``{"safe_rate_ml_h": 5.0}``).
    render_mode
        Only ``None``: the environment does not render (``pressor view`` shows recordings).
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        scenario: str | Scenario = "paper-tracking",
        *,
        patient_model: str = DEFAULT_PATIENT_MODEL,
        faults: Sequence[str | FaultSpec] = (),
        ticks_per_action: int = 10,
        rate_hz: float = 10.0,
        duration_s: float | None = None,
        reward: Callable[[Ticks], float] | None = None,
        max_rate_ml_h: float | None = None,
        supervisor: Mapping[str, Any] | None = None,
        render_mode: str | None = None,
    ) -> None:
        if render_mode is not None:
            raise ValueError(f"render_mode = {render_mode!r}: allowed None")
        check_int_range("ticks_per_action", ticks_per_action, 1, 10000)
        check_range("rate_hz", rate_hz, 0.1, 1000.0, unit="Hz")
        self.scenario = _scenario(scenario, duration_s)
        check_model_for_scenario(
            patient_model, self.scenario.name, self.scenario.frozen is not None
        )
        self.patient_model = patient_model
        self.faults = _faults(faults)
        self.ticks_per_action = ticks_per_action
        self.period_s = 1.0 / rate_hz
        self.n_ticks = int(round(self.scenario.duration_s / self.period_s))
        limit = self.scenario.pump.max_rate_ml_h if max_rate_ml_h is None else max_rate_ml_h
        self.max_rate_ml_h = float(limit)
        self.reward = MapReward() if reward is None else reward
        self._terms = getattr(self.reward, "terms", None)
        self.supervisor_overrides = dict(supervisor or {})
        self.agent = AgentController(self.period_s, self.max_rate_ml_h)
        supervisor_config_for(self.agent, 0.0, **self.supervisor_overrides)  # fail fast
        n = ticks_per_action
        self.action_space = spaces.Box(0.0, self.max_rate_ml_h, (1,), np.float32)
        self.observation_space = spaces.Dict(
            {
                "map_mmhg": spaces.Box(-np.inf, np.inf, (n,), np.float32),
                "quality": spaces.Box(0, 255, (n,), np.uint8),
                "target_mmhg": spaces.Box(-np.inf, np.inf, (1,), np.float32),
                "delivered_ml_h": spaces.Box(0.0, np.inf, (1,), np.float32),
                "pump_alarms": spaces.Box(0, 255, (1,), np.uint8),
            }
        )
        self.render_mode = None
        self.world: World | None = None
        self.core: ClosedLoopCore | None = None
        #: the ticks of the last step (what the reward was given)
        self.ticks: Ticks | None = None

    # -- gymnasium API ----------------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Start an episode with a fresh patient, pump, monitor, supervisor and zero action.

        The patient's seed is ``options["patient_seed"]`` if given, else ``seed`` if given (so
        ``reset(seed=s)`` is patient ``s`` of :func:`pressor.api.simulate` and of ``pressor
        trial``), else drawn from the environment's seeded generator.
        """
        super().reset(seed=seed)
        options = options or {}
        if "patient_seed" in options:
            patient_seed = int(options["patient_seed"])
        elif seed is not None:
            patient_seed = int(seed)
        else:
            patient_seed = int(self.np_random.integers(0, 2**62))
        check_int_range("patient_seed", patient_seed, 0, 2**63 - 1)
        self.patient_seed = patient_seed
        world = World(
            self.scenario,
            patient_seed,
            self.period_s,
            self.faults,
            patient_model=self.patient_model,
        )
        self.agent.reset()
        noise = self.scenario.sensor.noise_std_mmhg
        config = supervisor_config_for(self.agent, noise, **self.supervisor_overrides)
        self.world = world
        self.core = ClosedLoopCore(self.agent, Supervisor(config))
        self._status = None  # no pump status before the first tick
        n, period = self.n_ticks, self.period_s
        # the episode's record: a list per column, filled tick by tick (a list store costs a
        # quarter of a numpy one); a new record per episode, so earlier Ticks stay valid
        self._rec = {
            name: [0.0 if dtype is np.float64 else 0] * n for name, dtype in COLUMNS.items()
        }
        self._rec["t_s"] = [k * period for k in range(n)]  # as Trajectory.t_s
        obs = world.observe()
        m, q = self._sample(obs.map_mmhg, obs.quality)
        held = q | QUALITY_HELD  # before tick 0: tick 0's sample, held (sample-and-hold)
        self._map = deque([m] * (self.ticks_per_action - 1) + [m], maxlen=self.ticks_per_action)
        self._quality = deque(
            [held] * (self.ticks_per_action - 1) + [q], maxlen=self.ticks_per_action
        )
        self.ticks = None
        return self._observation(obs.target_mmhg), self._info(obs, 0, 0, 0.0, None)

    def step(self, action: Any) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Hold ``action`` (ml/h; shape (1,)) for ``ticks_per_action`` ticks; see the module
        docstring. ``truncated`` is True when the episode's duration is reached; an episode never
        terminates otherwise (no state of the loop ends a patient's run)."""
        world, core = self.world, self.core
        if world is None or core is None or world.tick >= self.n_ticks:
            raise RuntimeError("step() before reset() or after the episode ended: call reset()")
        try:
            self.agent.action_ml_h = float(action[0])
        except (TypeError, IndexError):
            self.agent.action_ml_h = float(action)
        k0 = world.tick
        k1 = min(k0 + self.ticks_per_action, self.n_ticks)
        r = self._rec
        m_a, q_a, tr_a = r["map_mmhg"], r["quality"], r["map_true_mmhg"]
        tg_a, c_a, rt_a, d_a = (
            r["target_mmhg"],
            r["command_ml_h"],
            r["rate_ml_h"],
            r["delivered_ml_h"],
        )
        al_a, st_a, f_a = r["alarms"], r["state"], r["faults"]
        observe, apply_command, advance = world.observe, world.apply_command, world.advance
        true_map, step = world.true_map_mmhg, core.step
        maps, qualities = self._map, self._quality
        status = self._status
        faults = 0  # the step's fault bits, OR-ed here (cheaper than a reduce afterwards)
        obs = observe()
        for k in range(k0, k1):
            rec = step(obs, obs.sim_time_s, status, CLEAN_LINK)
            sup = rec.supervisor
            apply_command(sup.command_ml_h)
            m_a[k] = obs.map_mmhg
            q_a[k] = obs.quality
            tr_a[k] = true_map()
            tg_a[k] = obs.target_mmhg
            st_a[k] = sup.state
            f_a[k] = sup.faults
            faults |= sup.faults
            status = advance()
            c_a[k] = world.last_command_ml_h
            rt_a[k] = world.last_mean_rate_ml_h
            d_a[k] = status.delivered_ml_h
            al_a[k] = status.alarms
            obs = observe()
            m = obs.map_mmhg
            if m != m:  # NaN: a sample without a value (see _sample)
                maps.append(0.0)
                qualities.append(obs.quality | QUALITY_INVALID)
            else:
                maps.append(m)
                qualities.append(obs.quality)
        self._status = status
        ticks = self._slice(k0, k1)
        self.ticks = ticks
        if self._terms is not None:
            terms = self._terms(ticks)
            reward = sum(terms.values())
        else:
            terms = None
            reward = float(self.reward(ticks))
        info = self._info(obs, int(st_a[k1 - 1]), faults, c_a[k1 - 1], terms)
        truncated = k1 >= self.n_ticks
        return self._observation(obs.target_mmhg), reward, False, truncated, info

    # -- helpers ----------------------------------------------------------------------------------
    def episode(self) -> Ticks:
        """Every tick of the episode so far (arrays of :class:`Ticks`; the same names and values
        as :class:`pressor.hil_sim.episode.Trajectory` for the same seed and commands)."""
        if self.world is None:
            raise RuntimeError("episode() before reset()")
        return self._slice(0, self.world.tick)

    def _slice(self, a: int, b: int) -> Ticks:
        return Ticks.of_record(self._rec, a, b, self.period_s, self.max_rate_ml_h)

    @staticmethod
    def _sample(map_mmhg: float, quality: int) -> tuple[float, int]:
        """A sample as the observation carries it: no value (NaN) is 0 with QUALITY_INVALID."""
        if math.isnan(map_mmhg):
            return 0.0, quality | QUALITY_INVALID
        return map_mmhg, quality

    def _observation(self, target_mmhg: float) -> dict[str, np.ndarray]:
        status = self._status
        delivered, alarms = (0.0, 0) if status is None else (status.delivered_ml_h, status.alarms)
        n = self.ticks_per_action
        # one array for the floats and one for the bits, then views (one allocation each: speed)
        floats = np.fromiter(chain(self._map, (target_mmhg, delivered)), np.float32, n + 2)
        bits = np.fromiter(chain(self._quality, (alarms,)), np.uint8, n + 1)
        return {
            "map_mmhg": floats[:n],
            "quality": bits[:n],
            "target_mmhg": floats[n : n + 1],
            "delivered_ml_h": floats[n + 1 :],
            "pump_alarms": bits[n:],
        }

    def _info(
        self, obs: Any, state: int, faults: int, command: float, terms: dict[str, float] | None
    ) -> dict[str, Any]:
        info: dict[str, Any] = {
            "t_s": obs.sim_time_s,
            "patient_seed": self.patient_seed,
            "state": state,
            "faults": faults,
            "command_ml_h": float(command),
            "map_true_mmhg": self.world.true_map_mmhg(),
            "K": obs.K,
            "T_s": obs.T_s,
            "tau_s": obs.tau_s,
        }
        if terms is not None:
            info["reward_terms"] = terms
        return info
