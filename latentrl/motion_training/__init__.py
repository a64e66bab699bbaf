"""Training a motion model (VAE, then latent denoiser) on a motion-text dataset: configs, losses, the trainer.

Beside :mod:`latentrl.datasets` (its data) and above :mod:`latentrl.motion` (the frozen runtime it
produces a model for); ``latentrl motion train`` is its command.
"""
