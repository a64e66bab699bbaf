"""Browser viewer (Viser): ``latentrl view`` plays motions, evaluations and runs; ``latentrl play`` steers a policy.

Optional: needs ``pip install 'latentrl[viewer]'``. Modules: ``sources`` (what PATH holds, no Viser),
``scene`` (skeleton, floor, trail, goals), ``playback`` (recorded motions), ``live`` (policy + motion
model in real time), ``server`` (start, URL, Ctrl-C) and ``commands`` (the two command bodies).
Nothing else in latentrl imports this package.
"""

from __future__ import annotations

from typing import Any

__all__ = ["play_command", "view_command"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from latentrl.viewer import commands

        return getattr(commands, name)
    raise AttributeError(f"module 'latentrl.viewer' has no attribute {name!r}")
