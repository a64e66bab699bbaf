"""PPO for latent-action envs: DART's actor-critic, a torch-native trainer and an SB3 path.

rsl_rl's shape: :mod:`~latentrl.ppo.contract` (what an env must give), :mod:`~latentrl.ppo.algorithm`
(PPO in paper order), :mod:`~latentrl.ppo.runner` (loop, logging, eval, checkpoints, resume, guards)
shared by the backends :mod:`~latentrl.ppo.trainer` (native) and :mod:`~latentrl.ppo.sb3`, and the
trainer registry :data:`TRAINERS` in :mod:`~latentrl.ppo.run`.

Sees only the Gymnasium ``VectorEnv`` interface (and SB3's ``VecEnv`` for the SB3 path); never
imports ``latentrl.envs`` or ``latentrl.motion``. The SB3 modules are imported lazily.
"""

from latentrl.ppo.checkpoint import LoadedPolicy, load_policy
from latentrl.ppo.config import BatchPlan, PolicyConfig, PPOConfig
from latentrl.ppo.policy import ActionEvaluation, ActorCritic, PolicyOutput, PolicyStep
from latentrl.ppo.run import TRAINERS, make_trainer, register_trainer, train
from latentrl.ppo.runner import Runner, TrainResult
from latentrl.ppo.storage import Batch, RolloutBuffer
from latentrl.ppo.trainer import NativeTrainer

__all__ = [
    "ActionEvaluation", "ActorCritic", "Batch", "BatchPlan", "LoadedPolicy", "NativeTrainer", "PPOConfig",
    "PolicyConfig", "PolicyOutput", "PolicyStep", "RolloutBuffer", "Runner", "TRAINERS", "TrainResult", "load_policy",
    "make_trainer", "register_trainer", "train",
]
