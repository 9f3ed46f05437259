"""The Gymnasium environment pressor/MAP-v0 (pressor.gym): real simulations, no doubles."""

from __future__ import annotations

import hashlib
import math
import subprocess
import sys

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import pressor.gym
from pressor import api
from pressor.baselines.pi import PIController
from pressor.contracts.faults import QUALITY_HELD, QUALITY_INVALID
from pressor.contracts.metrics import run_metrics
from pressor.gym import MapEnv, MapReward, Ticks
from pressor.gym.reward import COLUMNS
from pressor.hil_sim.patients.cohort import cohort_seeds
from pressor.hil_sim.trials.trial import run_patient, scenario_events
from pressor.runtime.core.supervisor_config import Fault, State

TRAJECTORY_FIELDS = (
    "t_s",
    "map_mmhg",
    "map_true_mmhg",
    "target_mmhg",
    "command_ml_h",
    "rate_ml_h",
    "delivered_ml_h",
    "quality",
    "alarms",
    "state",
    "faults",
)


def pi_policy(period_s: float):
    pi = PIController(sample_period_s=period_s)

    def act(obs):
        invalid = int(obs["quality"][-1]) & QUALITY_INVALID
        map_mmhg = math.nan if invalid else float(obs["map_mmhg"][-1])
        u = pi.step(map_mmhg, float(obs["target_mmhg"][0]), math.nan, math.nan, math.nan)
        return np.array([u], np.float32)

    return act


def run_episode(env, policy, seed):
    obs, info = env.reset(seed=seed)
    steps = [(obs, info)]
    truncated = False
    while not truncated:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        assert not terminated
        steps.append((obs, reward, info))
    return steps


def episode_digest(steps) -> str:
    h = hashlib.sha256()
    for step in steps:
        for key in sorted(step[0]):
            h.update(step[0][key].tobytes())
        h.update(repr(step[1:]).encode())
    return h.hexdigest()


# The spaces are in ml/h and mmHg on purpose; check_env's advice to normalise them is a warning.
@pytest.mark.filterwarnings("ignore:.*(symmetric and normalized|infinity).*:UserWarning")
def test_check_env_passes_on_the_registered_environment():
    env = gymnasium.make("pressor/MAP-v0", scenario="paper-disturbance", duration_s=30.0)
    check_env(env.unwrapped)
    assert pressor.gym.ENV_ID in gymnasium.registry


def test_the_same_seed_gives_the_same_episode_bytes_and_another_seed_does_not():
    env = MapEnv("paper-disturbance", duration_s=120.0, faults=("sensor-nan:30,5",))

    def digest(seed):
        env.action_space.seed(7)
        return episode_digest(run_episode(env, lambda obs: env.action_space.sample(), seed))

    assert digest(4) == digest(4)
    assert digest(4) != digest(5)


def test_pi_through_the_env_at_one_tick_per_action_is_pressor_trial_tick_for_tick():
    seed = cohort_seeds(1, 1)[0]  # pressor trial --seed 1: its first patient
    env = MapEnv("paper-disturbance", ticks_per_action=1, duration_s=600.0)
    run_episode(env, pi_policy(env.period_s), seed)
    episode = env.episode()
    run = api.simulate("pi", "paper-disturbance", seed, duration_s=600.0)
    for name in TRAJECTORY_FIELDS:
        assert getattr(episode, name).tobytes() == getattr(run.trajectory, name).tobytes(), name
    # ... and the metrics of the episode are the trial record's (pressor trial's patients.json)
    sc = env.scenario
    metrics = run_metrics(
        episode.t_s,
        episode.map_true_mmhg,
        episode.target_mmhg,
        episode.rate_ml_h,
        max_rate_ml_h=sc.pump.max_rate_ml_h,
        step_time_s=sc.step_time_s if sc.step_mmhg else None,
        step_mmhg=sc.step_mmhg if sc.step_mmhg else None,
        noisy=sc.noisy,
        reachable=run.record["reachable"],
        map_true_mmhg=episode.map_true_mmhg,
        events=scenario_events(sc),
    )
    record = run_patient(sc, "pi", seed)
    assert {k: record[k] for k in metrics} == metrics


def test_an_action_is_held_for_ticks_per_action_ticks_and_the_last_step_is_shorter():
    env = MapEnv("paper-tracking", ticks_per_action=10, duration_s=1.5)
    obs, _ = env.reset(seed=2)
    assert obs["map_mmhg"].shape == (10,)
    assert list(obs["quality"][:-1] & QUALITY_HELD) == [QUALITY_HELD] * 9
    _, _, _, truncated, info = env.step(np.array([12.0], np.float32))
    assert not truncated and info["t_s"] == pytest.approx(1.0)
    assert list(env.ticks.command_ml_h) == [12.0] * 10
    _, _, _, truncated, _ = env.step(np.array([20.0], np.float32))
    assert truncated and list(env.ticks.command_ml_h) == [20.0] * 5
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.array([1.0], np.float32))


def test_the_supervisor_clamps_an_action_above_the_pump_limit():
    env = MapEnv("paper-tracking", duration_s=10.0)
    env.reset(seed=1)
    _, _, _, _, info = env.step(np.array([500.0], np.float32))
    assert info["command_ml_h"] == env.max_rate_ml_h == 120.0
    assert info["faults"] & Fault.COMMAND_CLAMPED


