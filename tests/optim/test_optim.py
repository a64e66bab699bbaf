"""Noise optimization: gradients, constraint kernels, the solver, the suite format and ``latentrl optimize``."""

import json
import re

import numpy as np
import pytest
import torch

from latentrl.app.cli import main
from latentrl.motion.clip import MotionClip
from latentrl.motion.skeleton import JOINT_NAMES, NUM_JOINTS
from latentrl.optim import FORMAT, OptimizeSettings, load_suite, optimize, parse_suite
from latentrl.optim.losses import constraint_loss, goal_error_cm
from latentrl.optim.problems import stack_targets
from latentrl.optim.solver import rollout, start_states
from latentrl.resources import suites_folder
from tests.helpers import make_tiny_model, walking_clip

NO_REG = {"floor": 0.0, "skate": 0.0, "jerk": 0.0, "prior": 0.0}


def suite(*problems) -> list:
    return parse_suite({"format": FORMAT, "problems": list(problems)})


def rows(frame: torch.Tensor) -> list:
    return frame.tolist()


@pytest.fixture(scope="module")
def model(tiny_model):
    return tiny_model  # tests/conftest.py


def target_problem(model, name="p", primitives=2, seed=5, text="walk", frame=None) -> dict:
    """A keyframe problem whose keyframe is a rollout of the model from noise the optimizer is not given."""
    g = torch.Generator().manual_seed(seed)
    z = torch.randn(primitives, 1, *model.latent_shape, generator=g)
    start = model.initial_state(1, seed_index=torch.tensor([0]))
    with torch.no_grad():
        joints, _ = rollout(model, start, [model.encode_text([text])] * primitives, z, 5.0)
    frame = primitives * 8 - 1 if frame is None else frame
    return {"name": name, "start": {"seed": 0}, "text": text, "primitives": primitives,
            "constraints": [{"type": "keyframe", "frame": frame, "joints": rows(joints[0, 2 + frame])}]}


def test_gradient_matches_finite_differences(model):
    """d loss / d noise through sampler (CFG), decoder, canonicalization and placement, against central differences."""
    m = make_tiny_model().double()
    p = suite(target_problem(model, primitives=2))
    targets = stack_targets(p)
    targets.points = targets.points.double()
    targets.masks = targets.masks.double()
    targets.weights = targets.weights.double()
    start = start_states(m, p)
    start = start._replace(history=start.history.double(),
                           world=type(start.world)(start.world.rotation.double(), start.world.translation.double()))
    emb = [m.encode_text(["walk"]).double()] * 2
    z0 = torch.randn(2, 1, *m.latent_shape, dtype=torch.float64, generator=torch.Generator().manual_seed(1))

    def loss_of(z):
        joints, _ = rollout(m, start, emb, z, 5.0)
        return constraint_loss(joints[:, 2:], targets).sum()

    z = z0.clone().requires_grad_(True)
    loss_of(z).backward()
    grad = z.grad.flatten()
    eps = 1e-5
    for k in (0, 7, m.latent_dim + 3, 2 * m.latent_dim - 1):
        dz = torch.zeros_like(z0).flatten()
        dz[k] = eps
        dz = dz.reshape(z0.shape)
        with torch.no_grad():
            fd = (loss_of(z0 + dz) - loss_of(z0 - dz)) / (2 * eps)
        assert float(fd) == pytest.approx(float(grad[k]), rel=1e-4, abs=1e-7)
    assert grad.abs().sum() > 0


def test_rl_path_has_no_autograd(model):
    """``rollout_step`` (the env's call) stays under no_grad even when its noise asks for gradients."""
    state = model.initial_state(2, seed_index=torch.tensor([0, 0]))
    z = torch.zeros(2, *model.latent_shape, requires_grad=True)
    out = model.rollout_step(state, model.encode_text(["walk", "run"]), z)
    assert not out.joints_world.requires_grad
    diff = model.differentiable_step(state, model.encode_text(["walk", "run"]), z)
    assert diff.joints_world.requires_grad


