"""Vector-env contract (Gymnasium has no checker for vector envs): spaces, dtypes, masks,
autoreset, partial resets, seeding and bad input."""

import numpy as np
import pytest
import torch
from gymnasium.vector import AutoresetMode

from latentrl.errors import ConfigError, NonFiniteError, TextError
from latentrl.motion.representation import joints_of
from latentrl.motion.text import TableTextEncoder
from latentrl.rewards import DART_TERMS
from tests.envs.conftest import actions

OBS = 4 + 32 + 552 + 1


def test_spaces_layout_and_metadata(make_reach):
    env = make_reach(3)
    assert env.single_action_space.shape == (16,) and env.action_space.shape == (3, 16)
    assert env.single_action_space.low.min() == -4 and env.single_action_space.high.max() == 4
    assert env.single_observation_space.shape == (OBS,) and env.observation_space.shape == (3, OBS)
    assert env.single_observation_space.dtype == np.float32
    assert env.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
    layout = env.observation_layout
    assert list(layout) == ["goal", "text", "motion", "scene"]
    assert layout == {"goal": (0, 4), "text": (4, 36), "motion": (36, 588), "scene": (588, 589)}
    assert env.metadata["observation_layout"] == {k: list(v) for k, v in layout.items()}
    fields = env.observation_fields
    assert fields["goal_dir"] == (0, 3) and fields["goal_dist"] == (3, 4) and fields["scene"] == (588, 589)


def test_reset_and_step_return_batched_tensors(make_reach):
    env = make_reach(3)
    obs, info = env.reset(seed=0)
    assert isinstance(obs, torch.Tensor) and obs.shape == (3, OBS) and obs.dtype == torch.float32
    assert torch.isfinite(obs).all() and info == {}
    obs, reward, terminated, truncated, infos = env.step(actions(3).numpy().astype(np.float64))  # numpy accepted
    assert obs.shape == (3, OBS) and reward.shape == (3,) and reward.dtype == torch.float32
    assert terminated.dtype == torch.bool and truncated.dtype == torch.bool and terminated.shape == (3,)
    for name in DART_TERMS:
        assert infos[f"reward/{name}"].shape == (3,) and infos[f"_reward/{name}"].all()
    for key in ("is_success", "diverged", "nonfinite_action"):
        assert infos[key].dtype == torch.bool and infos[f"_{key}"].all()
    assert "final_obs" not in infos and "episode" not in infos
    # ordinary tensors: a trainer may feed them to autograd
    assert not obs.is_inference() and not reward.is_inference()
    torch.nn.Linear(OBS, 1)(obs).sum().backward()


def test_reward_is_the_weighted_sum_of_reported_terms(make_reach):
    env = make_reach(3, reward_weights={"jerk": 0.5})
    env.reset(seed=0)
    _, reward, _, _, infos = env.step(actions(3))
    manual = sum(env.rewards.weights[k] * infos[f"reward/{k}"] for k in DART_TERMS)
    torch.testing.assert_close(reward, manual)


def test_observation_fields_match_the_state(make_reach, tiny_model):
    env = make_reach(2, texts=("walk", "run"))
    obs, _ = env.reset(seed=1)
    obs, *_ = env.step(actions(2))
    f = env.observation_fields
    state = env._state
    assert torch.equal(obs[:, slice(*f["motion"])], state.history.reshape(2, -1))
    torch.testing.assert_close(obs[:, slice(*f["text"])], tiny_model.encode_text([env.texts[i] for i in env._text_idx]))
    pelvis0_z = state.world.apply(joints_of(state.history))[:, 0, 0, 2]
    torch.testing.assert_close(obs[:, 588], -pelvis0_z)
    goal_dir = obs[:, 0:3]
    torch.testing.assert_close(goal_dir.norm(dim=1), torch.ones(2))
    pelvis_last = env.history_world()[:, -1, 0]
    dist = (env.goal_world[:, :2] - pelvis_last[:, :2]).norm(dim=1).clamp(max=5.0)
    torch.testing.assert_close(obs[:, 3], dist)


