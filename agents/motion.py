"""The motion level's training env: velocity commands held a few steps, and an optional
shaping reward that pays progress along the path to the nearest frontier.

Learning exploration from velocity commands is slow for three reasons this wrapper addresses:

* **Horizon.** At 0.1 s a step, crossing a room takes 50–100 decisions, and a Gaussian policy's
  first moves average out to dithering in place. Holding each command ``hold`` steps (action
  repeat, as in Atari's frame skip) shortens the horizon by that factor.
* **Sparse credit.** The coverage reward arrives only once the robot reaches unseen space; on
  the way there, nothing says it is on the way. ``frontier_shaping`` adds the potential-based
  term ``k · (Φ(s') − Φ(s))`` with ``Φ = −(path length from the robot to the nearest
  reachable frontier of its own map, m)``, computed at every decision by the frontier
  planner's own costs (:func:`agents.frontier_planning.frontier_map`); a decision after which
  no frontier is reachable adds nothing (``Φ`` is kept). Shaping of this form guides without
  changing what is best to do (Ng, Harada & Russell, 1999): over an episode it sums to
  ``k · (d_0 − d_T)`` whatever the robot does, so it cannot be farmed. It is undiscounted on
  purpose: with ``γ · Φ(s')`` a robot standing still ``d`` metres from a frontier would earn
  ``k · (1 − γ) · d`` a decision, as much as driving towards it.
* **Exploration noise.** A Gaussian over ``(v, ω)`` centred on 0 drives backwards half the
  time (blind: the sonars face forward) and cancels its own moves. ``commands`` replaces the
  action by a choice among a few velocity commands (:data:`ARCS`: ahead, two arcs, two turns
  on the spot), so that even the untrained policy keeps moving.

The observation and the env's reward are kept (the shaping is added per robot, on top; train
with ``reward_mode="individual"``: before a merge the team reward pays nothing for robot 1's
exploration). Policies trained on it act on the plain env through
``agents.SB3Explorer``, each command held ``motion_hold`` steps as in training.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo.utils.wrappers import BaseParallelWrapper

from agents.frontier_planning import FrontierConfig, frontier_map
from topo.validation import check_int, check_real

ARCS = np.array([[1.0, 0.0], [0.7, 0.5], [0.7, -0.5], [0.0, 1.0], [0.0, -1.0]],
                dtype=np.float32)
"""``commands="arcs"``: ``(v, ω)`` in the env's units (fractions of the top speed and turn rate):
straight ahead, an arc left and right (radius ≈ 0.56 m at the defaults), on the spot left and
right."""


def frontier_distance(env: Any, agent: str, config: FrontierConfig) -> float:
    """Path length (m) from ``agent`` to the nearest reachable frontier cell of its own map
    (:func:`agents.frontier_planning.frontier_map`); ``inf`` when none is reachable."""
    snap = env.unwrapped.robot_map(agent)
    fmap = frontier_map(snap.grid, np.asarray(snap.odometry[:2]), config)
    if fmap is None or fmap.n_clusters == 0:
        return math.inf
    return float(np.where(fmap.labels > 0, fmap.cost_to, np.inf).min())


COMMANDS = ("continuous", "arcs")
"""What a motion-level action is: the env's ``(v, ω)`` box, or an index into :data:`ARCS`."""


def command(commands: str, action: Any, name: str = "action") -> np.ndarray:
    """The env's ``(v, ω)`` command for ``action`` under ``commands`` (:data:`COMMANDS`).

    Raises:
        ValueError: an ``"arcs"`` action that is not an index into :data:`ARCS`.
    """
    if commands != "arcs":
        return action
    index = np.asarray(action)
    if index.size != 1 or not np.issubdtype(index.dtype, np.integer) or not (
            0 <= int(index.reshape(())) < len(ARCS)):
        raise ValueError(f"{name} must be an index in [0, {len(ARCS)}) into agents.motion.ARCS, "
                         f"got {action!r}")
    return ARCS[int(index.reshape(()))]


