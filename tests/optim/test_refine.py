"""Closed-loop refinement of a policy's noise (latentrl.optim.refine) and the env hooks it reads."""

from __future__ import annotations

import copy

import pytest
import torch

from latentrl.envs.reach_joint import JOINTS, JointGoal, JointGoalEntry, ReachJointEnv
from latentrl.errors import LatentRLError
from latentrl.motion.checkpoint import load_motion_model
from latentrl.motion.skeleton import FPS
from latentrl.optim.refine import (
    Footsteps,
    RefineSettings,
    goal_targets,
    landing_loss,
    predict,
    refine,
    refining,
)

ENTRY = JointGoalEntry("walk", (JointGoal("pelvis", (0.3, 0.5, 0.8), 6 / FPS),
                                JointGoal("left_foot", (0.1, 0.9), 12 / FPS),
                                JointGoal("right_hand", (0.2, 1.0, 1.0), 30 / FPS)))


@pytest.fixture(scope="module")
def model64():
    """The embedded default model in float64: its feet plant (the lock acts; the tiny model's random feet
    never touch the floor), and finite differences need the precision."""
    m = copy.deepcopy(load_motion_model("default")).double()
    assert m.floor_snap is not None
    return m


def start64(model, n: int, gen: torch.Generator):
    """The model's initial state in float64 (``initial_state`` builds float32 transforms)."""
    s = model.initial_state(n, gen)
    world = type(s.world)(s.world.rotation.double(), s.world.translation.double())
    return s._replace(history=s.history.double(), world=world)


@pytest.mark.parametrize("lock", [False, True])
def test_post_processed_differentiable_step_places_the_primitive_as_rollout_step_does(model64, lock):
    gen = torch.Generator().manual_seed(0)
    state = start64(model64, 3, gen)
    text = model64.encode_text(["walk"] * 3).double()
    noise = torch.randn(3, *model64.latent_shape, generator=gen, dtype=torch.float64)
    ref = model64.rollout_step(state, text, noise, foot_lock=lock)
    out = model64.differentiable_step(state, text, noise, post_process=True, foot_lock=lock)
    for a, b in ((out.joints_world, ref.joints_world), (out.future, ref.future), (out.state.history, ref.state.history),
                 (out.state.world.translation, ref.state.world.translation)):
        assert torch.allclose(a, b, atol=1e-9)
    plain = model64.differentiable_step(state, text, noise)
    moved = (plain.joints_world[..., :2] - out.joints_world[..., :2]).abs().max()
    assert (moved > 0.01) if lock else (moved < 1e-9)  # the lock slid the body back under a planted foot


def test_gradients_through_the_foot_lock_match_finite_differences(model64):
    gen = torch.Generator().manual_seed(1)
    state = start64(model64, 1, gen)
    text = model64.encode_text(["walk"]).double()
    noise = torch.randn(1, *model64.latent_shape, generator=gen, dtype=torch.float64)
    direction = torch.randn(noise.shape, generator=gen, dtype=torch.float64)

    def pelvis_x(z: torch.Tensor) -> torch.Tensor:
        out = model64.differentiable_step(state, text, z, post_process=True, foot_lock=True)
        return out.joints_world[0, -1, 0, 0] + out.state.world.translation[0, 1]

    z = noise.clone().requires_grad_(True)
    pelvis_x(z).backward()
    analytic = float((z.grad * direction).sum())
    eps = 1e-6
    with torch.no_grad():
        numeric = float(pelvis_x(noise + eps * direction) - pelvis_x(noise - eps * direction)) / (2 * eps)
    assert analytic == pytest.approx(numeric, rel=1e-4, abs=1e-8)


def make(model, n=2, **kwargs) -> ReachJointEnv:
    return ReachJointEnv(n, motion=model, goals=[ENTRY], max_episode_steps=8, autoreset_mode="Disabled",
                         foot_lock=True, **kwargs)