def test_same_step_autoreset_reports_final_obs_and_episode(make_reach, tiny_model):
    env = make_reach(3, max_episode_steps=2)
    env.reset(seed=0)
    _, r1, _, tr1, infos1 = env.step(actions(3, 1))
    assert not tr1.any() and "final_obs" not in infos1
    obs, r2, term, tr2, infos = env.step(actions(3, 2))
    assert tr2.all() and not term.any()
    assert infos["_final_obs"].all() and infos["_episode"].all()
    assert infos["final_obs"].shape == (3, OBS) and torch.isfinite(infos["final_obs"]).all()
    torch.testing.assert_close(infos["episode"]["r"], r1 + r2)
    assert infos["episode"]["l"].tolist() == [2, 2, 2] and infos["episode"]["l"].dtype == torch.int32
    # the returned obs are the reset obs: the motion slice is the model's (only) seed history
    seed = tiny_model.seed_history.reshape(1, -1).expand(3, -1)
    assert torch.equal(obs[:, 36:588], seed) and not torch.equal(obs, infos["final_obs"])
    _, _, _, tr3, infos3 = env.step(actions(3, 3))  # counters restarted
    assert not tr3.any() and "episode" not in infos3


def test_disabled_autoreset_and_partial_reset_mask(make_reach, tiny_model):
    env = make_reach(3, max_episode_steps=2, autoreset_mode="Disabled")
    assert env.metadata["autoreset_mode"] is AutoresetMode.DISABLED
    env.reset(seed=0)
    env.step(actions(3, 1))
    obs, _, _, truncated, infos = env.step(actions(3, 2))
    assert truncated.all() and "final_obs" not in infos and infos["_episode"].all()
    obs2, info = env.reset(options={"reset_mask": np.array([True, False, True])})
    assert torch.equal(obs2[1], obs[1])  # untouched env: same observation
    seed = tiny_model.seed_history.reshape(-1)
    assert torch.equal(obs2[0, 36:588], seed) and torch.equal(obs2[2, 36:588], seed)
    _, _, _, truncated, _ = env.step(actions(3, 3))
    assert truncated.tolist() == [False, True, False]  # env 1 was never reset: its counter ran on


def test_partial_reset_leaves_other_envs_bitwise_untouched(make_reach):
    env = make_reach(4, texts=("walk", "run"))
    env.reset(seed=3)
    for k in range(2):
        env.step(actions(4, k))
    keep = torch.tensor([0, 3])
    snapshot = [
        env._state.history[keep].clone(),
        env._state.world.rotation[keep].clone(),
        env._state.world.translation[keep].clone(),
        env.goal_world[keep].clone(),
        env._text_idx[keep].clone(),
        env._steps[keep].clone(),
        env._ep_return[keep].clone(),
    ]
    env.reset(options={"reset_mask": torch.tensor([False, True, True, False])})
    after = [
        env._state.history[keep],
        env._state.world.rotation[keep],
        env._state.world.translation[keep],
        env.goal_world[keep],
        env._text_idx[keep],
        env._steps[keep],
        env._ep_return[keep],
    ]
    for a, b in zip(snapshot, after):
        assert torch.equal(a, b)
    assert env._steps[1:3].tolist() == [0, 0]


@pytest.mark.parametrize(
    "mask,match",
    [
        (np.array([True, False]), "shape"),
        (np.array([1, 0, 1]), "bool"),
        (np.array([False, False, False]), "at least one"),
    ],
)
def test_bad_reset_masks(make_reach, mask, match):
    env = make_reach(3)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        env.reset(options={"reset_mask": mask})


def test_reset_option_and_order_errors(make_reach):
    env = make_reach(2)
    with pytest.raises(ValueError, match="without a reset_mask first"):
        env.reset(options={"reset_mask": np.array([True, False])})
    with pytest.raises(ValueError, match=r"unknown reset option 'reset_msk' \(did you mean 'reset_mask'\?\)"):
        env.reset(options={"reset_msk": np.array([True, False])})
    with pytest.raises(TypeError, match="one int"):
        env.reset(seed=[1, 2])
    with pytest.raises(RuntimeError, match="call reset"):
        make_reach(2).step(actions(2))


def test_same_seed_same_actions_identical_rollouts(make_reach):
    a, b = make_reach(3, texts=("walk", "run")), make_reach(3, texts=("walk", "run"))
    oa, _ = a.reset(seed=7)
    ob, _ = b.reset(seed=7)
    assert torch.equal(oa, ob)
    for k in range(3):
        act = actions(3, k)
        sa, sb = a.step(act), b.step(act)
        for x, y in zip(sa[:4], sb[:4]):
            assert torch.equal(x, y)
    c = make_reach(3, texts=("walk", "run"))
    oc, _ = c.reset(seed=8)
    assert not torch.equal(oc[:, :4], oa[:, :4])  # another seed, other goals


def test_random_initial_steps_desynchronize_truncations(make_reach):
    env = make_reach(16, max_episode_steps=32, random_initial_steps=True)
    env.reset(seed=0)
    start = env._steps.clone()
    assert start.min() >= 0 and start.max() < 32 and len(set(start.tolist())) > 4
    env.reset(options={"reset_mask": np.ones(16, dtype=bool)})  # partial resets start at 0
    assert env._steps.eq(0).all()