def test_constraint_losses_are_zero_exactly_on_a_motion_that_meets_them():
    joints = walking_clip(16)["joints"][None].float()  # (1, 16, 22, 3), a hand-made walk
    j = JOINT_NAMES.index
    probs = suite(
        {"name": "key", "primitives": 2,
         "constraints": [{"type": "keyframe", "frame": 9, "joints": rows(joints[0, 9])}]},
        {"name": "sub", "primitives": 2, "constraints": [{"type": "keyframe", "frame": 3, "joints": {
            "head": rows(joints[0, 3, j("head")]), "left_wrist": rows(joints[0, 3, j("left_wrist")])}}]},
        {"name": "joint", "primitives": 2, "constraints": [{"type": "joint", "frame": 12, "joint": "left_foot",
                                                             "position": rows(joints[0, 12, j("left_foot")])}]},
        {"name": "traj", "primitives": 2, "constraints": [{"type": "trajectory", "joint": "pelvis", "frames": [2, 6],
                                                            "positions": rows(joints[0, 2:7, 0]), "axes": "xy"}]},
    )
    for p in probs:
        t = stack_targets([p])
        assert float(constraint_loss(joints, t)[0]) == 0.0, p.name
        assert float(goal_error_cm(joints, t)[0]) == 0.0, p.name
        moved = joints.clone()
        moved[..., 0] += 0.03  # 3 cm along x
        assert float(constraint_loss(moved, t)[0]) > 0.0
        assert float(goal_error_cm(moved, t)[0]) == pytest.approx(3.0, abs=1e-4)
        lifted = joints.clone()
        lifted[..., 2] += 0.05
        expected = 0.0 if p.name == "traj" else 5.0  # the trajectory counts x and y only
        assert float(goal_error_cm(lifted, t)[0]) == pytest.approx(expected, abs=1e-4)


def test_tiny_model_optimization_lowers_keyframe_error_tenfold(model):
    p = suite(target_problem(model, primitives=2, seed=11))
    r = optimize(model, p, OptimizeSettings(steps=80, lr=0.1, init="zeros", weights=NO_REG))[0]
    start, end = r.metrics["goal_error_start_cm"], r.metrics["goal_error_cm"]
    assert start > 0.5  # a random tiny model moves little with its noise
    assert end <= start / 10, (start, end)
    assert r.metrics["history_error_cm"] == 0.0
    assert r.joints.shape == (2 + 16, NUM_JOINTS, 3)
    assert r.noise.shape == (2, model.latent_dim)


def test_batch_results_equal_one_at_a_time(model):
    probs = suite(target_problem(model, "a", seed=1), target_problem(model, "b", seed=2, text="run"),
                  target_problem(model, "c", seed=3, text="hop on left leg"))
    settings = OptimizeSettings(steps=6, lr=0.05, batch=3, samples=2)
    together = optimize(model, probs, settings)
    alone = [optimize(model, [p], OptimizeSettings(steps=6, lr=0.05, batch=1, samples=2))[0] for p in probs]
    for a, b in zip(together, alone):
        assert a.problem.name == b.problem.name
        np.testing.assert_allclose(a.noise, b.noise, atol=1e-4)
        assert a.metrics["goal_error_cm"] == pytest.approx(b.metrics["goal_error_cm"], abs=1e-3)


def test_start_from_a_motion_file_continues_its_frames(model, tmp_path):
    first = optimize(model, suite(target_problem(model, primitives=2)), OptimizeSettings(steps=1))[0]
    path = first.clip().save(tmp_path / "start.npz")
    clip = MotionClip.load(path)
    p = target_problem(model, name="cont", primitives=1)
    p["start"] = {"motion": str(path), "frame": 10}
    r = optimize(model, suite(p), OptimizeSettings(steps=1))[0]
    np.testing.assert_allclose(r.joints[:2], clip.joints[9:11], atol=1e-4)
    assert r.metrics["history_error_cm"] == pytest.approx(0.0, abs=1e-6)


def test_shipped_suites_load():
    folder = suites_folder("constraints")
    names = sorted(f.stem for f in folder.glob("*.json"))
    assert {"inbetween", "inbetween_mid", "joint_targets"} <= set(names)
    for name in names:
        problems = load_suite(folder / f"{name}.json")
        assert problems and all(p.frames.max() < p.num_frames for p in problems)


