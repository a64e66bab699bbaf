"""A task defined here, outside the package, trains and evaluates through the ordinary commands.

``ToyEnv`` asks the body to reach a point straight ahead at a distance its config section sets; its
suites are JSON lists of ``{"text", "distance"}``. Registering its :class:`TaskSpec` is all it takes:
``latentrl train``'s code path (``run_training``) builds it from ``env.task: toy`` and ``env.options``,
runs its evaluator periodically, and ``latentrl eval`` judges the final policy with that evaluator.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pytest
import torch

from latentrl.app.cli import main
from latentrl.app.train import TrainConfig, run_training
from latentrl.config import require
from latentrl.envs.base import LatentMotionVectorEnv
from latentrl.envs.tasks import TASKS, TaskSpec, register_task
from latentrl.evaluation.episodes import end_of, rollout
from latentrl.evaluation.task_eval import TaskEpisode, TaskResult, aggregate, build_task_report, write_task_report
from latentrl.monitor import EvalReport
from latentrl.motion.checkpoint import save_motion_model


@dataclass
class ToyConfig:
    """``env.options`` of the toy task."""

    distance: float = 1.0

    def validate(self) -> None:
        require(self.distance > 0, "distance", f"must be > 0 metres, got {self.distance}")

    def kwargs(self) -> dict:
        return {"distance": self.distance}


class ToyEnv(LatentMotionVectorEnv):
    """Reach one point ``distance`` metres ahead of the start (+y)."""

    def __init__(self, num_envs: int = 1, *, distance: float = 1.0, **kwargs):
        self.distance = float(distance)
        super().__init__(num_envs, **kwargs)
        self._goal = torch.zeros(self.num_envs, 3, device=self.device)

    @property
    def goal_world(self) -> torch.Tensor:
        return self._goal

    def _reset_task(self, idx: torch.Tensor) -> None:
        self._text_idx[idx] = self._sample_texts(len(idx))
        start = self.history_world(idx)[:, -1, 0]
        self._goal[idx] = start + torch.tensor([0.0, self.distance, 0.0], device=self.device)
        self._goal[idx, 2] = self.floor_height

    def _goal_observation(self, history_world: torch.Tensor) -> torch.Tensor:
        return self._goal_features(history_world, self._goal)

    def _advance_task(self, reached: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return reached, reached


class ToyEvaluator:
    """Episodes of each ``{"text", "distance"}`` entry; the share that reached the point."""

    suite_kind = "toy"

    def load_suite(self, file: Path) -> list:
        return json.loads(Path(file).read_text())

    def default_suites(self, suites, texts):
        return suites

    def _env(self, motion, entry, n, settings):
        return ToyEnv(n, motion=motion, texts=(entry["text"],), distance=entry["distance"], device=settings.device,
                      max_episode_steps=settings.max_steps, autoreset_mode="Disabled", **settings.motion_kwargs())

    def fit(self, policy, motion, files, settings, observe_next):
        env = self._env(motion, self.load_suite(files[0])[0], 1, settings)
        assert policy.obs_dim == env.single_observation_space.shape[0]
        return False

    def run(self, act, motion, files, settings, *, observe_next, out_dir=None, render=0, motions=False):
        suites = []
        for file in files:
            results = []
            for index, entry in enumerate(self.load_suite(file)):
                env = self._env(motion, entry, settings.episodes, settings)
                outcome = rollout(env, act, settings.max_steps, settings.seed)
                episodes = [TaskEpisode(Path(file).stem, index, i, end_of(outcome, i), int(outcome["steps"][i]),
                                        {"reached": float(outcome["complete"][i])}) for i in range(env.num_envs)]
                results.append(TaskResult(Path(file).stem, index, entry["text"], episodes, 0.0))
            suites.append((Path(file).stem, str(file), results))
        return suites

    def report(self, results, settings, out_dir, **info):
        data = build_task_report("toy", results, settings, {"reached": "share"}, "reached: the point", **info)
        js, md = write_task_report(out_dir, data)
        return [f"wrote {js}, {md}"]

    def training_files(self, paths, suites):
        return [Path(p) for p in paths]

    def training_hook(self, files, motion, env_cfg, eval_cfg, device):
        from latentrl.evaluation.config import EvalSettings
        from latentrl.evaluation.runner import policy_fn

        settings = EvalSettings(episodes=eval_cfg.episodes, max_steps=eval_cfg.max_steps, device=str(device))
        settings.take_training_env(env_cfg)

        def evaluate(policy):
            suites = self.run(policy_fn(policy), motion, files, settings, observe_next=False)
            pooled = aggregate([ep for _, _, rs in suites for r in rs for ep in r.episodes])
            self.calls += 1
            return EvalReport({"reached": pooled["reached"]["mean"]}, {}, False)

        return evaluate

    calls = 0


@pytest.fixture
def toy_task():
    evaluator = ToyEvaluator()
    register_task(TaskSpec("toy", ToyEnv, ToyConfig, suite_kind="toy", evaluator=evaluator))
    yield evaluator
    del TASKS["toy"]


def test_a_task_defined_outside_the_package_trains_and_evaluates(toy_task, tiny_model, tmp_path, capsys):
    motion = save_motion_model(tiny_model, tmp_path / "tiny.pt")
    suite = tmp_path / "toy_near.json"
    suite.write_text(json.dumps([{"text": "walk", "distance": 0.2}, {"text": "walk", "distance": 3.0}]))
    cfg = TrainConfig(threads=1)
    cfg.env.task, cfg.env.num_envs, cfg.env.motion, cfg.env.max_episode_steps = "toy", 4, str(motion), 4
    cfg.env.options = {"distance": 0.5}
    cfg.policy.latent_dim = 16
    cfg.ppo.total_steps, cfg.ppo.num_steps, cfg.ppo.num_minibatches, cfg.ppo.update_epochs = 16, 4, 1, 1
    cfg.ppo.eval_every, cfg.eval.paths, cfg.eval.episodes, cfg.eval.max_steps = 1, [str(suite)], 2, 2
    cfg.ppo.checkpoint_every = 0
    result = run_training(cfg, tmp_path / "run", progress=False)
    assert result.iterations == 1 and toy_task.calls == 1  # one PPO iteration, evaluated by the toy evaluator

    out = tmp_path / "eval"
    assert main(["eval", str(result.final_checkpoint), "--paths", str(suite), "--episodes", "2", "--max-steps", "2",
                 "--device", "cpu", "--out", str(out), "--no-render", "--no-motions"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["task"] == "toy" and [e["label"] for e in report["suites"][0]["entries"]] == ["walk", "walk"]
    assert report["suites"][0]["entries"][0]["metrics"]["reached"]["n"] == 2
    assert "wrote" in capsys.readouterr().out


def test_the_toy_tasks_arguments_come_from_env_options(toy_task, tiny_model):
    from latentrl.envs.config import EnvConfig, build
    from latentrl.errors import ConfigError

    env = build(EnvConfig(task="toy", num_envs=1, options={"distance": 2.5}), "cpu", motion=tiny_model)
    assert isinstance(env, ToyEnv) and env.distance == 2.5
    with pytest.raises(ConfigError, match="options"):
        _ = EnvConfig(task="toy", options={"speed": 1.0}).section
    with pytest.raises(ConfigError, match=r"options.distance: must be > 0 metres, got -1"):
        EnvConfig(task="toy", options={"distance": -1.0}).validate()
    with pytest.raises(ConfigError, match=r"options: task 'reach' takes its arguments from env.reach"):
        EnvConfig(task="reach", options={"goal_angle_deg": 30}).validate()