def test_success_resamples_goal_and_counts(make_reach):
    env = make_reach(2, success_threshold=1e3)  # every step reaches the goal
    env.reset(seed=0)
    goal = env.goal_world.clone()
    _, reward, terminated, _, infos = env.step(actions(2))
    assert infos["is_success"].all() and infos["reward/success"].tolist() == [1.0, 1.0]
    assert not terminated.any() and not torch.equal(goal, env.goal_world)
    assert env._ep_goals.tolist() == [1, 1]


def test_goal_distance_termination(make_reach):
    env = make_reach(2, terminate_distance=0.01, max_episode_steps=10)
    env.reset(seed=0)
    _, _, terminated, truncated, infos = env.step(actions(2))
    assert terminated.all() and not truncated.any() and infos["_final_obs"].all()


def test_wrong_action_shape_names_the_expected_shape(make_reach):
    env = make_reach(3)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"\(num_envs, D\) = \(3, 16\), got \(3, 15\)"):
        env.step(torch.zeros(3, 15))
    with pytest.raises(ValueError, match=r"got \(3, 1, 16\)"):
        env.step(torch.zeros(3, 1, 16))


def test_nonfinite_actions_raise_naming_envs(make_reach):
    env = make_reach(3)
    env.reset(seed=0)
    act = actions(3)
    act[1, 4] = float("nan")
    act[2, 0] = float("inf")
    with pytest.raises(NonFiniteError, match=r"envs \[1, 2\]"):
        env.step(act)


def test_nonfinite_actions_zero_mode_is_documented_sanitisation(make_reach):
    a, b = make_reach(2, nonfinite_actions="zero"), make_reach(2)
    a.reset(seed=0)
    b.reset(seed=0)
    act = actions(2)
    bad = act.clone()
    bad[1, 3] = float("nan")
    clean = act.clone()
    clean[1] = 0.0
    oa, ra, *_, ia = a.step(bad)
    ob, rb, *_ = b.step(clean)
    assert ia["nonfinite_action"].tolist() == [False, True]
    assert torch.equal(oa, ob) and torch.equal(ra, rb) and torch.isfinite(oa).all()


def test_actions_are_clamped_to_the_bound(make_reach):
    a, b = make_reach(2), make_reach(2)
    a.reset(seed=0)
    b.reset(seed=0)
    big = actions(2) * 100
    assert torch.equal(a.step(big)[0], b.step(big.clamp(-4, 4))[0])


def test_diverged_env_is_terminated_frozen_and_reset(make_reach, tiny_model, monkeypatch):
    env = make_reach(3, max_episode_steps=10)
    env.reset(seed=0)
    real = tiny_model.rollout_step

    def exploding(state, text, noise, guidance):
        out = real(state, text, noise, guidance)
        joints = out.joints_world.clone()
        joints[1] = float("nan")
        history = out.state.history.clone()
        history[1] = float("nan")
        return out._replace(joints_world=joints, state=out.state._replace(history=history))

    monkeypatch.setattr(tiny_model, "rollout_step", exploding)
    obs, reward, terminated, _, infos = env.step(actions(3))
    assert infos["diverged"].tolist() == [False, True, False]
    assert terminated.tolist() == [False, True, False] and infos["_final_obs"].tolist() == [False, True, False]
    assert torch.isfinite(obs).all() and torch.isfinite(infos["final_obs"]).all() and torch.isfinite(reward).all()
    assert reward[1] == 0 and all(infos[f"reward/{k}"][1] == 0 for k in DART_TERMS)
    assert torch.isfinite(env._state.history).all()


@pytest.mark.parametrize("how", ["underground", "out-of-data-range"])
def test_a_body_under_the_floor_or_out_of_the_data_range_diverges(make_reach, tiny_model, monkeypatch, how):
    env = make_reach(3, max_episode_steps=10)
    env.reset(seed=0)
    real = tiny_model.rollout_step

    def sinking(state, text, noise, guidance):  # finite, within 1000 m: only the new checks catch it
        out = real(state, text, noise, guidance)
        joints, history = out.joints_world.clone(), out.state.history.clone()
        if how == "underground":
            joints[2, ..., 2] -= 5.0
        else:
            history[2] = tiny_model.mean + 1e4 * tiny_model.std
        return out._replace(joints_world=joints, state=out.state._replace(history=history))

    monkeypatch.setattr(tiny_model, "rollout_step", sinking)
    _, _, terminated, _, infos = env.step(actions(3))
    assert infos["diverged"].tolist() == [False, False, True] and terminated[2]


