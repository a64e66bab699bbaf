"""Gymnasium ids: registered by ``import latentrl``, usable through make_vec, cheap to import."""

import subprocess
import sys
import warnings

import gymnasium as gym
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

import latentrl  # noqa: F401  (registers the ids)
from latentrl.envs import FollowPathEnv, ReachLocationEnv, SingleEnv
from tests.envs.test_follow_path import PATHS


def test_ids_are_registered_with_vector_and_single_entry_points():
    for env_id in ("latentrl/ReachLocation-v0", "latentrl/FollowPath-v0", "latentrl/Joystick-v0",
                   "latentrl/TimedPath-v0"):
        spec = gym.spec(env_id)
        assert spec.vector_entry_point and spec.entry_point is not None  # make_vec: the batched env; make: one


def test_make_vec_reach_location(tiny_model):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # e.g. a missing autoreset_mode in metadata would warn
        env = gym.make_vec(
            "latentrl/ReachLocation-v0",
            num_envs=2,
            vectorization_mode="vector_entry_point",
            motion=tiny_model,
            texts=["walk", "run"],
        )
    assert isinstance(env, ReachLocationEnv) and env.num_envs == 2 and env.max_episode_steps == 32
    assert env.spec.id == "latentrl/ReachLocation-v0" and env.texts == ("walk", "run")
    obs, _ = env.reset(seed=0)
    assert obs.shape == (2, 589)


def test_make_vec_follow_path_with_a_suite(tiny_model):
    env = gym.make_vec(
        "latentrl/FollowPath-v0",
        num_envs=1,
        motion=tiny_model,
        paths=str(PATHS / "dart_demo_walk.json"),
        observe_next=True,
    )
    assert isinstance(env, FollowPathEnv) and env.max_episode_steps == 256
    assert env.single_observation_space.shape == (593,)


def test_import_latentrl_does_not_load_torch():
    code = (
        "import sys, latentrl, gymnasium; assert 'latentrl/ReachLocation-v0' in gymnasium.registry; "
        "assert 'torch' not in sys.modules, 'import latentrl loaded torch'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.filterwarnings("ignore:.*(symmetric and normalized|infinity):UserWarning")
def test_single_env_view_passes_gymnasiums_checker(make_reach):
    env = SingleEnv(make_reach(1, autoreset_mode=AutoresetMode.DISABLED, texts=("walk", "run")))
    check_env(env, skip_render_check=True)


def test_make_vec_joystick_and_timed_path(tiny_model):
    from latentrl.envs import JoystickEnv, TimedPathEnv

    joy = gym.make_vec("latentrl/Joystick-v0", num_envs=2, motion=tiny_model, texts=["run"], speed_range=(2.5, 4.0))
    assert isinstance(joy, JoystickEnv) and joy.max_episode_steps == 75 and joy.single_observation_space.shape == (588,)
    timed = gym.make_vec("latentrl/TimedPath-v0", num_envs=1, motion=tiny_model,
                         paths=str(PATHS.parent / "timed" / "timed_walk.json"))
    assert isinstance(timed, TimedPathEnv) and timed.max_episode_steps == 256
    assert timed.single_observation_space.shape == (590,)
