"""latentrl: RL controllers whose actions are the latent noise of a frozen DART motion model."""

__version__ = "0.1.0"

import latentrl.envs.registration  # noqa: E402, F401  (registers the Gymnasium ids; imports no torch)
