"""PPO for latent-action envs: DART's actor-critic, a torch-native trainer and an SB3 path.

Sees only the Gymnasium ``VectorEnv`` interface (and SB3's ``VecEnv`` for the SB3 path); never
imports ``latentrl.envs`` or ``latentrl.motion``. The SB3 modules are imported lazily.
"""

from latentrl.ppo.checkpoint import LoadedPolicy, load_policy
from latentrl.ppo.config import BatchPlan, PolicyConfig, PPOConfig
from latentrl.ppo.policy import ActionEvaluation, ActorCritic, PolicyOutput, PolicyStep
from latentrl.ppo.run import make_trainer, train
from latentrl.ppo.storage import Batch, RolloutBuffer
from latentrl.ppo.trainer import NativeTrainer, TrainResult

__all__ = [
    "ActionEvaluation", "ActorCritic", "Batch", "BatchPlan", "LoadedPolicy", "NativeTrainer", "PPOConfig",
    "PolicyConfig", "PolicyOutput", "PolicyStep", "RolloutBuffer", "TrainResult", "load_policy", "make_trainer",
    "train",
]
