"""ppo.init_from: a warm-started policy acts exactly as its source until training moves the new fields."""

import pytest
import torch

from latentrl.envs.reach import ReachLocationEnv
from latentrl.errors import CheckpointError, ConfigError
from latentrl.ppo import NativeTrainer, train
from latentrl.ppo.checkpoint import load_policy
from latentrl.scenes import Box, Scene
from tests.ppo.conftest import tiny_policy, tiny_ppo

WALL = Scene((Box((0.0, 2.0), (4.0, 0.2, 2.0)),))


def trained_flat(tiny_model, tmp_path, **policy):
    """One PPO iteration on the flat reach env; its final checkpoint."""
    train(ReachLocationEnv(4, motion=tiny_model), tmp_path / "flat", tiny_ppo(total_steps=32),
          tiny_policy(**policy), progress=False)
    path = tmp_path / "flat" / "final.pt"
    return load_policy(path).policy, path


@pytest.mark.parametrize("policy", [dict(obs_norm=True), dict(architecture="mlp", mlp_hidden=[16])],
                         ids=["dart-obs-norm", "mlp"])
def test_warm_start_onto_a_scene_env_acts_as_the_source_then_learns_the_rays(tiny_model, tmp_path, policy):
    source, path = trained_flat(tiny_model, tmp_path, **policy)
    flat, scened = ReachLocationEnv(4, motion=tiny_model), ReachLocationEnv(4, motion=tiny_model, scene=WALL)
    trainer = NativeTrainer(scened, tmp_path / "scene", tiny_ppo(total_steps=32, init_from=str(path)),
                            tiny_policy(**policy), progress=False)
    trainer.warm_start()  # what ppo.run.train does for a run that starts at step 0
    assert trainer.warm_started == ["scene_rays"]
    flat_obs, _ = flat.reset(seed=2)
    scene_obs, _ = scened.reset(seed=2)
    size = flat_obs.shape[1]
    assert torch.equal(scene_obs[:, :size], flat_obs)
    assert float((scene_obs[:, size:] - 4.0).abs().max()) > 0.1  # the wall is in view: the rays carry something
    trainer.policy.eval()
    with torch.no_grad():
        old, new = source(flat_obs), trainer.policy(scene_obs)
    assert torch.allclose(old.mean, new.mean, atol=1e-6) and torch.allclose(old.value, new.value, atol=1e-6)
    rays = slice(size, size + 16) if policy.get("architecture") == "mlp" else slice(1, 17)
    first = ("actor.body.layers.0.weight" if policy.get("architecture") == "mlp"
             else "trunk.scene_encoder.layers.0.weight")
    assert float(trainer.policy.state_dict()[first][:, rays].abs().max()) == 0.0
    if policy.get("obs_norm"):
        norm = trainer.policy.obs_normalizer
        assert torch.equal(norm.mean[size:], torch.zeros(16)) and torch.equal(norm.var[size:], torch.ones(16))
        assert torch.equal(norm.mean[:size], source.obs_normalizer.mean) and 0 < float(norm.count) <= 10_000
    train(ReachLocationEnv(4, motion=tiny_model, scene=WALL), tmp_path / "run",
          tiny_ppo(total_steps=32, init_from=str(path)), tiny_policy(**policy), progress=False)
    learned = load_policy(tmp_path / "run" / "final.pt").policy.state_dict()
    assert float(learned[first][:, rays].abs().max()) > 0.0  # the gradient reaches the rays


def test_warm_start_refuses_another_width_and_a_missing_file(tiny_model, tmp_path):
    _, path = trained_flat(tiny_model, tmp_path)
    with pytest.raises(CheckpointError, match=r"init_from policy has policy.latent_dim = 32; this config has 64"):
        NativeTrainer(ReachLocationEnv(4, motion=tiny_model), tmp_path / "b", tiny_ppo(init_from=str(path)),
                      tiny_policy(latent_dim=64), progress=False).warm_start()
    with pytest.raises(ConfigError, match=r"ppo.init_from: no policy 'nope_default'"):
        train(ReachLocationEnv(4, motion=tiny_model), tmp_path / "c", tiny_ppo(init_from="nope_default"),
              tiny_policy(), progress=False)
    assert not (tmp_path / "c").exists()  # refused before anything was written


def test_a_resumed_run_continues_its_own_weights_without_reading_the_source(tiny_model, tmp_path):
    _, path = trained_flat(tiny_model, tmp_path)
    source = tmp_path / "source.pt"
    path.rename(source)
    run = tmp_path / "run"
    train(ReachLocationEnv(4, motion=tiny_model, scene=WALL), run, tiny_ppo(total_steps=32, init_from=str(source)),
          tiny_policy(), progress=False)
    source.unlink()  # the source is gone: a resume must not need it
    result = train(ReachLocationEnv(4, motion=tiny_model, scene=WALL), run,
                   tiny_ppo(total_steps=64, init_from=str(source)), tiny_policy(), resume=True, progress=False)
    assert result.env_steps == 64


def test_a_reach_policy_warm_starts_the_sit_task_and_acts_as_itself(tiny_model, tmp_path):
    """The sit task observes its seat and phase as a ``task`` group after the reach task's ``goal``: a reach policy
    warm-starts it (new groups silent), so the sit policy begins by walking to the goal as the reach policy did."""
    from latentrl.envs.sit import SitEnv

    source, path = trained_flat(tiny_model, tmp_path, obs_norm=True)
    sit = SitEnv(4, motion=tiny_model)
    trainer = NativeTrainer(sit, tmp_path / "sit", tiny_ppo(total_steps=32, init_from=str(path)),
                            tiny_policy(obs_norm=True), progress=False)
    trainer.warm_start()
    assert trainer.warm_started == ["task", "scene_rays"]
    obs, _ = sit.reset(seed=1)
    layout = sit.observation_layout
    reach_part = torch.cat([obs[:, a:b] for name, (a, b) in layout.items() if name in ("goal", "text", "motion",
                                                                                          "scene")], dim=1)
    trainer.policy.eval()
    with torch.no_grad():
        old, new = source(reach_part), trainer.policy(obs)
    assert torch.allclose(old.mean, new.mean, atol=1e-6) and torch.allclose(old.value, new.value, atol=1e-6)