def test_upcoming_goals_list_the_goals_not_yet_due_with_their_offsets(tiny_model):
    env = make(tiny_model)
    env.reset(seed=0)
    goals = env.upcoming_goals()
    assert goals["offset"].tolist() == [[6, 12, 30]] * 2 and goals["valid"].all()
    assert goals["joint"][0].tolist() == [JOINTS["pelvis"], JOINTS["left_foot"], JOINTS["right_hand"]]
    assert goals["planar"][0].tolist() == [False, True, False]
    env.step(torch.zeros(2, tiny_model.latent_dim))  # the pelvis goal (frame 6) is due: the foot's is current
    goals = env.upcoming_goals()
    assert goals["offset"][:, :2].tolist() == [[4, 22]] * 2
    assert goals["valid"].tolist() == [[True, True, False]] * 2
    assert goals["target"][0, 0].tolist() == pytest.approx([0.1, 0.9, env.floor_height])


def test_upcoming_asap_goals_get_the_time_they_will_get(tiny_model):
    import math

    entry = JointGoalEntry("walk", (JointGoal("pelvis", (0.0, 0.3), 6 / FPS), JointGoal("left_foot", (0.1, 0.9), None),
                                    JointGoal("left_foot", (0.1, 2.1), None)))
    env = ReachJointEnv(1, motion=tiny_model, goals=[entry], max_episode_steps=8, autoreset_mode="Disabled")
    env.reset(seed=0)
    goals = env.upcoming_goals()
    assert goals["valid"].all() and goals["estimated"][0].tolist() == [False, True, True]
    # each leaves the previous goal's target at its time, at max_speed (at least a frame after it is current)
    first = max(6 + math.ceil(math.hypot(0.1, 0.6) / env.max_speed * FPS), 8 + 1)
    second = max(first + math.ceil(1.2 / env.max_speed * FPS - 1e-6), math.ceil(first / 8) * 8 + 1)
    assert goals["offset"][0].tolist() == [6, first, second] == [6, 22, 52]
    env.step(torch.zeros(1, tiny_model.latent_dim))  # the pelvis goal is due; the first footstep gets its time
    goals = env.upcoming_goals()
    assert goals["estimated"][0].tolist()[:2] == [False, True] and env.goal_record()[1][0, 1] >= 0


def test_goal_targets_hold_the_goals_in_the_horizon_footsteps_and_a_pace_target(tiny_model):
    env = make(tiny_model)
    env.reset(seed=0)
    t, steps, active = goal_targets(env, 16, pace=0.5)
    # rows: three goals, three footstep rows, the two frames after a footstep (2 x 3 rows), one pace row
    assert t.weights[0].tolist() == [1.0, 1.0, 0.0, 0.0, 1.0, 0.0] + [0.0, 1.0, 0.0] * 2 + [0.0] and active.all()
    assert t.masks[0, 7].tolist() == [1.0, 1.0, 0.0]  # held on its stone in x and y
    assert steps.on[0].tolist() == [False, True, False] and steps.frame[0, 1] == 11
    assert t.frames[0, :2].tolist() == [5, 11] and t.masks[0, 1].tolist() == [1.0, 1.0, 0.0]
    assert t.points[0, 4].tolist() == pytest.approx([0.1, 0.9, env.floor_height + 0.02])
    far = ReachJointEnv(1, motion=tiny_model, goals=[JointGoalEntry("walk", (JointGoal("pelvis", (0.0, 3.0), 2.0),))],
                        max_episode_steps=12, autoreset_mode="Disabled")
    far.reset(seed=0)
    t, _, active = goal_targets(far, 16, pace=0.5)
    now = far.history_world()[0, -1, 0]
    goal = torch.tensor([0.0, 3.0, far.floor_height])
    assert t.weights[0].tolist() == [0.0] * 4 + [0.5] and t.frames[0, -1] == 15
    # on the straight line, at the pace that arrives at frame 60
    assert t.points[0, -1].tolist() == pytest.approx((now + (goal - now) * 16 / 60).tolist(), abs=1e-6)
    _, _, active = goal_targets(far, 16, pace=0.0)
    assert not active.any()