def test_the_supervisor_holds_the_pump_through_a_sensor_fault_whatever_the_action():
    env = MapEnv("paper-tracking", duration_s=40.0, faults=("sensor-nan:20,5",))
    env.reset(seed=1)
    for _ in range(20):  # 20 s at 8 ml/h, then the monitor has no value for 5 s
        env.step(np.array([8.0], np.float32))
    obs, _, _, _, info = env.step(np.array([100.0], np.float32))
    assert info["state"] == State.HOLD
    assert set(env.ticks.command_ml_h) == {8.0}  # the agent's 100 ml/h never reaches the pump
    assert list(obs["map_mmhg"]) == [0.0] * 10 and all(obs["quality"] & QUALITY_INVALID)


def test_default_reward_terms_follow_the_documented_formula():
    n = 4
    ticks = Ticks(
        t_s=np.arange(n) * 0.5,
        map_mmhg=np.zeros(n),
        quality=np.zeros(n, np.int64),
        # e = +2 (in band), -9 (4 below), +11 (6 above), -5 (in band: the edge belongs to it)
        map_true_mmhg=np.array([82.0, 71.0, 91.0, 75.0]),
        target_mmhg=np.full(n, 80.0),
        command_ml_h=np.zeros(n),
        rate_ml_h=np.array([0.0, 60.0, 120.0, 60.0]),
        delivered_ml_h=np.zeros(n),
        alarms=np.zeros(n, np.int64),
        state=np.zeros(n, np.int64),
        faults=np.zeros(n, np.int64),
        period_s=0.5,
        max_rate_ml_h=120.0,
    )
    reward = MapReward()
    terms = reward.terms(ticks)
    assert terms == pytest.approx(
        {
            "in_band": 1.0 * 0.5 * 2,
            "hypotension": -0.2 * 0.5 * 4.0,
            "overshoot": -0.05 * 0.5 * 6.0,
            "drug": -0.1 * 0.5 * 2.0,
        }
    )
    assert reward(ticks) == pytest.approx(sum(terms.values()))
    weighted = MapReward(in_band=0.0, hypotension=1.0, overshoot=0.0, drug=0.0)
    assert weighted(ticks) == pytest.approx(-0.5 * 4.0)


def test_a_steps_ticks_are_the_episodes_ticks_of_that_step_and_stay_valid_after_reset():
    env = MapEnv("paper-tracking", ticks_per_action=10, duration_s=3.0)
    env.reset(seed=2)
    env.step(np.array([12.0], np.float32))
    env.step(np.array([30.0], np.float32))
    second = env.ticks
    assert len(second) == 10 and second.values("command_ml_h") == [30.0] * 10
    episode = env.episode()
    for name in COLUMNS:
        column = getattr(second, name)
        assert column.dtype == COLUMNS[name], name
        assert column.tobytes() == getattr(episode, name)[10:20].tobytes(), name
        assert second.values(name) == column.tolist(), name
    made = second.map_true_mmhg
    env.reset(seed=3)
    env.step(np.array([1.0], np.float32))
    assert second.map_true_mmhg is made and second.values("command_ml_h") == [30.0] * 10
    with pytest.raises(AttributeError, match="no attribute 'volume'"):
        second.volume  # noqa: B018
    with pytest.raises(KeyError, match="allowed t_s, map_mmhg"):
        second.values("volume")


def test_ticks_built_from_arrays_refuse_columns_of_different_lengths():
    columns = {name: np.zeros(3, dtype) for name, dtype in COLUMNS.items()}
    columns["rate_ml_h"] = np.zeros(2)
    with pytest.raises(ValueError, match=r"different lengths \[2, 3\]"):
        Ticks(**columns, period_s=0.1, max_rate_ml_h=120.0)


def test_the_env_reports_the_default_reward_terms_and_a_callable_replaces_the_reward():
    env = MapEnv("paper-tracking", duration_s=5.0)
    env.reset(seed=1)
    _, reward, _, _, info = env.step(np.array([5.0], np.float32))
    assert reward == pytest.approx(sum(info["reward_terms"].values()))
    assert info["reward_terms"]["drug"] < 0.0

    def drug_only(ticks: Ticks) -> float:
        return -float(ticks.rate_ml_h.sum())

    env = MapEnv("paper-tracking", duration_s=5.0, reward=drug_only)
    env.reset(seed=1)
    env.step(np.array([5.0], np.float32))
    _, reward, _, _, info = env.step(np.array([5.0], np.float32))
    assert reward == -float(env.ticks.rate_ml_h.sum()) < 0.0 and "reward_terms" not in info


def test_reset_seed_is_the_patient_seed_and_unseeded_resets_continue_reproducibly():
    env = MapEnv("paper-tracking", duration_s=5.0)
    assert env.reset(seed=5)[1]["patient_seed"] == 5
    assert env.reset(options={"patient_seed": 9})[1]["patient_seed"] == 9
    env.reset(seed=5)
    drawn = [env.reset()[1]["patient_seed"] for _ in range(3)]
    env.reset(seed=5)
    assert [env.reset()[1]["patient_seed"] for _ in range(3)] == drawn


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"faults": ("link-drop",)}, "link fault"),
        ({"ticks_per_action": 0}, "ticks_per_action"),
        ({"rate_hz": 5000.0}, "rate_hz"),
        ({"scenario": "no-such-scenario"}, "no-such-scenario"),
    ],
)
def test_bad_options_are_refused_naming_the_option(kwargs, match):
    with pytest.raises(ValueError, match=match):
        MapEnv(**kwargs)


def test_pressor_works_without_importing_gymnasium():
    code = "import sys, pressor.api, pressor.cli; assert 'gymnasium' not in sys.modules"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True).returncode == 0
