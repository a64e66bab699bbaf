"""The sit / get-up task: its phases and successes on hand-made motion, its reward, observation and seat files, a
few training iterations of configs/sit.yaml and its evaluation (tiny model: the default model before v6 has no
"sit down" or "stand up")."""

import json
import math
from pathlib import Path

import gymnasium as gym
import pytest
import torch

from latentrl.app.cli import main
from latentrl.envs.sit import SEATED_PELVIS_ABOVE_SEAT_M, SeatSpec, SitEnv, load_seats
from latentrl.errors import ConfigError, DataError
from latentrl.evaluation.sit import seat_file_text, seat_suite
from latentrl.motion.skeleton import PELVIS
from latentrl.resources import packaged
from latentrl.rewards import RewardComposer, RewardInputs

CONFIG = packaged("configs", "sit.yaml")
# a seat 0.45 m high at (0, 2); a sitter faces -y, toward the start: the sit-down spot is (0, 1.6)
SEAT = SeatSpec((0.0, 2.0), 0.45, -90.0)


def frames(env: SitEnv, x: float, y: float, z: float, facing_deg: float = -90.0) -> torch.Tensor:
    """(N, 8, 22, 3) new frames with every joint at the given pelvis position but the hips, 0.1 m to either side
    of it so that the body faces ``facing_deg`` (SEAT's sitter facing by default)."""
    out = torch.zeros(env.num_envs, 8, 22, 3)
    out[..., 0], out[..., 1], out[..., 2] = x, y, z
    a = math.radians(facing_deg)
    right = torch.tensor([math.sin(a), -math.cos(a)]) * 0.1  # the body's right: forward turned -90 degrees
    out[..., 2, :2] += right  # SMPL joint 2: right hip; 1: left hip
    out[..., 1, :2] -= right
    return out