def test_land_holds_the_foot_down_on_its_stone_for_that_many_frames_after_its_own(tiny_model):
    env = make(tiny_model)
    env.reset(seed=0)
    plain, _, _ = goal_targets(env, 16, pace=0.5)
    t, steps, active = goal_targets(env, 16, pace=0.5, land=6)
    # rows: three goals, three footstep rows, six frames after the footstep (6 x 3 rows; the footstep is due at
    # predicted frame 11 of 16, so frames 12-15 are held), one pace row
    assert t.weights[0].tolist() == [1.0, 1.0, 0.0, 0.0, 1.0, 0.0] + [0.0, 1.0, 0.0] * 4 + [0.0] * 6 + [0.0]
    assert t.frames[0, 7:19:3].tolist() == [12, 13, 14, 15] and t.masks[0, 7].tolist() == [1.0, 1.0, 1.0]
    assert t.points[0, 7].tolist() == pytest.approx([0.1, 0.9, env.floor_height + 0.02])  # on the floor
    assert torch.equal(t.points[:, :6], plain.points[:, :6]) and torch.equal(t.points[:, -1], plain.points[:, -1])
    assert active.all() and steps.on[0].tolist() == [False, True, False]
    with pytest.raises(LatentRLError, match="refine land: expected 0-16 frames, got 17"):
        RefineSettings(land=17).check()


def test_landing_loss_costs_a_foot_low_off_its_stone_only():
    joints = torch.zeros(4, 10, 22, 3)
    foot = JOINTS["left_foot"]
    stone = torch.tensor([0.0, 1.0])
    joints[..., foot, 1] = 1.0  # every frame on the stone, on the floor ...
    joints[1, 6, foot, :2] = torch.tensor([0.0, 0.8])  # ... but episode 1 comes down 20 cm short at frame 6
    joints[2, 6, foot] = torch.tensor([0.0, 0.8, 0.10])  # episode 2 passes 20 cm short, 10 cm up
    joints[3, 6, foot] = torch.tensor([0.0, 0.8, 0.015])  # episode 3 20 cm short, half way into the contact band
    steps = Footsteps(frame=torch.full((4, 1), 8), joint=torch.full((4, 1), foot),
                      on=torch.ones(4, 1, dtype=torch.bool), xy=stone.expand(4, 1, 2))
    loss = landing_loss(joints, steps, floor=0.0)
    huber = (0.2**2 + 0.01**2) ** 0.5 - 0.01
    assert loss.tolist() == pytest.approx([0.0, huber, 0.0, 0.5 * huber], abs=1e-6)
    off = steps._replace(on=torch.zeros(4, 1, dtype=torch.bool))
    assert landing_loss(joints, off, floor=0.0).tolist() == [0.0] * 4


def test_refine_lands_the_goal_closer_and_predicts_the_env_step_exactly():
    model = load_motion_model("default")
    probe = make(model, n=3)
    probe.reset(seed=0)
    zero = torch.zeros(3, model.latent_dim)
    with torch.no_grad():  # where zero noise puts the pelvis at frame 6: the target is 7.2 cm beside it
        at = predict(model, probe.step_inputs(), zero.reshape(1, 3, *model.latent_shape))[0, 5, 0]
    target = (float(at[0]) + 0.06, float(at[1]) + 0.04)  # a spot: the pelvis xy
    entry = JointGoalEntry("walk", (JointGoal("pelvis", target, 6 / FPS),))
    env = ReachJointEnv(3, motion=model, goals=[entry], max_episode_steps=8, autoreset_mode="Disabled",
                        foot_lock=True)
    env.reset(seed=0)
    refined = refine(env, zero, RefineSettings(steps=12, horizon=2, skate=0.0))  # the goal alone
    assert refined.shape == zero.shape and not torch.equal(refined, zero)
    with torch.no_grad():
        predicted = predict(model, env.step_inputs(), refined.reshape(1, 3, *model.latent_shape))
    _, _, _, _, infos = env.step(refined)
    after = infos["joint_error_m"]
    assert infos["goal_due"].all() and (after < 0.025).all(), after  # from 7.2 cm
    # the prediction (floor snap and foot lock included) is the step the env took
    assert (predicted[:, 5, 0, :2] - torch.tensor(target)).norm(dim=-1).tolist() == pytest.approx(after.tolist(),
                                                                                               abs=1e-4)