@pytest.fixture(scope="module")
def tiny_file(eval_files) -> str:
    return str(eval_files["motion"])  # the tiny model as a file (tests/conftest.py)


def test_optimize_command_writes_report_motions_and_plot(tiny_file, tmp_path, model):
    suite_path = tmp_path / "s.json"
    suite_path.write_text(json.dumps({"format": FORMAT, "problems": [target_problem(model, "one", seed=4),
                                                                     target_problem(model, "two", seed=6)]}))
    out = tmp_path / "out"
    code = main(["optimize", str(suite_path), "--motion", tiny_file, "--steps", "3", "--out", str(out),
                 "--no-progress", "--samples", "2"])
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    assert report["post_processing"] == "none"
    assert [e["name"] for e in report["problems"]] == ["one", "two"]
    for e in report["problems"]:
        clip = MotionClip.load(out / e["motion"])
        assert clip.frames == 2 + 16
        assert clip.meta["problem"] == e["name"]
        assert len(e["targets"]) == NUM_JOINTS and e["targets"][0]["motion_frame"] == 2 + 15
        assert e["metrics"]["steps"] == 3 and e["metrics"]["jerk_unconstrained"] > 0
    assert (out / "report.md").read_text().count("| one |") == 1
    assert (out / "optimize.png").read_bytes()[:4] == b"\x89PNG"


BAD = [
    ({"constraints": [{"type": "joint", "frame": 3, "joint": "left_hand", "position": [0, 0, 1]}]},
     r"constraints\[0\]\.joint: unknown joint 'left_hand'"),
    ({"constraints": [{"type": "joint", "frame": 16, "joint": "pelvis", "position": [0, 0, 1]}]},
     r"constraints\[0\]\.frame: 16 is outside \[0, 15\]"),
    ({"constraints": [{"type": "keyframe", "frame": 3, "joints": [[0, 0, 1]] * 21}]},
     r"constraints\[0\]\.joints: expected 22 rows"),
    ({"constraints": [{"type": "joint", "frame": 3, "joint": "pelvis", "position": [0, "NaN", 1]}]},
     r"position\[1\]: expected a finite number, got nan"),
    ({"constraints": [{"type": "trajectory", "frames": [2, 5], "joint": "pelvis", "positions": [[0, 0, 1]] * 3}]},
     r"positions: expected 4 rows"),
    ({"constraints": [{"type": "squat"}]}, r"constraints\[0\]\.type: expected one of keyframe, joint, trajectory"),
    ({"primitives": 0}, r"primitives: 0 is outside \[1, 64\]"),
    ({"text": ["walk"]}, r"text: expected one prompt or a list of 2"),
    ({"start": {"seed": 99}}, r"start\.seed 99 is outside the model's 1 seed histories"),
    ({"constraints": [{"type": "joint", "frame": 3, "joint": "pelvis", "position": [0, 0, 1], "axes": "xw"}]},
     r"axes: expected some of 'xyz'"),
]


