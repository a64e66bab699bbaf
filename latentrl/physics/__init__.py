"""Physics in the loop (``pip install 'latentrl[physics]'``): latentrl's motion executed by a MuJoCo humanoid.

- :mod:`~latentrl.physics.humanoid`: the MJCF humanoid generated from latentrl's SMPL-22 rest skeleton;
- :mod:`~latentrl.physics.reference`: a motion's PD targets (joint rotations as hinge angles);
- :mod:`~latentrl.physics.tracker`: the untrained PD tracker with its reported root assist;
- :mod:`~latentrl.physics.tracking_env`, :mod:`~latentrl.physics.learned`: the learned tracker's env, config and
  evaluation (PPO on the project's runner);
- :mod:`~latentrl.physics.loop`: the closed loop, simulated frames fed back as the motion model's history.

Nothing here is imported by the kinematic path; MuJoCo itself is imported only by :func:`require_mujoco`.
"""

from __future__ import annotations

from latentrl.errors import ConfigError

INSTALL_HINT = "pip install 'latentrl[physics]'"


def require_mujoco():
    """The ``mujoco`` module, or a one-line :class:`ConfigError` saying how to install it."""
    try:
        import mujoco
    except ImportError:
        raise ConfigError(f"physics needs MuJoCo, which is not installed: {INSTALL_HINT}") from None
    return mujoco
