"""Teams of explorers by name: :data:`EXPLORERS` (the scripted ones) and :func:`make_team`
(also ``"sb3:PATH"``, a trained policy)."""

from __future__ import annotations

from typing import Any

from agents.base import Explorer
from agents.scripted import Blackboard, CoordinatedFrontier, Frontier, RandomWalk, WallFollower

EXPLORERS = {
    "random_walk": RandomWalk,
    "wall_follower": WallFollower,
    "frontier": Frontier,
    "coordinated_frontier": CoordinatedFrontier,
}
"""Scripted explorers by name (``make_team`` also accepts ``"sb3:PATH"``)."""


def make_team(name: str, action_type: str = "continuous", env: Any = None
              ) -> dict[str, Explorer]:
    """One explorer per robot, ``{"robot_0": ..., "robot_1": ...}``; the coordinated team
    shares one :class:`Blackboard`. With ``env``, each is bound to its robot of it
    (:meth:`agents.base.Explorer.bind`: the frontier explorers read their maps there)."""
    if name.startswith("sb3:"):
        from agents.sb3_explorer import SB3Explorer, sb3_team

        team = sb3_team(SB3Explorer.load_policy(name[4:]), action_type=action_type)
    elif name == "coordinated_frontier":
        board = Blackboard()
        team = {f"robot_{i}": CoordinatedFrontier(i, board, action_type=action_type)
                for i in range(2)}
    elif name not in EXPLORERS:
        raise ValueError(f"explorer must be one of {sorted(EXPLORERS)} or 'sb3:PATH', "
                         f"got {name!r}")
    else:
        team = {f"robot_{i}": EXPLORERS[name](action_type=action_type) for i in range(2)}
    if env is not None:
        for agent, explorer in team.items():
            explorer.bind(env, agent)
    return team