def test_the_skate_weight_trades_goal_error_for_planted_feet():
    from latentrl.evaluation.metrics import foot_skate_cm_s

    model = load_motion_model("default")
    entry = JointGoalEntry("walk", (JointGoal("pelvis", (0.1, 0.45), 16 / FPS),))
    skate = []
    for weight in (0.0, 5.0):
        env = ReachJointEnv(4, motion=model, goals=[entry], max_episode_steps=8, autoreset_mode="Disabled",
                            foot_lock=True)
        env.reset(seed=0)
        action = refine(env, torch.zeros(4, model.latent_dim), RefineSettings(steps=8, horizon=2, skate=weight))
        with torch.no_grad():
            plan = predict(model, env.step_inputs(), action.reshape(1, 4, *model.latent_shape))
        seen = torch.cat((env.history_world()[:, -1:], plan), dim=1)
        skate.append(float(foot_skate_cm_s(seen, FPS).mean()))
    assert skate[1] < 0.8 * skate[0], skate


def test_an_env_with_nothing_to_refine_leaves_the_others_as_they_would_be_alone(tiny_model):
    far = JointGoalEntry("walk", (JointGoal("pelvis", (0.0, 3.0), 2.0),))  # beyond the horizon, no pace target
    both = ReachJointEnv(2, motion=tiny_model, goals=[ENTRY, far], max_episode_steps=8, autoreset_mode="Disabled")
    alone = ReachJointEnv(1, motion=tiny_model, goals=[ENTRY], max_episode_steps=8, autoreset_mode="Disabled")
    both.reset(seed=0)
    alone.reset(seed=0)
    action = torch.full((2, tiny_model.latent_dim), 0.3)
    settings = RefineSettings(steps=4, horizon=2, pace=0.0)
    mixed = refine(both, action, settings)
    assert torch.isfinite(mixed).all() and torch.equal(mixed[1], action[1])
    assert torch.allclose(mixed[0], refine(alone, action[:1], settings)[0], atol=1e-6)


def test_step_inputs_lock_the_feet_as_the_env_steps_them(tiny_model):
    import copy

    from latentrl.motion.rollout import LOCK_MIN_WEIGHT

    model = copy.deepcopy(tiny_model)
    model.foot_lock = True  # a model locked by itself: an env without its own lock steps it locked
    env = ReachJointEnv(1, motion=model, goals=[ENTRY], foot_lock=False)
    env.reset(seed=0)
    inputs = env.step_inputs()
    assert inputs["foot_lock"] is None and inputs["lock_min_weight"] == LOCK_MIN_WEIGHT
    locked = ReachJointEnv(1, motion=model, goals=[ENTRY], foot_lock=True, foot_lock_min_weight=0.05)
    locked.reset(seed=0)
    assert locked.step_inputs()["foot_lock"] is True and locked.step_inputs()["lock_min_weight"] == 0.05


