"""The scene safety filter (latentrl.optim.avoid): untouched far from objects, off a wall near one."""

from __future__ import annotations

import pytest
import torch

from latentrl.envs.reach import ReachLocationEnv
from latentrl.errors import LatentRLError
from latentrl.motion.checkpoint import load_motion_model
from latentrl.motion.skeleton import JOINT_NAMES
from latentrl.optim.avoid import AvoidSettings, avoid, avoiding, band
from latentrl.optim.refine import inputs_rows, predict
from latentrl.scenes.contact import collision_cost, penetration, skin_radii
from latentrl.scenes.scene import Box, Cylinder, Scene, SceneBatch

WALL = Scene([Box(center=(0.0, 0.8), size=(4.0, 0.2, 1.5))])
"""A wall across the way 0.7 m ahead of the start pelvis (the body starts at the origin facing +y)."""


@pytest.fixture(scope="module")
def model():
    """The embedded default model: its walk goes forward (the tiny model's random motion does not)."""
    return load_motion_model("default")


def walker(model, scene, n=1) -> ReachLocationEnv:
    env = ReachLocationEnv(n, motion=model, scene=scene, autoreset_mode="Disabled", max_episode_steps=16,
                           texts=["walk"], record_history=True)
    env.reset(seed=0)
    return env


def test_a_flat_floor_env_gets_the_policys_own_action(tiny_model):
    env = ReachLocationEnv(2, motion=tiny_model, autoreset_mode="Disabled")
    env.reset(seed=0)
    action = torch.randn(2, tiny_model.latent_dim)
    assert avoid(env, action, AvoidSettings()) is action


def test_a_plan_clear_of_every_object_is_left_alone(model):
    far = Scene([Box(center=(0.0, 20.0), size=(1.0, 1.0, 1.0))])
    env = walker(model, far, n=2)
    action = torch.zeros(2, model.latent_dim)
    assert avoid(env, action, AvoidSettings()) is action


def test_the_band_adds_the_margin_to_every_joint_but_the_feet_and_ankles():
    joints = torch.zeros(1, 1, 22, 3)
    keep, skin = band(joints, 0.1), skin_radii(joints)
    for j, name in enumerate(JOINT_NAMES):
        grounded = name in ("left_ankle", "right_ankle", "left_foot", "right_foot")
        assert float(keep[j]) == pytest.approx(float(skin[j]) + (0.0 if grounded else 0.1))


def test_the_filters_cost_is_the_summed_depth_inside_the_band_averaged_over_frames():
    scene = SceneBatch.from_scenes([Scene([Box(center=(0.0, 1.0), size=(2.0, 0.2, 2.0))])])
    joints = torch.zeros(1, 2, 22, 3)
    joints[..., 2] = 1.0
    joints[0, 0, 0, 1] = 0.85  # the pelvis 5 cm from the box's face (y = 0.9) in frame 0; every other joint far
    keep = torch.full((22,), 0.1)
    assert float(collision_cost(joints, scene, keep)[0]) == pytest.approx((0.1 - 0.05) / 2, abs=1e-6)


def test_step_inputs_of_some_envs_plan_those_envs_as_the_whole_batch_does(model):
    env = walker(model, WALL, n=3)
    inputs = env.step_inputs()
    z = torch.randn(2, 3, *model.latent_shape, generator=torch.Generator().manual_seed(0))
    idx = torch.tensor([2, 0])
    with torch.no_grad():
        whole = predict(model, inputs, z)
        some = predict(model, inputs_rows(inputs, idx), z[:, idx])
    assert torch.allclose(some, whole[idx], atol=1e-5)


def _walk_into(env, act, steps: int) -> torch.Tensor:
    """Step ``env`` ``steps`` times with ``act``; its recorded world joints since the reset."""
    obs = env.observation()
    for _ in range(steps):
        obs = env.step(act(obs))[0]
    return torch.as_tensor(env.export_clip(0, episode=0).joints)[None]


def test_a_body_walking_at_a_pillar_stops_short_of_it_with_the_filter(model):
    """Zero noise walks 'walk' straight at a pillar and through it; with the filter no joint reaches its skin."""
    pillar = Scene([Cylinder(center=(0.15, 1.3), radius=0.25, height=1.8)])

    def zeros(obs):
        return torch.zeros(obs.shape[0], model.latent_dim)

    blind = _walk_into(walker(model, pillar), zeros, 8)
    scene = walker(model, pillar).scene.batch
    assert float(penetration(blind, scene).max()) > 0.1  # without the filter a joint goes 10 cm and more in
    env = walker(model, pillar)
    safe = _walk_into(env, avoiding(env, zeros, AvoidSettings()), 8)
    assert float(penetration(safe, scene).max()) == 0.0
    assert float(safe[0, -1, 0, 1]) > 0.4  # it went forward before it stopped


