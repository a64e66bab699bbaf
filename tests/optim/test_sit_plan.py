"""The planned sit (``latentrl.optim.sit_plan``): the plan the env executes is the plan it predicted, texts and all;
the best draw is kept and the optimizer only improves on it; outside the sit phase the policy acts; the loss's
known answers; bad settings in one line (tiny model: the default model has no sit)."""

import math

import pytest
import torch

from latentrl.envs.sit import SEATED_PELVIS_ABOVE_SEAT_M, SitEnv
from latentrl.errors import LatentRLError
from latentrl.motion.skeleton import PELVIS
from latentrl.optim.refine import inputs_rows, predict
from latentrl.optim.sit_plan import (
    LEAVE_MARGIN_M,
    PlanGoals,
    SitPlanner,
    SitPlanSettings,
    plan_goals,
    plan_loss,
    plan_sits,
)
from latentrl.scenes.scene import SceneBatch
from tests.envs.test_sit import SEAT, frames, step_hooks


def sitting_env(model, n: int = 2, settle: int = 2) -> SitEnv:
    """``n`` envs whose approach just ended (the next ``settle`` steps are ``stand still``, then ``sit down``)."""
    env = SitEnv(n, motion=model, seats=[SEAT], settle_steps=settle, autoreset_mode="Disabled",
                 record_history=True, max_episode_steps=64)
    env.reset(seed=0)
    step_hooks(env, frames(env, 0.1, 1.5, float(env._stand_z[0]), -130.0))  # the approach ends (hand-made)
    assert env.phase.tolist() == [1] * n
    return env


def zeros(env):
    return lambda obs: torch.zeros(env.num_envs, env.single_action_space.shape[0])


def test_the_plans_texts_are_the_settle_steps_left_then_the_sit(tiny_model):
    env = sitting_env(tiny_model, settle=2)
    rows = env.plan_texts(torch.arange(2), 5)
    texts = env.text_table.texts
    assert [texts[int(r)] for r in rows[:, 0]] == ["stand still"] * 2 + ["sit down"] * 3
    assert rows.shape == (5, 2) and torch.equal(rows[:, 0], rows[:, 1])


def test_the_env_executes_the_plan_it_predicted(tiny_model):
    """Stepping the env with the planned noises gives the predicted frames (settle texts, then the sit's)."""
    env = sitting_env(tiny_model)
    settings = SitPlanSettings(steps=2, samples=3, primitives=4, hold=8)
    idx = torch.arange(2)
    z = plan_sits(env, idx, settings)
    assert z.shape == (4, 2, *tiny_model.latent_shape)
    with torch.no_grad():
        texts = env.text_table.embeddings[env.plan_texts(idx, 4)]
        predicted = predict(tiny_model, inputs_rows(env.step_inputs(), idx), z, texts)
    planner = SitPlanner(env, zeros(env), settings)
    for s in range(4):
        env.step(planner(env.observation()))
        assert torch.allclose(env.history_world(), predicted[:, 8 * s + 6:8 * s + 8], atol=1e-5)  # its last 2 frames
    assert planner.planned == 2


def test_the_best_draw_is_kept_and_the_optimizer_only_lowers_its_loss(tiny_model):
    env = sitting_env(tiny_model, n=1)
    idx = torch.arange(1)
    goals, scene = plan_goals(env, idx), env.scene.batch
    texts = env.text_table.embeddings[env.plan_texts(idx, 3)]

    def loss_of(z, settings):
        with torch.no_grad():
            joints = predict(tiny_model, inputs_rows(env.step_inputs(), idx), z, texts)
            return float(plan_loss(joints, z, goals, scene, env.floor_height, settings))

    drawn = SitPlanSettings(steps=0, samples=6, primitives=3, hold=8)
    best = plan_sits(env, idx, drawn)
    g = torch.Generator().manual_seed(0)  # the planner's own draws (seed 0, first call)
    draws = torch.randn(6, 3, 1, *tiny_model.latent_shape, generator=g).clamp(-env.action_bound, env.action_bound)
    each = [loss_of(d, drawn) for d in draws]
    assert loss_of(best, drawn) == pytest.approx(min(each), rel=1e-5)
    tuned = SitPlanSettings(steps=6, samples=6, primitives=3, hold=8)
    assert loss_of(plan_sits(env, idx, tuned), tuned) <= min(each) + 1e-6


