"""``compile=True``: a step's tensor maths is one graph (no graph break) and gives the eager step's results."""

import pytest
import torch
from torch.utils._python_dispatch import TorchDispatchMode

from latentrl.rewards import RewardConfig
from tests.envs.conftest import actions


def _core_inputs(env):
    state = env._state
    noise, _ = env._prepare_actions(actions(env.num_envs))
    return state, env._text_idx, noise, env.goal_world.clone()


def _trace_one_graph(env) -> tuple:
    """The env's step core traced with fullgraph=True (raises on any graph break) and run eagerly, after a reset.

    The eager backend checks the trace without compiling C++."""
    env.reset(seed=0)
    torch._dynamo.reset()
    core = torch.compile(env._motion_core, fullgraph=True, backend="eager")
    with torch.no_grad():
        return core(*_core_inputs(env)), env._motion_core(*_core_inputs(env))


def test_every_task_step_core_traces_as_one_graph(make_task):
    traced, eager = _trace_one_graph(make_task(num_envs=3))
    torch.testing.assert_close(traced[4], eager[4])  # reward
    torch.testing.assert_close(traced[1], eager[1])  # world joints of the new frames
    assert traced[5].keys() == eager[5].keys()


def test_every_task_steps_through_one_compiled_graph_without_recompiling(make_task):
    """Autoresets, partial resets, new commands and waypoints change values, never the graph's guards."""
    env = make_task(num_envs=3, max_episode_steps=2)
    torch._dynamo.reset()
    env._core = torch.compile(env._motion_core, fullgraph=True, backend="eager")
    env.reset(seed=0)
    env.step(actions(3, seed=0))  # compiles
    with torch._dynamo.config.patch(error_on_recompile=True):
        for step in range(1, 5):  # truncations every 2 steps: same-step autoresets included
            env.step(actions(3, seed=step))


class _HostData(TorchDispatchMode):
    """Records ops that build a tensor from Python data (``torch.tensor``, list indices, scalar setitem):
    on CUDA each is a host-to-device copy, which a CUDA graph cannot capture."""

    def __init__(self):
        super().__init__()
        self.seen: list[str] = []

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        if func in (torch.ops.aten.lift_fresh.default, torch.ops.aten.lift_fresh_copy.default):
            self.seen.append(str(func))
        return func(*args, **(kwargs or {}))


@pytest.mark.parametrize("foot_lock", [False, True])
def test_every_task_step_core_builds_no_tensor_from_host_data(make_task, foot_lock):
    """The sampler's timesteps, guidance, floor snap, canonical frame and foot lookup use device tensors only."""
    env = make_task(num_envs=3, foot_lock=foot_lock)
    env.reset(seed=0)
    env.step(actions(3, seed=0))  # caches (text table, diffusion tables) fill outside the probe
    inputs = _core_inputs(env)
    with torch.no_grad(), _HostData() as probe:
        env._motion_core(*inputs)
    assert probe.seen == []


def test_a_scaled_skill_term_keeps_one_graph(make_reach):
    """``rewards.skill_scale`` (a per-family multiplier of the ``skill`` term) adds no graph break."""
    env = make_reach(3, reward_weights={"skill": 1.0}, reward_config=RewardConfig(skill_scale={"run": 3.0}))
    traced, eager = _trace_one_graph(env)
    torch.testing.assert_close(traced[4], eager[4])
    torch.testing.assert_close(traced[5]["skill"], eager[5]["skill"])


@pytest.mark.slow
def test_compiled_env_matches_the_eager_env(make_reach):
    """The inductor-compiled step (what ``compile: true`` runs) reproduces the eager env step for step."""
    torch._dynamo.reset()
    eager, compiled = make_reach(4), make_reach(4, compile=True)
    assert compiled.compiled and not eager.compiled
    for env in (eager, compiled):
        env.reset(seed=3)
    for step in range(3):
        a = actions(4, seed=step)
        obs_e, rew_e, term_e, trunc_e, _ = eager.step(a)
        obs_c, rew_c, term_c, trunc_c, _ = compiled.step(a)
        torch.testing.assert_close(rew_c, rew_e, atol=1e-4, rtol=1e-4)
        torch.testing.assert_close(obs_c, obs_e, atol=1e-4, rtol=1e-4)
        assert torch.equal(term_c, term_e) and torch.equal(trunc_c, trunc_e)


def test_the_cuda_step_is_compiled_for_graph_capture_and_returns_copies(make_task, monkeypatch):
    """On CUDA ``compile=True`` asks for CUDA-graph capture ("reduce-overhead"), marks every call as a new step and
    copies the outputs (a replay overwrites them). Checked here with the eager backend on CPU tensors: the
    capture itself needs a GPU and is not run by this suite."""
    from latentrl.envs import compiled

    seen, marks, real = [], [], torch.compile
    monkeypatch.setattr(torch, "compile", lambda fn, **kw: seen.append(kw) or real(fn, **{**kw, "backend": "eager"}))
    monkeypatch.setattr(torch.compiler, "cudagraph_mark_step_begin", lambda: marks.append(1))
    assert compiled.compile_mode("cpu") == "default" and compiled.compile_mode("cuda:0") == "reduce-overhead"

    fixed = torch.zeros(3)
    step = compiled.compile_step_core(lambda x: (fixed, {"y": x + 1}), "cuda")
    out = step(torch.ones(3))
    assert seen[-1] == {"fullgraph": True, "dynamic": False, "mode": "reduce-overhead"} and len(marks) == 1
    assert out[0] is not fixed and out[0].data_ptr() != fixed.data_ptr()
    assert torch.equal(out[1]["y"], torch.full((3,), 2.0))

    torch._dynamo.reset()
    env, plain = make_task(num_envs=3), make_task(num_envs=3)
    env._core = compiled.compile_step_core(env._motion_core, "cuda")
    env.reset(seed=0)
    plain.reset(seed=0)
    for i in range(3):
        got, want = env.step(actions(3, seed=i)), plain.step(actions(3, seed=i))
        torch.testing.assert_close(got[0], want[0])
        torch.testing.assert_close(got[1], want[1])
    assert len(marks) == 4