class MotionEnv(BaseParallelWrapper):
    """``two_robot_explore`` (or ``multi_robot_explore``) at the motion level (module
    docstring).

    Args:
        env: a ``two_robot_explore_v0`` or ``multi_robot_explore_v0`` ``ParallelEnv``.
        hold: env steps each velocity command is held (the reward is their sum), ``>= 1``.
        frontier_shaping: ``k``, reward per metre of progress towards the nearest frontier
            (``0``: none, the env's reward alone), ``>= 0``.
        commands: ``"continuous"`` (the env's ``Box`` action) or ``"arcs"``: ``Discrete(5)``,
            action ``i`` is the command ``ARCS[i]`` (the env must have
            ``action_type="continuous"``).
        config: the :class:`~agents.frontier_planning.FrontierConfig` of the distance.

    ``infos`` are the env's after the last held step, plus ``env_steps`` (steps taken: fewer
    than ``hold`` when the episode ended) and, with shaping, ``frontier_distance`` (m, the
    one ``Φ`` uses now; -1 until a frontier has been reachable).

    Raises:
        TypeError: ``env`` is not a ``two_robot_explore`` env.
        ValueError: ``hold`` or ``frontier_shaping`` out of range, an unknown ``commands``,
            or ``"arcs"`` on a discrete-action env.
    """

    metadata = {"name": "two_robot_explore_motion_v0", "render_modes": ["rgb_array", "human"],
                "is_parallelizable": True}

    def __init__(self, env: Any, hold: int = 1, frontier_shaping: float = 0.0,
                 commands: str = "continuous", config: FrontierConfig | None = None) -> None:
        if not hasattr(env, "possible_agents") or not hasattr(env, "robot_map"):
            raise TypeError(f"env must be a two_robot_explore ParallelEnv, got "
                            f"{type(env).__name__}")
        super().__init__(env)
        self.hold = check_int(hold, "hold", low=1)
        self.shaping = check_real(frontier_shaping, "frontier_shaping", low=0.0,
                                  low_inclusive=True)
        if commands not in COMMANDS:
            raise ValueError(f"commands must be one of {list(COMMANDS)}, got {commands!r}")
        if commands == "arcs" and env.config.action_type != "continuous":
            raise ValueError("commands='arcs' needs an env with action_type='continuous', got "
                             f"{env.config.action_type!r}")
        self.commands = commands
        self._action_space = (spaces.Discrete(len(ARCS)) if commands == "arcs"
                              else env.action_space(env.possible_agents[0]))
        self.config = config or FrontierConfig()
        self.possible_agents = list(env.possible_agents)
        self.agents: list[str] = []
        self._distance: dict[str, float] = {}

    def action_space(self, agent: str) -> spaces.Space:
        return self._action_space

    def reset(self, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict, dict]:
        obs, infos = self.env.reset(seed=seed, options=options)
        self.agents = list(self.env.agents)
        if self.shaping:
            self._distance = {a: frontier_distance(self.env, a, self.config)
                              for a in self.agents}
            infos = {a: {**i, "frontier_distance": self._finite(a)} for a, i in infos.items()}
        return obs, infos

    def _finite(self, agent: str) -> float:
        d = self._distance[agent]
        return d if math.isfinite(d) else -1.0

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Run the commands for ``hold`` env steps; the reward is their sum plus shaping."""
        if not self.agents:
            raise RuntimeError("step() called before reset() or after the episode ended")
        if self.commands == "arcs":
            actions = {a: command(self.commands, act, f"action of {a}")
                       for a, act in actions.items()}
        total = dict.fromkeys(self.agents, 0.0)
        taken = 0
        while taken < self.hold and self.env.agents:
            obs, rewards, terms, truncs, infos = self.env.step(actions)
            taken += 1
            for a, r in rewards.items():
                total[a] += r
        extra: dict[str, dict[str, Any]] = {a: {"env_steps": taken} for a in infos}
        if self.shaping:
            for a in infos:
                new, old = frontier_distance(self.env, a, self.config), self._distance[a]
                if math.isfinite(new):
                    if math.isfinite(old):
                        total[a] += self.shaping * (old - new)
                    self._distance[a] = new
                extra[a]["frontier_distance"] = self._finite(a)
        self.agents = list(self.env.agents)
        infos = {a: {**i, **extra[a]} for a, i in infos.items()}
        return obs, total, terms, truncs, infos
