"""The application layer: the body of every ``latentrl`` command, and the wiring of envs to trainers.

Each command is a function taking one request dataclass (``TrainRequest``, ``EvalRequest``, ...);
:mod:`latentrl.app.cli` only turns arguments into requests, and commands call each other with
requests, never with argv. Nothing outside this package imports it.
"""
