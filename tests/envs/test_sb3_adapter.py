"""Sb3VecEnv: SB3's VecEnv contract (env_checker-style checks) and a 2-iteration PPO run."""

import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import VecCheckNan, VecEnv

from latentrl.envs import Sb3VecEnv
from latentrl.errors import ConfigError
from latentrl.rewards import COMMON_TERMS, DART_TERMS

OBS = 4 + 32 + 552 + 1


def test_vecenv_contract(make_reach):
    venv = Sb3VecEnv(make_reach(3, max_episode_steps=2))
    assert isinstance(venv, VecEnv) and venv.num_envs == 3
    assert venv.observation_space.shape == (OBS,) and venv.action_space.shape == (16,)
    assert np.isfinite(venv.action_space.low).all() and np.isfinite(venv.action_space.high).all()
    obs = venv.reset()
    assert isinstance(obs, np.ndarray) and obs.dtype == np.float32 and obs.shape == (3, OBS)
    assert all(venv.observation_space.contains(o) for o in obs)
    assert venv.get_attr("render_mode") == [None] * 3 and venv.env_is_wrapped(object) == [False] * 3
    act = np.stack([venv.action_space.sample() for _ in range(3)])
    obs, rewards, dones, infos = venv.step(act)
    assert obs.dtype == np.float32 and rewards.dtype == np.float32 and rewards.shape == (3,)
    assert dones.dtype == np.bool_ and not dones.any() and len(infos) == 3
    # no episode keys yet
    assert all(set(info) == {f"reward/{k}" for k in (*DART_TERMS, *COMMON_TERMS)} for info in infos)
    assert all(isinstance(v, float) for v in infos[0].values())
    obs, rewards, dones, infos = venv.step(act)
    assert dones.all() and len(infos) == 3
    for info in infos:
        assert info["terminal_observation"].shape == (OBS,) and info["terminal_observation"].dtype == np.float32
        assert info["TimeLimit.truncated"] is True and info["is_success"] in (True, False)
        assert info["episode"]["l"] == 2 and isinstance(info["episode"]["r"], float) and "t" in info["episode"]
    assert not np.array_equal(obs[0], infos[0]["terminal_observation"])


def test_metadata_keeps_the_layout_and_reward_terms_can_be_dropped(make_reach):
    env = make_reach(2)
    venv = Sb3VecEnv(env, reward_terms=False)
    assert venv.metadata["observation_layout"] == env.metadata["observation_layout"]
    venv.reset()
    _, _, _, infos = venv.step(np.zeros((2, 16), np.float32))
    assert infos == [{}, {}]


def test_no_nans_through_vec_check_nan(make_reach):
    venv = VecCheckNan(Sb3VecEnv(make_reach(2, max_episode_steps=2)), raise_exception=True)
    venv.reset()
    for _ in range(3):
        venv.step(np.stack([venv.action_space.sample() for _ in range(2)]) * 10)  # beyond the bound: clamped


def test_seed_then_reset_is_reproducible(make_reach):
    venv = Sb3VecEnv(make_reach(2))
    venv.seed(3)
    first = venv.reset()
    venv.seed(3)
    assert np.array_equal(first, venv.reset())


def test_rejects_envs_without_same_step_autoreset(make_reach):
    with pytest.raises(ConfigError, match="SAME_STEP"):
        Sb3VecEnv(make_reach(2, autoreset_mode="Disabled"))


def test_ppo_trains_two_iterations(make_reach):
    venv = Sb3VecEnv(make_reach(2, max_episode_steps=3))
    model = PPO(
        "MlpPolicy", venv, n_steps=4, batch_size=8, n_epochs=1, policy_kwargs={"net_arch": [16]}, device="cpu", seed=0
    )
    model.set_logger(Logger(None, []))  # SB3's default logger would create a /tmp/SB3-<date> folder
    model.learn(total_timesteps=16)
    assert model.num_timesteps == 16 and model._n_updates == 1 * 2
    assert len(model.ep_info_buffer) >= 2 and all(ep["l"] == 3 for ep in model.ep_info_buffer)
    assert len(model.ep_success_buffer) == len(model.ep_info_buffer)