def test_the_settings_refuse_values_out_of_range_in_one_line():
    for bad, message in ((dict(steps=-1), "avoid steps: expected 0-1000, got -1"),
                         (dict(horizon=0), "avoid horizon: expected 1-16 primitives, got 0"),
                         (dict(margin=2.0), "avoid margin: expected metres in [0, 1], got 2.0"),
                         (dict(lr=0.0), "avoid lr: expected a learning rate in (0, 10], got 0.0"),
                         (dict(anchor=-1.0), "avoid anchor: expected a weight in [0, 1e6], got -1.0"),
                         (dict(samples=-1), "avoid samples: expected 0-256, got -1")):
        with pytest.raises(LatentRLError) as err:
            AvoidSettings(**bad).check()
        assert str(err.value) == message


def test_an_empty_scene_gets_the_policys_own_action_without_a_prediction(model, monkeypatch):
    import latentrl.optim.avoid as A

    env = walker(model, Scene())
    monkeypatch.setattr(A, "predict", lambda *a, **k: pytest.fail("an empty scene needs no prediction"))
    action = torch.zeros(1, model.latent_dim)
    assert avoid(env, action, AvoidSettings()) is action


def _at_the_wall(model):
    """A walker facing WALL, the zero noise whose plan comes too close, and an optimized noise whose plan keeps out."""
    env = walker(model, WALL)
    zeros = torch.zeros(1, model.latent_dim)
    safe = avoid(env, zeros, AvoidSettings())
    assert not torch.equal(safe, zeros)  # the zero-noise plan is at risk here
    return env, zeros, safe


def _plan(env, model, noise: torch.Tensor) -> torch.Tensor:
    z = torch.zeros(2, 1, *model.latent_shape)
    z[0] = noise.reshape(1, *model.latent_shape)
    with torch.no_grad():
        return predict(model, env.step_inputs(), z)


def test_a_safe_draw_of_the_policy_is_taken_without_the_optimizer(model, monkeypatch):
    import latentrl.optim.avoid as A

    env, zeros, safe = _at_the_wall(model)
    keep = band(_plan(env, model, zeros), 0.1)
    assert float(collision_cost(_plan(env, model, safe), env.scene.batch, keep)[0]) == 0.0
    monkeypatch.setattr(A.torch.optim, "Adam", lambda *a, **k: pytest.fail("a safe draw needs no optimizer"))
    chosen = avoid(env, zeros, AvoidSettings(samples=2), lambda k: torch.stack([zeros, safe]))
    assert torch.equal(chosen, safe)


def test_of_the_safe_draws_the_one_ending_nearest_the_policys_own_plan_is_taken(model):
    env, zeros, safe = _at_the_wall(model)
    other = safe + 0.05 * torch.randn(safe.shape, generator=torch.Generator().manual_seed(1))
    keep, scene = band(_plan(env, model, zeros), 0.1), env.scene.batch
    plans = {name: _plan(env, model, z) for name, z in (("safe", safe), ("other", other))}
    assert all(float(collision_cost(p, scene, keep)[0]) == 0.0 for p in plans.values())
    own_end = _plan(env, model, zeros)[0, -1, 0, :2]
    miss = {name: float((p[0, -1, 0, :2] - own_end).norm()) for name, p in plans.items()}
    assert miss["safe"] != miss["other"]
    nearest = safe if miss["safe"] < miss["other"] else other
    for order in ((safe, other), (other, safe)):
        chosen = avoid(env, zeros, AvoidSettings(samples=2), lambda k, o=order: torch.stack(o))
        assert torch.allclose(chosen, nearest, atol=1e-6)


def test_where_no_draw_is_safe_the_optimizer_moves_the_policys_own_noise(model):
    env, zeros, safe = _at_the_wall(model)
    chosen = avoid(env, zeros, AvoidSettings(samples=3), lambda k: torch.zeros(k, 1, model.latent_dim))
    assert torch.equal(chosen, safe)  # the same optimization as without draws, bit for bit


def test_avoiding_draws_its_samples_from_the_sampling_policy_only_where_a_plan_is_at_risk(model):
    calls = []

    def policy(obs):
        calls.append(1)
        return torch.zeros(obs.shape[0], model.latent_dim)

    far = Scene([Box(center=(0.0, 20.0), size=(1.0, 1.0, 1.0))])
    env = walker(model, far)
    avoiding(env, lambda obs: torch.zeros(obs.shape[0], model.latent_dim), AvoidSettings(samples=5),
             policy)(env.observation())
    assert calls == []  # a clear plan costs no draw (and no random number)
    env = walker(model, WALL)
    avoiding(env, lambda obs: torch.zeros(obs.shape[0], model.latent_dim), AvoidSettings(samples=5),
             policy)(env.observation())
    assert len(calls) == 5