def test_outside_the_planned_phases_the_policy_acts_and_a_plan_is_dropped(tiny_model):
    env = SitEnv(2, motion=tiny_model, seats=[SEAT], autoreset_mode="Disabled", record_history=True)
    obs, _ = env.reset(seed=0)
    action = torch.full((2, env.single_action_space.shape[0]), 0.3)
    planner = SitPlanner(env, lambda o: action, SitPlanSettings(steps=1, samples=2, primitives=3, hold=4,
                                                                  getup_primitives=0))
    assert torch.equal(planner(obs), action) and planner.planned == 0  # the approach: the policy's
    env._phase[1] = 1  # env 1 begins its sit: planned, env 0 still the policy's
    out = planner(obs)
    assert planner.planned == 1 and torch.equal(out[0], action[0]) and not torch.equal(out[1], action[1])
    assert int(planner.cursor[1]) == 1 and int(planner.length[1]) == 3
    env._phase[1] = 2  # it sat: the rest of its plan is dropped, the policy stands it up (get-up not planned)
    assert torch.equal(planner(obs), action) and int(planner.length[1]) == 0
    env._phase[1] = 1
    planner(obs)
    assert planner.planned == 2  # sitting again: a new plan


def test_the_get_up_is_planned_in_plans_of_its_own_length_one_per_phase(tiny_model):
    env = SitEnv(1, motion=tiny_model, seats=[SEAT], autoreset_mode="Disabled", record_history=True)
    obs, _ = env.reset(seed=0)
    planner = SitPlanner(env, zeros(env), SitPlanSettings(steps=0, samples=2, primitives=4, hold=4,
                                                          getup_primitives=2))
    texts = env.text_table.texts
    env._phase[0] = 2  # standing up
    assert [texts[int(r)] for r in env.plan_texts(torch.arange(1), 2)[:, 0]] == ["stand up"] * 2
    planner(obs)
    assert planner.planned == 1 and int(planner.length[0]) == 2 and int(planner.phase[0]) == 2
    env._phase[0] = 3  # stood: the walk away gets a new plan at once
    planner(obs)
    assert planner.planned == 2 and int(planner.phase[0]) == 3 and int(planner.cursor[0]) == 1
    assert [texts[int(r)] for r in env.plan_texts(torch.arange(1), 2)[:, 0]] == ["walk"] * 2


def test_an_env_that_got_up_is_left_to_the_policy_until_it_is_reset(tiny_model):
    """An evaluation without autoreset steps an ended env on: its walk away is not planned again."""
    env = SitEnv(1, motion=tiny_model, seats=[SEAT], autoreset_mode="Disabled", record_history=True)
    obs, _ = env.reset(seed=0)
    action = torch.full((1, env.single_action_space.shape[0]), 0.3)
    planner = SitPlanner(env, lambda o: action, SitPlanSettings(steps=0, samples=2, primitives=3, hold=4))
    env._phase[0] = 3
    env._events = {"left": torch.tensor([True])}  # the step that just ended: the get-up success
    assert torch.equal(planner(obs), action) and planner.planned == 0
    env._events = {"left": torch.tensor([False])}  # the steps after it
    assert torch.equal(planner(obs), action) and planner.planned == 0
    env.reset(seed=1)
    planner(obs)  # the approach of the next episode: the policy's, and the mark is gone
    env._phase[0] = 3
    planner(obs)
    assert planner.planned == 1


def test_a_plan_that_ran_out_is_made_again_while_the_env_still_sits(tiny_model):
    env = sitting_env(tiny_model, n=1, settle=0)
    planner = SitPlanner(env, zeros(env), SitPlanSettings(steps=0, samples=2, primitives=2, hold=4))
    for _ in range(3):
        planner(env.observation())  # the env is not stepped: it stays in its sit phase
    assert planner.planned == 2 and int(planner.cursor[0]) == 1


def test_a_non_finite_action_goes_through_for_the_env_to_refuse(tiny_model):
    env = sitting_env(tiny_model, n=1)
    bad = torch.full((1, env.single_action_space.shape[0]), float("nan"))
    planner = SitPlanner(env, lambda o: bad, SitPlanSettings(steps=1, samples=1, primitives=2, hold=4))
    assert torch.isnan(planner(env.observation())).all() and planner.planned == 0