def step_hooks(env: SitEnv, future: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The task's part of a step on hand-made frames: (reached, terminated, success)."""
    reached = env._reached(future, env.goal_world.clone())
    done, success = env._advance_task(reached)
    return reached, done, success


def test_the_generator_seats_the_pelvis_where_the_task_expects_it():
    from latentrl.datasets.locomotion.skills import SEAT_HEIGHT_RANGE
    from latentrl.datasets.locomotion.skills import SEATED_PELVIS_ABOVE_SEAT_M as DATA

    assert SEATED_PELVIS_ABOVE_SEAT_M == DATA and SEAT_HEIGHT_RANGE == (0.2, 0.6)
    from latentrl.datasets.locomotion.config import SYNONYMS

    assert "sit down" in SYNONYMS["sit_down"] and "stand up" in SYNONYMS["stand_up"]


def test_phases_and_successes_on_hand_made_motion(tiny_model):
    env = SitEnv(1, motion=tiny_model, seats=[SEAT], hold_frames=12)
    env.reset(seed=0)
    stand = float(env._stand_z[0])
    texts = env.text_table.texts
    assert env.phase.tolist() == [0] and texts[int(env._text_idx[0])] == "walk"
    assert env.goal_world[0, :2].tolist() == pytest.approx([0.0, 1.6], abs=1e-6)  # 0.4 m in front of the seat
    # approach: within 0.3 m of the sit-down spot but facing the seat (+y), or 50 degrees off: not yet
    for facing in (90.0, -40.0):
        assert step_hooks(env, frames(env, 0.1, 1.5, stand, facing))[0].tolist() == [False]
    assert env.phase.tolist() == [0]
    # the pelvis passes within 0.3 m of the sit-down spot, its back to the seat (within 45 degrees)
    reached, done, _ = step_hooks(env, frames(env, 0.1, 1.5, stand, -130.0))
    assert reached.tolist() == [True] and not done.any() and env.phase.tolist() == [1]
    assert texts[int(env._text_idx[0])] == "sit down" and env.goal_world[0, :2].tolist() == [0.0, 2.0]
    seated = 0.45 + SEATED_PELVIS_ABOVE_SEAT_M
    # 8 seated frames, then a frame 6 cm too high breaks the hold, then 8 + 4 more: 12 in a row -> sit success
    assert step_hooks(env, frames(env, 0.1, 2.1, seated + 0.01))[0].tolist() == [False]
    assert int(env._hold[0]) == 8
    broken = frames(env, 0.1, 2.1, seated)
    broken[:, 0, :, 2] += 0.06
    assert step_hooks(env, broken)[0].tolist() == [False] and int(env._hold[0]) == 7
    assert step_hooks(env, frames(env, 0.0, 2.0, seated))[0].tolist() == [True]
    assert env.phase.tolist() == [2] and texts[int(env._text_idx[0])] == "stand up"
    assert env.goal_world[0, :2].tolist() == pytest.approx([0.0, 1.4], abs=1e-6)  # the leave point, 0.6 m out
    # stand: not yet upright, then upright
    assert not step_hooks(env, frames(env, 0.0, 1.9, 0.8 * stand))[0].any() and env.phase.tolist() == [2]
    step_hooks(env, frames(env, 0.0, 1.9, stand))
    assert env.phase.tolist() == [3] and texts[int(env._text_idx[0])] == "walk"
    # leave: upright but too close to the seat, then 0.7 m away -> get-up success ends the episode
    assert not step_hooks(env, frames(env, 0.0, 1.5, stand))[1].any()
    reached, done, success = step_hooks(env, frames(env, 0.0, 1.3, stand))
    assert reached.tolist() == done.tolist() == success.tolist() == [True]


def test_outside_the_radius_or_off_the_height_no_sit(tiny_model):
    env = SitEnv(2, motion=tiny_model, seats=[SEAT], hold_frames=8)
    env.reset(seed=0)
    env._phase[:] = 1
    seated = 0.45 + SEATED_PELVIS_ABOVE_SEAT_M
    future = torch.cat((frames(env, 0.35, 2.0, seated)[:1], frames(env, 0.0, 2.0, seated + 0.06)[:1]))
    assert step_hooks(env, future)[0].tolist() == [False, False] and env._hold.tolist() == [0, 0]


def test_pelvis_height_term_known_values():
    joints = torch.zeros(3, 10, 22, 3)
    joints[:, 2:, PELVIS, 2] = torch.tensor([0.5, 0.9, 0.7])[:, None]
    target = torch.tensor([0.55, 0.9, float("nan")])
    comp = RewardComposer(terms=("pelvis_height",))
    _, terms = comp(RewardInputs(joints, torch.zeros(3, 3), torch.zeros(3, dtype=torch.bool), torch.ones(3),
                                 pelvis_target=target))
    assert terms["pelvis_height"].tolist() == pytest.approx([-0.05, 0.0, 0.0])


def test_env_draws_seats_observes_them_and_registers(tiny_model):
    env = gym.make_vec("latentrl/Sit-v0", num_envs=64, vectorization_mode="vector_entry_point", motion=tiny_model)
    obs, _ = env.reset(seed=3)
    assert env.observation_layout["goal"] == (0, 4) and env.observation_layout["task"] == (4, 13)
    assert "scene_rays" in env.observation_layout
    seat = env.seat
    assert float(seat[:, 2].min()) >= 0.2 and float(seat[:, 2].max()) <= 0.6
    dist = torch.linalg.vector_norm(seat[:, :2], dim=-1)
    assert float(dist.min()) >= 1.5 - 1e-5 and float(dist.max()) <= 3.0 + 1e-5
    # the seat is the env's scene: its top is the terrain under its centre
    assert torch.allclose(env.scene.batch.height(seat[:, None, :2])[:, 0], seat[:, 2])
    fields = env.observation_fields
    assert torch.equal(obs[:, slice(*fields["seat_height"])][:, 0], seat[:, 2])
    assert obs[:, slice(*fields["phase"])].tolist() == [[1.0, 0.0, 0.0, 0.0]] * 64
    facing = obs[:, slice(*fields["seat_facing"])]
    assert torch.allclose(facing.norm(dim=-1), torch.ones(64), atol=1e-5)
    _, reward, _, _, infos = env.step(torch.zeros(64, 16))
    assert {"reward/pelvis_height", "reward/collision", "sit_success", "getup_success", "phase"} <= set(infos)
    assert torch.isfinite(reward).all()


def test_seat_files_and_bad_arguments(tiny_model, tmp_path):
    shipped = load_seats(packaged("tasks", "sit", "sit_seats.json"))
    assert shipped == seat_suite() and packaged("tasks", "sit", "sit_seats.json").read_text() == \
        seat_file_text(seat_suite())
    heights = [s.seat_height for s in shipped]
    assert min(heights) == 0.2 and max(heights) == 0.6
    for s in shipped:
        d, a = math.hypot(*s.center), math.degrees(math.atan2(s.center[1], s.center[0]))
        assert 1.5 <= d <= 3.0 and 30.0 <= a <= 150.0
    bad = tmp_path / "bad.json"
    for data, message in (([{"center": [0, 2], "seat_height": 2.0, "facing_deg": 0}],
                           "seat 0: field 'seat_height' must be metres in [0.05, 1.5], got 2.0"),
                          ([{"center": [0, 2], "seat_height": 0.4}], "seat 0: missing field 'facing_deg'"),
                          ({}, "expected a list of 1 to 1000 seats")):
        bad.write_text(json.dumps(data))
        with pytest.raises(DataError) as err:
            load_seats(bad)
        assert str(err.value).startswith(f"{bad}: ") and message in str(err.value)
    with pytest.raises(ConfigError, match="scene: the sit task places its own seat"):
        SitEnv(1, motion=tiny_model, scene="stairs_10")
    with pytest.raises(ConfigError, match=r"seat_height: must be \[min, max\]"):
        SitEnv(1, motion=tiny_model, seat_height=(0.6, 0.2))
    with pytest.raises(ConfigError, match="hold_frames"):
        SitEnv(1, motion=tiny_model, hold_frames=0)
    with pytest.raises(ConfigError, match=r"approach_facing_deg: must be degrees in \(0, 180\] or null"):
        SitEnv(1, motion=tiny_model, approach_facing_deg=270)


def test_any_facing_ends_the_approach_when_the_facing_is_not_asked(tiny_model):
    env = SitEnv(1, motion=tiny_model, seats=[SEAT], approach_facing_deg=None)
    env.reset(seed=0)
    assert step_hooks(env, frames(env, 0.1, 1.5, float(env._stand_z[0]), 90.0))[0].tolist() == [True]


def test_sit_config_trains_a_few_iterations_and_evaluates(eval_files, tmp_path, capsys):
    sets = [f"env.motion={eval_files['motion']}", "env.num_envs=4", "env.max_episode_steps=4", "ppo.num_steps=4",
            "ppo.total_steps=32", "ppo.num_minibatches=2", "ppo.update_epochs=1", "ppo.eval_every=2",
            "ppo.checkpoint_every=1", "policy.latent_dim=32", "eval.episodes=1", "eval.max_steps=2", "threads=1"]
    run = tmp_path / "run"
    assert main(["train", str(CONFIG), "--run-dir", str(run), "--no-progress",
                 *[x for s in sets for x in ("--set", s)]]) == 0, capsys.readouterr().err
    seats = tmp_path / "two.json"
    seats.write_text(seat_file_text(seat_suite()[:2]))
    out = tmp_path / "ev"
    assert main(["eval", str(run / "final.pt"), "--paths", str(seats), "--episodes", "2", "--max-steps", "3",
                 "--device", "cpu", "--out", str(out), "--no-progress"]) == 0, capsys.readouterr().err
    report = json.loads((out / "report.json").read_text())
    assert report["task"] == "sit" and report["criteria"]["hold_frames"] == 15
    entries = report["suites"][0]["entries"]
    assert len(entries) == 2 and all(len(e["episodes"]) == 2 for e in entries)
    assert {"sit_success", "getup_success", "getup_after_sit", "scene_penetration_max_cm"} <= set(report["overall"])
    for ep in (ep for e in entries for ep in e["episodes"]):  # the get-up rate of the episodes that sat
        m = ep["metrics"]
        assert m["getup_after_sit"] == (m["getup_success"] if m["sit_success"] else None)
    md = (out / "report.md").read_text()
    assert "sit_success (share)" in md and "getup_success (share)" in md
    motions = sorted(Path(out, "motions").glob("*.npz"))
    assert motions and all(m.stat().st_size > 0 for m in motions)
    planned = tmp_path / "ev_planned"  # the planned sit: its settings in the report
    assert main(["eval", str(run / "final.pt"), "--paths", str(seats), "--episodes", "1", "--max-steps", "2",
                 "--device", "cpu", "--out", str(planned), "--no-progress", "--sit-plan", "1",
                 "--sit-plan-samples", "2", "--sit-plan-getup", "1", "--sit-plan-approach", "0.5"]) == 0, \
        capsys.readouterr().err
    plan = json.loads((planned / "report.json").read_text())["sit_plan"]
    assert plan["steps"] == 1 and plan["samples"] == 2 and plan["primitives"] == 9 and plan["getup_primitives"] == 1
    assert plan["approach"] == 0.5 and plan["approach_primitives"] == 5
    assert main(["eval", str(run / "final.pt"), "--paths", str(seats), "--sit-plan", "4", "--sit-plan-samples",
                 "5000", "--out", str(tmp_path / "no")]) == 2
    assert "--sit-plan-samples: expected 0-1024, got 5000" in capsys.readouterr().err
    assert main(["eval", str(run / "final.pt"), "--paths", str(seats), "--sit-plan", "4", "--sit-plan-getup", "-1",
                 "--out", str(tmp_path / "no")]) == 2
    assert "--sit-plan-getup: expected 0-32, got -1" in capsys.readouterr().err
    assert main(["eval", str(run / "final.pt"), "--paths", str(seats), "--sit-plan", "4", "--sit-plan-approach", "9",
                 "--out", str(tmp_path / "no")]) == 2
    assert "--sit-plan-approach: expected metres in [0, 5], got 9.0" in capsys.readouterr().err


def test_list_shows_the_sit_task_and_its_suite(capsys):
    assert main(["list", "tasks"]) == 0
    assert any(line.split()[:2] == ["sit", "latentrl/Sit-v0"] for line in capsys.readouterr().out.splitlines())
    assert main(["list", "suites"]) == 0
    assert any(line.split()[:1] == ["sit"] and "sit_seats" in line for line in capsys.readouterr().out.splitlines())
    assert main(["list", "configs"]) == 0
    assert any(line.split()[:3] == ["sit", "latentrl", "train"] for line in capsys.readouterr().out.splitlines())


def test_restoring_the_episode_state_restores_the_seats(tiny_model):
    env = SitEnv(3, motion=tiny_model)
    env.reset(seed=1)
    saved, seats, rows = env.get_rng_state(), env.seat.clone(), env.scene.batch.box_center.clone()
    env.reset(seed=2)
    assert not torch.equal(env.seat, seats)
    env.set_rng_state(saved)
    assert torch.equal(env.seat, seats) and torch.allclose(env.scene.batch.box_center, rows)


def test_settle_steps_stand_still_before_the_sit_down(tiny_model):
    """With ``settle_steps: 2`` the two steps after the approach have ``stand still``, then ``sit down``; a new
    approach starts the count again."""
    env = SitEnv(1, motion=tiny_model, seats=[SEAT], settle_steps=2)
    env.reset(seed=0)
    texts = env.text_table.texts
    stand = float(env._stand_z[0])
    step_hooks(env, frames(env, 0.1, 1.5, stand, -130.0))  # the approach ends
    away = frames(env, 0.0, 0.5, stand)  # nowhere near the seat: phase 1 goes on
    seen = [texts[int(env._text_idx[0])]]
    for _ in range(3):
        step_hooks(env, away)
        seen.append(texts[int(env._text_idx[0])])
    assert env.phase.tolist() == [1] and seen == ["stand still", "stand still", "sit down", "sit down"]
    env.reset(seed=1)
    assert int(env._settle[0]) == 0 and texts[int(env._text_idx[0])] == "walk"
    with pytest.raises(ConfigError, match="settle_steps: must be an integer in"):
        SitEnv(1, motion=tiny_model, settle_steps=-1)
