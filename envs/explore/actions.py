"""The env's actions: their spaces and the check that turns a step's actions into commands.

Both robots act every step. An action is a normalised ``(v, ω)`` command in ``[-1, 1]²``
(``action_type="continuous"``, values outside are clipped) or the index of one of
:data:`DISCRETE_ACTIONS` (``"discrete"``); the robots scale it by ``max_speed`` and
``max_turn_rate``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

DISCRETE_ACTIONS = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [-1.0, 0.0]])
"""``(v, ω)`` of each discrete action: stop, forward, turn left, turn right, backward."""


def action_space(action_type: str) -> spaces.Space:
    """``Box(-1, 1, (2,))`` for ``"continuous"``, ``Discrete(5)`` for ``"discrete"``."""
    if action_type == "continuous":
        return spaces.Box(-1.0, 1.0, (2,), np.float32)
    return spaces.Discrete(len(DISCRETE_ACTIONS))


def parse_actions(actions: Any, live: Sequence[str], agents: Sequence[str], action_type: str
                  ) -> list[tuple[float, float]]:
    """The ``(v, ω)`` command of each of ``agents``, in their order, from a step's ``actions``
    (a dict with one action per ``live`` agent; the live agents are all of ``agents`` while
    the episode runs).

    Raises:
        TypeError: ``actions`` not a dict, or an action of the wrong type.
        ValueError: an unknown or finished agent, a missing one, an action of the wrong shape,
            out of range (discrete) or not finite.
    """
    if not isinstance(actions, dict):
        raise TypeError(f"actions must be a dict {{agent: action}}, got "
                        f"{type(actions).__name__}")
    if not (len(actions) == len(live) and all(a in actions for a in live)):
        unknown = sorted(str(a) for a in actions if a not in live)
        if unknown:
            raise ValueError(f"actions has unknown or finished agents {unknown}; live agents: "
                             f"{list(live)}")
        missing = [a for a in live if a not in actions]
        if missing:
            raise ValueError(f"actions is missing agents {missing}; every live agent acts "
                             f"every step")
    return [parse_action(agent, actions[agent], action_type) for agent in agents]


def parse_action(agent: str, action: Any, action_type: str) -> tuple[float, float]:
    """One agent's normalised ``(v, ω)`` command (errors as :func:`parse_actions`)."""
    if action_type == "discrete":
        if isinstance(action, (bool, np.bool_)) or not isinstance(
                action, (int, np.integer)) and not (
                isinstance(action, np.ndarray) and action.shape == ()
                and np.issubdtype(action.dtype, np.integer)):
            raise TypeError(f"action of {agent} must be an int in [0, "
                            f"{len(DISCRETE_ACTIONS)}), got {action!r}")
        a = int(action)
        if not 0 <= a < len(DISCRETE_ACTIONS):
            raise ValueError(f"action of {agent} must be in [0, {len(DISCRETE_ACTIONS)}), "
                             f"got {a}")
        v, w = DISCRETE_ACTIONS[a]
        return float(v), float(w)
    try:
        arr = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"action of {agent} must be a numeric (v, w) pair, got "
                        f"{action!r}") from exc
    if arr.shape != (2,):
        raise ValueError(f"action of {agent} must have shape (2,) (v, w), got shape "
                         f"{arr.shape}")
    v, w = arr.tolist()
    if not (math.isfinite(v) and math.isfinite(w)):
        raise ValueError(f"action of {agent} must be finite, got {[v, w]}")
    return min(max(v, -1.0), 1.0), min(max(w, -1.0), 1.0)