def test_the_loss_is_zero_at_each_goal_and_pulls_only_beyond_its_slack():
    """Known answers with the regularizers off. Sit: the pelvis at its seated point, 0.05 m inside the slack, 0.1 m
    beyond it (the pseudo-Huber distance of 0.1 m) or 0.1 m too high. Stand: at or above the upright height, or
    0.1 m under it. Leave: upright and far enough, or 0.1 m too near the seat."""
    seat = torch.tensor([[0.0, 2.0, 0.45 + SEATED_PELVIS_ABOVE_SEAT_M]])
    settings = SitPlanSettings(hold=4, collision=0.0, floor=0.0, skate=0.0, prior=0.0, slack=0.1)
    noise = torch.zeros(1, 1, 1, 4)
    scene = SceneBatch.empty(1, boxes=1)
    leave = 0.6 + LEAVE_MARGIN_M

    def loss(phase, pelvis, early=None):
        j = torch.zeros(1, 16, 22, 3)
        j[:, :, PELVIS] = torch.tensor(pelvis)
        if early is not None:  # the first frames, before the goal's own frames
            j[:, :4, PELVIS] = torch.tensor(early)
        goals = PlanGoals(torch.tensor([phase]), seat, torch.tensor([0.8]), torch.tensor([leave]), SPOT, FACING)
        return float(plan_loss(j, noise, goals, scene, 0.0, settings))

    huber = (0.1**2 + 0.01**2) ** 0.5 - 0.01
    z = float(seat[0, 2])
    assert loss(1, [0.0, 2.0, z]) == 0.0 and loss(1, [0.05, 2.0, z]) == 0.0
    assert loss(1, [0.2, 2.0, z]) == pytest.approx(huber, rel=1e-5)
    assert loss(1, [0.0, 2.0, z + 0.1]) == pytest.approx(huber, rel=1e-5)
    assert loss(1, [0.0, 2.0, z], early=[0.0, 2.0, 1.5]) == 0.0  # off only before the held frames: not counted
    assert loss(2, [0.0, 2.2, 0.8]) == 0.0 and loss(2, [0.0, 2.2, 0.9]) == 0.0
    assert loss(2, [0.0, 2.2, 0.7]) == pytest.approx(huber, rel=1e-5)
    assert loss(3, [0.0, 2.0 + leave, 0.85]) == 0.0
    assert loss(3, [0.0, 2.0 + leave - 0.1, 0.85]) == pytest.approx(huber, rel=1e-4)
    assert loss(3, [0.0, 2.0 + leave - 0.1, 0.85], early=[0.0, 2.0, 0.4]) == pytest.approx(huber, rel=1e-4)


SPOT = torch.tensor([[0.0, 1.6, 0.0]])
"""The sit-down spot of the loss tests: 0.4 m in front of a seat at (0, 2) whose sitter faces -y."""
FACING = torch.tensor([[0.0, -1.0]])


def test_the_approach_loss_is_zero_at_the_spot_turned_to_the_facing_and_counts_the_turn_left():
    """Known answers: at the spot facing -y 0; 0.1 m beyond the slack the pseudo-Huber distance; a quarter turn
    off costs ``facing`` x 1, a half turn ``facing`` x 2 (1 - cos)."""
    settings = SitPlanSettings(hold=4, collision=0.0, floor=0.0, skate=0.0, prior=0.0, slack=0.1, facing=0.5)
    goals = PlanGoals(torch.tensor([0]), torch.zeros(1, 3), torch.tensor([0.8]), torch.tensor([0.7]), SPOT, FACING)
    noise, scene = torch.zeros(1, 1, 1, 4), SceneBatch.empty(1, boxes=1)

    def loss(x, y, facing_deg):
        a = math.radians(facing_deg)
        j = torch.zeros(1, 16, 22, 3)
        j[..., 0], j[..., 1], j[..., 2] = x, y, 0.9
        right = torch.tensor([math.sin(a), -math.cos(a)]) * 0.1
        j[..., 2, :2] += right  # right hip; the left one mirrored
        j[..., 1, :2] -= right
        return float(plan_loss(j, noise, goals, scene, 0.0, settings))

    huber = (0.1**2 + 0.01**2) ** 0.5 - 0.01
    assert loss(0.0, 1.6, -90.0) == pytest.approx(0.0, abs=1e-6)
    assert loss(0.05, 1.6, -90.0) == pytest.approx(0.0, abs=1e-6)
    assert loss(0.2, 1.6, -90.0) == pytest.approx(huber, rel=1e-4)
    assert loss(0.0, 1.6, 0.0) == pytest.approx(0.5, rel=1e-4)
    assert loss(0.0, 1.6, 90.0) == pytest.approx(1.0, rel=1e-4)