def test_unknown_text_with_table_only_encoder(tiny_model, monkeypatch, make_reach):
    table = TableTextEncoder({"walk": torch.ones(32)}, name="table")
    monkeypatch.setattr(tiny_model, "text_encoder", table)
    with pytest.raises(TextError, match="unknown prompt 'moonwalk'"):
        make_reach(2, texts=("walk", "moonwalk"))


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"autoreset_mode": "NextStep"}, "autoreset_mode: NextStep is not supported"),
        ({"autoreset_mode": "sometimes"}, "autoreset_mode: unknown mode"),
        ({"text_weights": (1.0,), "texts": ("walk", "run")}, "text_weights: needs one weight per text"),
        ({"text_weights": (0.0, 0.0), "texts": ("walk", "run")}, "text_weights: must be finite"),
        ({"nonfinite_actions": "ignore"}, "nonfinite_actions"),
        ({"reward_weights": {"distance": 1.0}}, "did you mean 'dist'"),
        ({"max_episode_steps": 0}, "max_episode_steps"),
    ],
)
def test_bad_constructor_arguments(make_reach, kwargs, match):
    with pytest.raises(ConfigError, match=match):
        make_reach(2, **kwargs)


def test_text_weights_select_texts(make_reach):
    env = make_reach(8, texts=("walk", "run"), text_weights=(0.0, 1.0))
    env.reset(seed=0)
    assert [env.texts[i] for i in env._text_idx] == ["run"] * 8
    assert env.text_table.floor_scale.tolist() == pytest.approx([1.0, 0.1])


# --------------------------------------------------------------------------- every task, every id
def test_every_task_steps_batched_tensors_and_reports_its_terms(make_task):
    env = make_task(3)
    obs, _ = env.reset(seed=0)
    dim = env.single_observation_space.shape[0]
    assert obs.shape == (3, dim) and obs.dtype == torch.float32 and torch.isfinite(obs).all()
    assert list(env.observation_layout) == ["goal", "text", "motion", "scene"]
    assert env.observation_fields["scene"] == (dim - 1, dim)
    for k in range(3):
        obs, reward, terminated, truncated, infos = env.step(actions(3, k))
        assert obs.shape == (3, dim) and reward.shape == (3,) and torch.isfinite(reward).all()
        assert terminated.dtype == torch.bool and truncated.dtype == torch.bool
        assert {k[len("reward/"):] for k in infos if k.startswith("reward/")} == set(env.reward_terms)
        manual = sum(env.rewards.weights[t] * infos[f"reward/{t}"] for t in env.reward_terms)
        torch.testing.assert_close(reward, manual)
        for key in ("is_success", "diverged", "nonfinite_action"):
            assert infos[key].shape == (3,) and infos[f"_{key}"].all()


def test_every_task_autoresets_in_the_same_step(make_task):
    env = make_task(3, max_episode_steps=2)
    env.reset(seed=0)
    env.step(actions(3, 1))
    obs, _, _, truncated, infos = env.step(actions(3, 2))
    assert truncated.all() and infos["_final_obs"].all() and infos["_episode"].all()
    assert infos["episode"]["l"].tolist() == [2, 2, 2] and not torch.equal(obs, infos["final_obs"])
    assert env._ep_len.eq(0).all()


def test_every_task_partial_reset_leaves_other_envs_untouched(make_task):
    env = make_task(4, autoreset_mode="Disabled")
    env.reset(seed=3)
    for k in range(2):
        env.step(actions(4, k))
    keep = torch.tensor([0, 3])
    before = env.observation()[keep].clone()
    task_state = {k: v[keep].clone() for k, v in vars(env).items()
                  if torch.is_tensor(v) and v.ndim >= 1 and v.shape[0] == 4 and not k.startswith("_all")}
    obs, _ = env.reset(options={"reset_mask": np.array([False, True, True, False])})
    assert torch.equal(obs[keep], before)
    for name, value in task_state.items():
        assert torch.equal(getattr(env, name)[keep], value), name
    assert env._steps[1:3].tolist() == [0, 0] and env._steps[keep].tolist() == [2, 2]


def test_every_task_is_reproducible_from_its_seed(make_task):
    a, b, c = make_task(3), make_task(3), make_task(3)
    oa, ob, oc = a.reset(seed=5)[0], b.reset(seed=5)[0], c.reset(seed=6)[0]
    assert torch.equal(oa, ob) and not torch.equal(oa[:, :3], oc[:, :3])
    for k in range(4):
        sa, sb = a.step(actions(3, k)), b.step(actions(3, k))
        for x, y in zip(sa[:4], sb[:4]):
            assert torch.equal(x, y)