@pytest.mark.parametrize("change,message", BAD, ids=[m[:30] for _, m in BAD])
def test_bad_suite_gives_one_line_and_exit_2(change, message, tiny_file, tmp_path, capsys):
    problem = {"name": "p", "start": {"seed": 0}, "text": "walk", "primitives": 2,
               "constraints": [{"type": "joint", "frame": 3, "joint": "pelvis", "position": [0, 0, 1]}]}
    problem.update(change)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"format": FORMAT, "problems": [problem]}).replace('"NaN"', "NaN"))
    out = tmp_path / "out"
    code = main(["optimize", str(path), "--motion", tiny_file, "--steps", "1", "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and re.search(message, err[0]), err
    assert not out.exists()


def test_bad_suite_file_and_flags(tmp_path, capsys):
    path = tmp_path / "s.json"
    path.write_text('{"format": "other/1", "problems": []}')
    assert main(["optimize", str(path), "--no-progress"]) == 2
    assert "format: expected 'latentrl.constraints/1'" in capsys.readouterr().err
    path.write_text("{")
    assert main(["optimize", str(path), "--no-progress"]) == 2
    assert "invalid JSON: " in capsys.readouterr().err
    assert main(["optimize", str(tmp_path / "missing.json"), "--no-progress"]) == 2
    assert "no such suite file" in capsys.readouterr().err
    assert main(["optimize", "joint_targets", "--floor", "-1", "--no-progress", "--out", str(tmp_path / "o")]) == 2
    assert "weights.floor: expected a finite number >= 0" in capsys.readouterr().err
    assert main(["optimize", "joint_targets", "--problem", "nope", "--no-progress"]) == 2
    assert "--problem 'nope': not in" in capsys.readouterr().err


def test_warm_start_takes_a_policys_clamped_noises(tmp_path):
    """``--init POLICY``: the first step starts from the shipped reach policy's actions, not from randn."""
    from latentrl.motion.checkpoint import load_motion_model
    from latentrl.optim.warm import pelvis_goal, policy_warm_start

    model = load_motion_model("default")
    problem = load_suite(suites_folder("constraints") / "joint_targets.json")[0]
    assert pelvis_goal(problem) == pytest.approx(tuple(problem.targets[-1, :2]))
    warm = policy_warm_start("reach_walk_default")
    z = warm(model, [problem])
    assert z.shape == (problem.primitives, 1, *model.latent_shape)
    assert float(z.abs().max()) <= 4.0 + 1e-6 and float(z.std()) > 0.2  # policy actions, not N(0, 0.1^2)
    r = optimize(model, [problem], OptimizeSettings(steps=1), warm_start=warm)[0]
    cold = optimize(model, [problem], OptimizeSettings(steps=1))[0]
    assert r.metrics["goal_error_start_cm"] != pytest.approx(cold.metrics["goal_error_start_cm"])


def test_warm_start_refuses_a_non_steering_policy(tmp_path, capsys):
    assert main(["optimize", "joint_targets", "--init", "joystick_walk_default", "--no-progress",
                 "--out", str(tmp_path / "o")]) == 2
    assert "expected 'zeros', 'randn' or a reach/path policy" in capsys.readouterr().err


def test_a_dart_checkpoint_optimizes_too(parity_dir):
    """DART's checkpoint layout (the parity model, with its mean-pose seed) goes through the same solver."""
    from latentrl.motion.checkpoint import load_motion_model
    from latentrl.motion.text import HashedTextEncoder, TableTextEncoder

    dart = load_motion_model(parity_dir / "mld_denoiser/mld_parity_A/checkpoint_1.pt")
    hashed = HashedTextEncoder(dart.text_dim)
    dart.text_encoder = TableTextEncoder({"walk": hashed.encode(["walk"])[0]}, name=hashed.name)
    r = optimize(dart, suite(target_problem(dart, primitives=2, seed=3)),
                 OptimizeSettings(steps=30, lr=0.1, init="zeros", weights=NO_REG))[0]
    assert r.metrics["goal_error_cm"] < r.metrics["goal_error_start_cm"] / 3


def test_bench_optimize_writes_rows_curves_and_plot(tmp_path, capsys):
    """``latentrl bench optimize`` on one shipped suite, 2 steps: a row with its figures, a curve, the plot."""
    out = tmp_path / "b.json"
    assert main(["bench", "optimize", "--suites", "joint_targets", "--steps", "2", "--cost-steps", "1",
                 "--models", "default", "--batches", "1", "--device", "cpu", "--json", str(out),
                 "--plot", str(tmp_path / "b.png")]) == 0
    data = json.loads(out.read_text())
    (row,) = data["suites"]
    assert row["suite"] == "joint_targets" and row["problems"] == 7 and row["goal_error_cm"] > 0
    assert row["history_error_cm"] == 0.0 and row["jerk_unconstrained"] > 0
    t, e = data["curves"]["joint_targets cold (cpu)"]
    assert len(t) == len(e) == 2 and t[1] > t[0] > 0
    (cost,) = data["cost"]
    assert cost["model"] == "default" and cost["seconds_per_100_steps_64_frames"] > 0
    assert (tmp_path / "b.png").read_bytes()[:4] == b"\x89PNG"
