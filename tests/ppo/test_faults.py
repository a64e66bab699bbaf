"""Faults during training: NaN/inf observations, rewards and losses stop the run and keep the last good
checkpoint; envs whose motion diverges are counted in TensorBoard and train.log."""

import math

import pytest
import torch

from latentrl.errors import NonFiniteError
from latentrl.ppo import train
from latentrl.ppo import update as ppo_update_module
from latentrl.ppo.checkpoint import read_checkpoint
from latentrl.ppo.sb3 import LatentActorCriticPolicy
from tests.ppo.conftest import tiny_policy, tiny_ppo
from tests.ppo.envs import NumpyVecEnv, ReachVecEnv
from tests.ppo.helpers import scalars


class FaultyEnv(ReachVecEnv):
    """ReachVecEnv whose ``quantity`` ('obs' or 'reward') of env 2 turns NaN/inf at global step ``at`` (1-based),
    and which reports env 0 as diverged every 4th step."""

    def __init__(self, at: int | None = None, quantity: str = "obs", value: float = math.nan):
        super().__init__(8, max_episode_steps=6)
        self.at, self.quantity, self.value, self.count = at, quantity, value, 0

    def step(self, actions):
        obs, reward, terminated, truncated, infos = super().step(actions)
        self.count += 1
        if self.count == self.at:
            obs, reward = obs.clone(), reward.clone()
            if self.quantity == "obs":
                obs[2, 5] = self.value
            else:
                reward[2] = self.value
        diverged = torch.zeros(self.num_envs, dtype=torch.bool)
        diverged[0] = self.count % 4 == 0
        infos.update(diverged=diverged, _diverged=torch.ones(self.num_envs, dtype=torch.bool))
        return obs, reward, terminated, truncated, infos


def snapshot(run):
    return {p.name: p.read_bytes() for p in sorted((run / "checkpoints").glob("iter_*.pt"))}


@pytest.mark.parametrize(("quantity", "value", "named"), [
    ("obs", math.nan, "observation of env 2 returned by rollout step 2 is nan"),
    ("reward", math.inf, "reward of env 2 at rollout step 2 is inf"),
])
def test_nonfinite_rollout_stops_native_training_keeping_the_last_checkpoint(tmp_path, quantity, value, named):
    run = tmp_path / "run"
    env = FaultyEnv(at=2 * 8 + 3, quantity=quantity, value=value)  # iteration 3, rollout step 2
    with pytest.raises(NonFiniteError, match=f"^iteration 3: {named}; training stopped without saving") as exc:
        train(env, run, tiny_ppo(total_steps=64 * 5), tiny_policy(), progress=False)
    assert f"last good checkpoint: {run / 'checkpoints' / 'iter_2.pt'}" in str(exc.value)
    assert exc.value.exit_code == 3
    assert sorted(snapshot(run)) == ["iter_1.pt", "iter_2.pt"] and not (run / "final.pt").exists()
    assert read_checkpoint(run / "checkpoints" / "iter_2.pt")["env_steps"] == 128
    assert "stopped: iteration 3: " + named in (run / "train.log").read_text()


def test_nan_loss_stops_native_training_and_resume_starts_from_the_last_good_checkpoint(tmp_path, monkeypatch):
    run, cfg = tmp_path / "run", tiny_ppo(total_steps=64 * 3, update_epochs=1)
    original, calls = ppo_update_module.ppo_loss, []

    def poisoned(policy, batch, c):
        terms = original(policy, batch, c)
        calls.append(1)
        if len(calls) == 3:  # iteration 2 (2 minibatches per iteration)
            return terms._replace(loss=terms.loss * math.nan, policy_loss=terms.policy_loss * math.nan)
        return terms

    monkeypatch.setattr(ppo_update_module, "ppo_loss", poisoned)
    with pytest.raises(NonFiniteError, match=r"^iteration 2: policy loss is nan \(value loss .*\); training stopped"):
        train(FaultyEnv(), run, cfg, tiny_policy(), progress=False)
    kept = snapshot(run)
    assert sorted(kept) == ["iter_1.pt"] and not (run / "final.pt").exists()
    state = read_checkpoint(run / "checkpoints" / "iter_1.pt")
    assert all(torch.isfinite(v).all() for v in state["policy"].values())
    monkeypatch.setattr(ppo_update_module, "ppo_loss", original)
    result = train(FaultyEnv(), run, cfg, tiny_policy(), resume=True, progress=False)
    assert (result.iterations, result.env_steps) == (3, 192)
    assert "start at iteration 1, 64 env steps" in (run / "train.log").read_text()


