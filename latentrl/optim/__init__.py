"""Latent noise optimization: keyframes, joint targets and trajectories through the frozen motion model.

``load_suite`` reads a ``latentrl.constraints/1`` file, ``optimize`` solves its problems and ``write_outputs``
writes what ``latentrl optimize`` writes (docs/optimize.md).
"""

from latentrl.optim.problems import FORMAT, Problem, load_suite, parse_suite
from latentrl.optim.solver import OptimizeSettings, Result, optimize

__all__ = ["FORMAT", "OptimizeSettings", "Problem", "Result", "load_suite", "optimize", "parse_suite"]
