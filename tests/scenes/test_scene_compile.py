"""An env with a scene keeps the compiled step's contract: one graph, and no tensor built from host data."""

import torch

from latentrl.envs.reach import ReachLocationEnv
from latentrl.scenes.random import RandomObstacles
from tests.envs.test_compiled_step import _core_inputs, _HostData, _trace_one_graph


def make(tiny_model):
    return ReachLocationEnv(3, motion=tiny_model, scene=RandomObstacles(count=[3, 8]),
                            reward_weights={"collision": 1.0, "terrain_contact": 1.0})


def test_a_scene_env_step_core_traces_as_one_graph(tiny_model):
    traced, eager = _trace_one_graph(make(tiny_model))
    torch.testing.assert_close(traced[4], eager[4])
    torch.testing.assert_close(traced[5]["collision"], eager[5]["collision"])


def test_a_scene_env_step_core_builds_no_tensor_from_host_data(tiny_model):
    env = make(tiny_model)
    env.reset(seed=0)
    env.step(torch.zeros(3, 16))  # caches fill outside the probe
    inputs = _core_inputs(env)
    with torch.no_grad(), _HostData() as probe:
        env._motion_core(*inputs)
    assert probe.seen == []