def test_diverged_envs_are_counted_in_tensorboard_and_train_log(tmp_path):
    run = tmp_path / "run"
    train(FaultyEnv(), run, tiny_ppo(), tiny_policy(), progress=False)
    # env 0 diverges at global steps 4 and 8 of each 8-step rollout: 2 per iteration
    assert scalars(run)["rollout/diverged"] == [(64, 2.0), (128, 2.0)]
    lines = [line for line in (run / "train.log").read_text().splitlines() if " | steps " in line]
    assert all(" | diverged 2 | " in line for line in lines) and len(lines) == 2


def test_sb3_stops_on_nan_observation_and_counts_nothing_it_is_not_told(tmp_path):
    run = tmp_path / "run"
    with pytest.raises(NonFiniteError, match=r"^iteration 2: observation of env 2 returned by rollout step 4 is nan"):
        train(NumpyVecEnv(FaultyEnv(at=8 + 5)), run, tiny_ppo(total_steps=64 * 3), tiny_policy(), trainer="sb3",
              progress=False)
    assert sorted(snapshot(run)) == ["iter_1.pt"] and not (run / "final.pt").exists()
    assert "rollout/diverged" not in scalars(run)  # NumpyVecEnv does not forward `diverged`


def test_sb3_stops_on_nan_loss(tmp_path, monkeypatch):
    run = tmp_path / "run"
    original = LatentActorCriticPolicy.evaluate_actions

    def poisoned(self, obs, actions):
        values, log_prob, entropy = original(self, obs, actions)
        return values, log_prob * math.nan, entropy

    monkeypatch.setattr(LatentActorCriticPolicy, "evaluate_actions", poisoned)
    with pytest.raises(NonFiniteError, match=r"^iteration 1: policy loss is nan .*last good checkpoint: none yet"):
        train(NumpyVecEnv(FaultyEnv()), run, tiny_ppo(), tiny_policy(), trainer="sb3", progress=False)
    assert not (run / "final.pt").exists() and snapshot(run) == {}


def test_real_env_divergence_is_reset_and_counted(tiny_model, tmp_path):
    from latentrl.envs import ReachLocationEnv, Sb3VecEnv

    def env():  # every joint lies beyond 1 mm of the origin: every step of every env diverges
        return ReachLocationEnv(4, motion=tiny_model, max_episode_steps=4, divergence_limit=1e-3)

    cfg = tiny_ppo(total_steps=32, num_steps=8, num_minibatches=2, update_epochs=1)
    train(env(), tmp_path / "native", cfg, tiny_policy(), progress=False)
    assert scalars(tmp_path / "native")["rollout/diverged"] == [(32, 32.0)]
    assert "| ep_len_mean 1 |" in (tmp_path / "native" / "train.log").read_text()  # terminated and reset each step
    train(Sb3VecEnv(env()), tmp_path / "sb3", cfg, tiny_policy(), trainer="sb3", progress=False)
    assert scalars(tmp_path / "sb3")["rollout/diverged"] == [(32, 32.0)]


def test_nonfinite_rollout_names_the_quantity_env_and_step():
    from latentrl.ppo.runner import nonfinite_rollout
    from latentrl.ppo.storage import RolloutBuffer

    buf = RolloutBuffer(4, 3, 5, 2)
    buf.final_obs[1, 2] = math.nan  # stale row: no episode ended there, so GAE never reads it
    assert nonfinite_rollout(buf) is None
    buf.dones[1, 2] = True
    assert nonfinite_rollout(buf) == "final observation of env 2 at rollout step 1 is nan"
    buf.obs[0, 1, 4] = -math.inf
    assert nonfinite_rollout(buf) == "observation of env 1 at the start of the rollout is -inf"
    buf.obs.fill_(3e38)  # sums overflow to inf, but every value is finite
    buf.final_obs.zero_()
    assert nonfinite_rollout(buf) is None
