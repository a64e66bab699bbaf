"""``foot_lock`` in the envs: the config field reaches the rollout, the step stays one graph, feet slide less."""

import torch

from latentrl.envs.config import EnvConfig, build
from tests.envs.conftest import actions


def test_foot_lock_step_core_traces_as_one_graph(make_reach):
    env = make_reach(3, foot_lock=True)
    env.reset(seed=0)
    torch._dynamo.reset()
    core = torch.compile(env._motion_core, fullgraph=True, backend="eager")
    state = env._state
    noise, _ = env._prepare_actions(actions(3))
    inputs = (state, env._text_idx, noise, env.goal_world.clone())
    with torch.no_grad():
        torch.testing.assert_close(core(*inputs)[1], env._motion_core(*inputs)[1])


def test_config_field_locks_the_feet_of_the_default_model():
    """Same seed and actions, with and without the lock: same heights, less skate reward lost, and only then."""
    skate, heights = {}, {}
    for lock in (False, True):
        env = build(EnvConfig(num_envs=8, texts=["walk"], foot_lock=lock), "cpu")
        assert env.foot_lock is lock
        env.reset(seed=0)
        total, zs = 0.0, []
        for step in range(4):
            _, _, _, _, info = env.step(actions(8, seed=step, dim=env.single_action_space.shape[0]))
            total += float(info["reward/skate"].sum())
            zs.append(env.history_world()[..., 2])
        skate[lock], heights[lock] = total, torch.stack(zs)
    assert torch.allclose(heights[True], heights[False], atol=1e-5)
    assert skate[True] > 0.5 * skate[False]  # skate terms are <= 0: the locked walk loses less than half as much
