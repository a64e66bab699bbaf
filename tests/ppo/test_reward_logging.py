"""TensorBoard's ``Episode_Reward/<term>`` and ``action/*`` read back from the events file of a tiny run."""

from types import SimpleNamespace

import pytest

from latentrl.ppo import train
from latentrl.ppo.contract import action_magnitude, reward_weights
from tests.ppo.conftest import tiny_policy, tiny_ppo
from tests.ppo.envs import NumpyVecEnv, ReachVecEnv
from tests.ppo.helpers import scalars

WEIGHTS = {"dist": 1.0, "success": 1.0, "effort": 0.01}


class WeightedReach(ReachVecEnv):
    """The test reach env naming its reward weights as latentrl's envs do (``env.rewards.weights``)."""

    rewards = SimpleNamespace(weights=WEIGHTS)


def test_action_magnitude_known_answers():
    assert action_magnitude([[3.0, 4.0, 0.0, 0.0]]) == pytest.approx((5.0, 1.0))  # |z| = 5 > sqrt(4) = 2
    assert action_magnitude([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]]) == pytest.approx((0.5, 0.0))
    assert action_magnitude([[[2.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 2.5]]]) == pytest.approx((2.25, 0.5))
    assert action_magnitude([]) is None


def test_weights_are_found_on_the_env_or_the_env_an_adapter_wraps():
    assert reward_weights(WeightedReach(2)) == WEIGHTS
    assert reward_weights(NumpyVecEnv(WeightedReach(2))) == WEIGHTS
    assert reward_weights(ReachVecEnv(2)) is None


@pytest.mark.parametrize("trainer", ["native", "sb3"])
def test_episode_reward_terms_add_up_to_the_episode_return(tmp_path, trainer):
    env = WeightedReach(8, max_episode_steps=6)
    run = tmp_path / trainer
    train(env if trainer == "native" else NumpyVecEnv(env), run, tiny_ppo(), tiny_policy(), trainer=trainer,
          progress=False)
    found = scalars(run)
    for name in WEIGHTS:
        assert [s for s, _ in found[f"Episode_Reward/{name}"]] == [64, 128], name
    # after the first rollout the window holds exactly its finished episodes: their mean return is the sum of
    # the weighted per-term episode sums (the env's reward is dist + success + 0.01 effort)
    first = sum(found[f"Episode_Reward/{name}"][0][1] for name in WEIGHTS)
    assert first == pytest.approx(found["rollout/ep_rew_mean"][0][1], rel=1e-4, abs=1e-5)
    assert found["Episode_Reward/effort"][0][1] < 0  # a penalty keeps its sign
    for tag in ("action/norm_mean", "action/beyond_shell"):
        assert [s for s, _ in found[tag]] == [64, 128], tag
    assert all(v > 0 for _, v in found["action/norm_mean"])
    assert all(0.0 <= v <= 1.0 for _, v in found["action/beyond_shell"])


def test_no_weights_no_episode_reward_tags(tmp_path):
    train(ReachVecEnv(8, max_episode_steps=6), tmp_path / "run", tiny_ppo(), tiny_policy(), progress=False)
    assert not [t for t in scalars(tmp_path / "run") if t.startswith("Episode_Reward/")]