def test_the_seats_collision_weighs_approach_collision_in_approach_plans_and_collision_in_the_others():
    """The same joint 0.1 m inside a seat costs ``approach_collision`` / ``collision`` times its depth."""
    from latentrl.scenes.contact import collision_cost
    from latentrl.scenes.scene import Box, Scene

    settings = SitPlanSettings(hold=4, floor=0.0, skate=0.0, prior=0.0, collision=1.0, approach_collision=10.0)
    scene = SceneBatch.from_scenes([Scene([Box(center=(0.0, 2.0), size=(0.5, 0.5, 0.45))])])
    j = torch.zeros(1, 16, 22, 3)
    j[..., 1] = 2.0  # every joint over the seat centre, 0.2 m above the floor: inside it
    j[..., 2] = 0.2
    j[..., 2, 0] += 0.1  # hips apart: a body axis for the approach's turn term
    j[..., 1, 0] -= 0.1
    cost = float(collision_cost(j, scene))
    noise = torch.zeros(1, 1, 1, 4)

    def loss(phase, **weights):
        goals = PlanGoals(torch.tensor([phase]), torch.tensor([[0.0, 2.0, 0.2]]), torch.tensor([0.0]),
                          torch.tensor([0.0]), torch.tensor([[0.0, 2.0, 0.0]]), FACING)
        return float(plan_loss(j, noise, goals, scene, 0.0, SitPlanSettings(**{**vars(settings), **weights})))

    assert cost > 0.1
    assert loss(1) - loss(1, collision=0.0) == pytest.approx(cost, rel=1e-4)
    assert loss(0) - loss(0, approach_collision=0.0) == pytest.approx(10.0 * cost, rel=1e-4)


def test_the_approach_is_planned_only_within_its_range_and_executes_its_plan(tiny_model):
    """Out of range the policy acts; within it a plan of ``approach_primitives`` walk steps replaces its action,
    and an env that walks out of range drops its plan."""
    env = SitEnv(1, motion=tiny_model, seats=[SEAT], autoreset_mode="Disabled", record_history=True)
    obs, _ = env.reset(seed=0)
    action = torch.full((1, env.single_action_space.shape[0]), 0.3)
    far = float((env.history_world()[0, -1, PELVIS, :2] - env.goal_world[0, :2]).norm())
    settings = SitPlanSettings(steps=1, samples=2, primitives=3, hold=4, approach=far - 0.1, approach_primitives=2)
    planner = SitPlanner(env, lambda o: action, settings)
    assert torch.equal(planner(obs), action) and planner.planned == 0  # 0.1 m out of range
    planner.settings = SitPlanSettings(steps=1, samples=2, primitives=3, hold=4, approach=far + 0.1,
                                       approach_primitives=2)
    texts = env.text_table.texts
    assert [texts[int(r)] for r in env.plan_texts(torch.arange(1), 2)[:, 0]] == ["walk"] * 2
    planned = planner(obs)
    assert planner.planned == 1 and int(planner.length[0]) == 2 and int(planner.phase[0]) == 0
    assert not torch.equal(planned, action) and torch.equal(planned[0], planner.plan[0, 0].flatten())
    planner.settings = settings  # out of range again: the plan is dropped, the policy acts
    assert torch.equal(planner(obs), action) and int(planner.length[0]) == 0


def test_the_settings_refuse_values_out_of_range_in_one_line(tiny_model):
    for field, value, match in (("steps", -1, "sit plan steps: expected 0-1000"),
                                ("samples", 2000, "sit plan samples: expected 0-1024"),
                                ("hold", 100, "sit plan hold: expected 1-72 frames"),
                                ("getup_primitives", 40, "sit plan getup primitives: expected 0-32"),
                                ("approach", -0.5, r"sit plan approach: expected metres in \[0, 5\]"),
                                ("approach_primitives", 0, "sit plan approach primitives: expected 1-32"),
                                ("facing", -1.0, r"sit plan facing: expected a weight in \[0, 1000\]"),
                                ("approach_collision", 2000.0,
                                 r"sit plan approach_collision: expected a weight in \[0, 1000\]"),
                                ("slack", 2.0, r"sit plan slack: expected metres in \[0, 1\]"),
                                ("lr", 0.0, r"sit plan lr: expected a learning rate in \(0, 10\]"),
                                ("floor", -1.0, r"sit plan floor: expected a weight in \[0, 1000\]")):
        with pytest.raises(LatentRLError, match=match):
            SitPlanSettings(**{field: value}).check()
    from latentrl.envs.reach import ReachLocationEnv

    env = ReachLocationEnv(1, motion=tiny_model)
    with pytest.raises(LatentRLError, match="has no sit phase"):
        SitPlanner(env, zeros(env), SitPlanSettings())
