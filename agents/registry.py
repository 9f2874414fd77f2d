"""Teams of explorers by name: :data:`EXPLORERS` (the scripted ones) and :func:`make_team`
(also ``"sb3:PATH"``, a trained policy), for teams of any size."""

from __future__ import annotations

from typing import Any

from agents.base import Explorer
from agents.scripted import (
    Blackboard,
    CoordinatedFrontier,
    Frontier,
    RandomWalk,
    WallFollower,
    robot_index,
)
from topo.validation import check_int

EXPLORERS = {
    "random_walk": RandomWalk,
    "wall_follower": WallFollower,
    "frontier": Frontier,
    "coordinated_frontier": CoordinatedFrontier,
}
"""Scripted explorers by name (``make_team`` also accepts ``"sb3:PATH"``)."""


def make_team(name: str, action_type: str = "continuous", env: Any = None,
              n_robots: int | None = None) -> dict[str, Explorer]:
    """One explorer per robot, ``{"robot_0": ..., "robot_<N-1>": ...}``; the coordinated team
    shares one :class:`Blackboard`.

    Args:
        name: a key of :data:`EXPLORERS` or ``"sb3:PATH"``.
        action_type: the env's ``action_type``.
        env: the env the team drives: its robots (``possible_agents``) make the team, and each
            explorer is bound to its robot (:meth:`agents.base.Explorer.bind`: the frontier
            explorers read their maps there).
        n_robots: the team size without ``env`` (default 2); with ``env`` it must match it.
    """
    if n_robots is not None:
        n_robots = check_int(n_robots, "n_robots", low=1)
    if env is not None:
        agents = list(getattr(env, "unwrapped", env).possible_agents)
        if n_robots is not None and n_robots != len(agents):
            raise ValueError(f"n_robots must match the env's team of {len(agents)} robots, "
                             f"got {n_robots}")
    else:
        agents = [f"robot_{i}" for i in range(2 if n_robots is None else n_robots)]
    if name.startswith("sb3:"):
        from agents.sb3_explorer import SB3Explorer, sb3_team

        # a team policy drives any team size (its teammates are a set)
        policy = SB3Explorer.load_policy(name[4:], n_robots=len(agents))
        team = sb3_team(policy, action_type=action_type, n_robots=len(agents))
    elif name == "coordinated_frontier":
        board = Blackboard()
        team = {a: CoordinatedFrontier(robot_index(a), board, action_type=action_type)
                for a in agents}
    elif name not in EXPLORERS:
        raise ValueError(f"explorer must be one of {sorted(EXPLORERS)} or 'sb3:PATH', "
                         f"got {name!r}")
    else:
        team = {a: EXPLORERS[name](action_type=action_type) for a in agents}
    if env is not None:
        for agent, explorer in team.items():
            explorer.bind(env, agent)
    return team

