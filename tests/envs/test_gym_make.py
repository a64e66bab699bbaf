"""``gymnasium.make(id)``: one numpy env per registered id that passes Gymnasium's checker; ``make_vec`` unchanged."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import latentrl  # noqa: F401  (registers the ids)
from latentrl.envs import LatentMotionVectorEnv, SingleEnv
from latentrl.errors import ConfigError
from tests.envs.conftest import TASK_IDS

# unbounded observation spaces and float32 bounds: what the checker says of every env of ours, not failures
pytestmark = pytest.mark.filterwarnings("ignore:.*(symmetric and normalized|infinity|unwrapped|precision):UserWarning")


@pytest.mark.parametrize("env_id", list(TASK_IDS))
def test_make_returns_a_single_env_that_passes_check_env(env_id, tiny_model):
    extra, _ = TASK_IDS[env_id]
    env = gym.make(env_id, motion=tiny_model, texts=("walk", "run"), **extra)
    single = env.unwrapped
    assert isinstance(single, SingleEnv) and not isinstance(env, gym.vector.VectorEnv)
    assert single.env.num_envs == 1 and single.env.max_episode_steps == gym.spec(env_id).max_episode_steps
    assert env.spec.id == env_id
    check_env(single, skip_render_check=True)

    obs, info = env.reset(seed=3)
    assert isinstance(obs, np.ndarray) and obs.dtype == np.float32 and obs.shape == env.observation_space.shape
    for _ in range(3):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert isinstance(obs, np.ndarray) and env.observation_space.contains(obs)
        assert isinstance(reward, float) and np.isfinite(reward) and isinstance(info["is_success"], bool)
        if terminated or truncated:
            obs, _ = env.reset()
    env.close()


def test_make_without_arguments_runs_the_embedded_default_model():
    env = gym.make("latentrl/ReachLocation-v0")
    obs, _ = env.reset(seed=0)
    assert env.action_space.shape == (env.unwrapped.env.motion.latent_dim,)
    first = obs
    obs, reward, terminated, truncated, _ = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert obs.shape == first.shape and np.isfinite(reward) and not truncated
    env.close()


def test_make_max_episode_steps_truncates_earlier(tiny_model):
    env = gym.make("latentrl/ReachLocation-v0", max_episode_steps=2, motion=tiny_model,
                   goal_distance=(4.0, 5.0))
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape, dtype=np.float32)
    assert env.step(zero)[3] is False and env.step(zero)[3] is True


def test_make_refuses_vector_arguments(tiny_model):
    with pytest.raises(ConfigError, match="num_envs=4 belongs to gymnasium.make_vec"):
        gym.make("latentrl/ReachLocation-v0", motion=tiny_model, num_envs=4)


def test_make_vec_still_builds_the_batched_env(tiny_model):
    env = gym.make_vec("latentrl/Joystick-v0", num_envs=3, motion=tiny_model)
    assert isinstance(env, LatentMotionVectorEnv) and env.num_envs == 3 and env.max_episode_steps == 75


def test_entry_point_takes_an_env_class_as_register_task_does(tiny_model):
    from latentrl.envs import ReachLocationEnv
    from latentrl.envs.single import SingleEntryPoint

    env = SingleEntryPoint(ReachLocationEnv, 5)(motion=tiny_model)
    assert isinstance(env.env, ReachLocationEnv) and env.env.max_episode_steps == 5
    check_env(env, skip_render_check=True)
