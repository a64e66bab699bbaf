"""What only a GPU can check: the captured CUDA step, host-sync-free step cores, autocast, PPO on CUDA.

Skipped without CUDA (CI has none); ``scripts/gpu_check.sh`` runs them on a lent GPU and docs/benchmarks.md
records the run. Tiny random-weight model: these check behaviour, not speed.
"""

from pathlib import Path

import gymnasium as gym
import pytest
import torch

import latentrl  # noqa: F401  (registers the env ids)
from latentrl.envs.reach import ReachLocationEnv
from tests.envs.conftest import TASK_IDS, actions
from tests.helpers import make_tiny_model

pytestmark = [pytest.mark.cuda, pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")]

TINY = Path(__file__).resolve().parents[2] / "configs" / "tiny.yaml"
N = 8  # tiny.yaml's env.num_envs: the training test below reuses the compiled step's kernels


@pytest.fixture(scope="module")
def cuda_model():
    return make_tiny_model().to("cuda")


def _graph_launches(fn) -> int:
    """How many CUDA-graph replays (``cudaGraphLaunch``) ``fn`` makes, read from the profiler."""
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof:
        fn()
        torch.cuda.synchronize()
    return sum(e.count for e in prof.key_averages() if "cudaGraphLaunch" in e.key)


def test_the_compiled_cuda_step_replays_a_cuda_graph_and_matches_the_eager_step(cuda_model):
    from torch._dynamo.utils import counters

    torch._dynamo.reset()
    counters.clear()
    eager = ReachLocationEnv(N, motion=cuda_model, device="cuda", max_episode_steps=3)
    graph = ReachLocationEnv(N, motion=cuda_model, device="cuda", max_episode_steps=3, compile=True)
    kept_eager, kept_graph = [], []
    for env in (eager, graph):
        env.reset(seed=0)
    for step in range(7):  # truncations every 3 steps: autoresets happen inside the captured steps
        a = actions(N, seed=step).cuda()
        oe, re, te, tre, _ = eager.step(a)
        og, rg, tg, trg, _ = graph.step(a)
        torch.testing.assert_close(og, oe, atol=1e-3, rtol=1e-3)
        torch.testing.assert_close(rg, re, atol=1e-3, rtol=1e-3)
        assert torch.equal(tg, te) and torch.equal(trg, tre)
        kept_eager.append(oe)
        kept_graph.append(og)
    # a replay writes into the same memory: what earlier steps returned must be copies, still intact
    torch.testing.assert_close(torch.stack(kept_graph), torch.stack(kept_eager), atol=1e-3, rtol=1e-3)
    assert counters["inductor"]["cudagraph_skips"] == 0
    assert _graph_launches(lambda: graph.step(actions(N, seed=9).cuda())) >= 1
    assert _graph_launches(lambda: eager.step(actions(N, seed=9).cuda())) == 0


@pytest.mark.parametrize("env_id", list(TASK_IDS))
def test_every_task_step_core_makes_no_host_sync_or_host_copy_on_cuda(cuda_model, env_id):
    """``set_sync_debug_mode('error')`` raises on ``.item()``, ``nonzero`` and blocking host<->device copies."""
    extra, _ = TASK_IDS[env_id]
    env = gym.make_vec(env_id, num_envs=4, vectorization_mode="vector_entry_point", motion=cuda_model,
                       texts=("walk", "run"), device="cuda", foot_lock=True, **extra)
    env.reset(seed=0)
    env.step(actions(4, seed=0).cuda())  # lazy caches (text table, diffusion tables) fill outside the check
    noise, _ = env._prepare_actions(actions(4, seed=1).cuda())
    inputs = (env._state, env._text_idx, noise, env.goal_world.clone())
    torch.cuda.synchronize()
    torch.cuda.set_sync_debug_mode("error")
    try:
        with torch.no_grad():
            env._motion_core(*inputs)
    finally:
        torch.cuda.set_sync_debug_mode("default")


@pytest.mark.parametrize("amp", ["bf16", "fp16"])
def test_autocast_sampling_on_cuda_changes_the_numbers_a_little(cuda_model, amp):
    from latentrl.motion.rollout import AMP_DTYPES

    g = torch.Generator().manual_seed(0)
    hist = (torch.randn(16, 2, 276, generator=g) * 0.1).cuda()
    text = torch.randn(16, cuda_model.text_dim, generator=g).cuda()
    noise = torch.randn(16, *cuda_model.latent_shape, generator=g).cuda()
    with torch.no_grad():
        plain = cuda_model.sample_primitive(hist, text, noise, guidance_scale=5.0).future
        cuda_model.amp_dtype = AMP_DTYPES[amp]
        try:
            low = cuda_model.sample_primitive(hist, text, noise, guidance_scale=5.0).future
        finally:
            cuda_model.amp_dtype = None
    assert low.dtype == torch.float32
    rel = float((low - plain).norm() / plain.norm())
    assert 0 < rel < 0.05, rel


@pytest.mark.parametrize("trainer, compiled", [("native", False), ("native", True), ("sb3", False)])
def test_ppo_trains_on_cuda_and_its_checkpoint_loads_on_the_cpu(tmp_path, trainer, compiled):
    from latentrl.app.cli import main
    from latentrl.motion import save_motion_model
    from latentrl.ppo.checkpoint import read_checkpoint

    motion = save_motion_model(make_tiny_model(), tmp_path / "tiny.pt")
    run = tmp_path / "run"
    args = ["train", str(TINY), "--device", "cuda", "--trainer", trainer, "--run-dir", str(run), "--no-progress",
            "--set", f"env.motion={motion}", "--set", f"env.compile={str(compiled).lower()}"]
    assert main(args) == 0
    policy = read_checkpoint(run / "final.pt")["policy"]
    assert policy and all(t.device.type == "cpu" and torch.isfinite(t).all() for t in policy.values())


def test_noise_optimization_on_cuda_matches_the_cpu(cuda_model):
    """``latentrl optimize --device cuda``: the same problems give the same noises and errors as on the CPU."""
    from latentrl.optim import OptimizeSettings, optimize
    from tests.optim.test_optim import suite, target_problem

    cpu_model = make_tiny_model()
    probs = suite(target_problem(cpu_model, "a", seed=1), target_problem(cpu_model, "b", seed=2, text="run"))
    settings = OptimizeSettings(steps=5, lr=0.05, batch=2)
    on_cpu = optimize(cpu_model, probs, settings)
    on_gpu = optimize(cuda_model, probs, settings)
    for c, g in zip(on_cpu, on_gpu):
        assert abs(c.metrics["goal_error_cm"] - g.metrics["goal_error_cm"]) < 1e-2
        assert float(abs(torch.as_tensor(c.noise) - torch.as_tensor(g.noise)).max()) < 1e-3