def test_zero_steps_and_nothing_to_refine_keep_the_policy_action(tiny_model):
    env = make(tiny_model)
    env.reset(seed=0)
    action = torch.randn(2, tiny_model.latent_dim)
    assert refine(env, action, RefineSettings(steps=0)) is action
    far = ReachJointEnv(2, motion=tiny_model, goals=[JointGoalEntry("walk", (JointGoal("pelvis", (0.0, 3.0), 2.0),))],
                        max_episode_steps=12, autoreset_mode="Disabled")
    far.reset(seed=0)
    assert torch.equal(refine(far, action, RefineSettings(steps=4, pace=0.0)), action)
    act = refining(env, lambda obs: torch.zeros(obs.shape[0], tiny_model.latent_dim), RefineSettings(steps=2))
    assert act(env.observation()).shape == (2, tiny_model.latent_dim)
    # start "zeros": the policy's action is ignored (the same result as a zero action)
    zeros = RefineSettings(steps=2, start="zeros")
    assert torch.equal(refine(env, action, zeros), refine(env, torch.zeros_like(action), zeros))
    # ... but a non-finite policy action is passed on for the env to refuse, whatever the start
    broken = action.clone()
    broken[1, 3] = float("nan")
    for start in ("zeros", "policy"):
        out = refine(env, broken, RefineSettings(steps=2, start=start))
        assert torch.isnan(out[1, 3]) and torch.isfinite(out[0]).all()
        assert torch.equal(out[0], refine(env, action, RefineSettings(steps=2, start=start))[0])
    from latentrl.errors import NonFiniteError

    with pytest.raises(NonFiniteError):
        env.step(refine(env, broken, zeros))


def test_auto_start_takes_the_policy_action_only_for_the_joints_it_was_trained_on(tiny_model):
    """Env 0's current goal is the pelvis, env 1's a foot: with ``auto`` the pelvis row refines as from the policy
    and the foot row as from zero noise; with every joint trained, both as from the policy."""
    foot = JointGoalEntry("walk", (JointGoal("left_foot", (0.1, 0.9), 12 / FPS),))
    env = ReachJointEnv(2, motion=tiny_model, goals=[ENTRY, foot], max_episode_steps=8, autoreset_mode="Disabled")
    env.reset(seed=0)
    action = torch.randn(2, tiny_model.latent_dim)
    auto = refine(env, action, RefineSettings(steps=2, start="auto", policy_joints=("pelvis",)))
    policy = refine(env, action, RefineSettings(steps=2, start="policy"))
    zeros = refine(env, action, RefineSettings(steps=2, start="zeros"))
    assert torch.equal(auto[0], policy[0]) and torch.equal(auto[1], zeros[1]) and not torch.equal(auto[1], policy[1])
    every = refine(env, action, RefineSettings(steps=2, start="auto", policy_joints=("pelvis", "left_foot")))
    assert torch.equal(every, policy)


@pytest.mark.parametrize("field, value, match", [
    ("steps", -1, "refine steps: expected 0-1000, got -1"),
    ("horizon", 0, "refine horizon: expected 1-16 primitives, got 0"),
    ("lr", 0.0, r"refine lr: expected a learning rate in \(0, 10\], got 0.0"),
    ("pace", -1.0, r"refine pace: expected a weight in \[0, 1000\], got -1.0"),
    ("skate", float("nan"), r"refine skate: expected a weight in \[0, 1000\], got nan"),
    ("start", "random", r"refine start: expected one of policy, zeros, auto, got 'random'"),
    ("policy_joints", ("pelvis", "tail"), r"refine policy joints: expected some of pelvis, .*, got 'tail'"),
])
def test_bad_settings_are_one_line_errors(field, value, match):
    with pytest.raises(LatentRLError, match=match):
        RefineSettings(**{field: value}).check()


def test_settings_of_takes_each_given_value_and_the_default_for_none():
    assert RefineSettings.of(8) == RefineSettings(steps=8)
    got = RefineSettings.of(32, 2, "auto", 3.0, None, 6, ("pelvis", "left_foot"))
    assert got == RefineSettings(steps=32, horizon=2, start="auto", skate=3.0, land=6,
                                 policy_joints=("pelvis", "left_foot"))
    assert got.pace == RefineSettings().pace
