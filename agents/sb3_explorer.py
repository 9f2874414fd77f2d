"""``SB3Explorer``: a trained Stable-Baselines3 policy behind the :class:`Explorer` interface, so
learned policies drive evaluations and generate map-pair datasets like scripted ones
(``--explorer sb3:PATH``). Motion-level policies (trained on the env) act every step; goal-level
policies (trained on :class:`agents.goals.FrontierGoalEnv`: a ``frontiers`` observation and
``Discrete(SECTORS)`` actions) pick a sector every ``hold`` steps and a
:class:`agents.goals.GoalFrontier` drives, exactly as in training. Any policy with SB3's
``predict(observation, deterministic)`` and ``observation_space`` works the same way: RLlib
policies come through :class:`agents.rllib.RLlibPolicy`."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import Explorer
from topo.validation import check_int


class SB3Explorer(Explorer):
    """Acts with a saved SB3 model (PPO by default) from the robot's observation.

    Args:
        policy: a loaded SB3 model (``BaseAlgorithm``; load once with :meth:`load_policy`) or
            another object with its ``predict`` and ``observation_space`` (an
            :class:`agents.rllib.RLlibPolicy`); share it between the robots (parameter
            sharing, as trained).
        deterministic: use the policy's mode; ``False`` samples the action (from an SB3
            model's distribution, or through a policy's ``sample(observation, rng)`` such as
            :meth:`agents.rllib.RLlibPolicy.sample`, with the explorer's own generator:
            reproducible per seeded episode; other policies through their ``predict``).
        action_type: must match what the model was trained with.
        blackboard: a goal-level policy's planner shares it with the teammate's, so each sees
            the other's goal (:func:`sb3_team` wires one; default: a board of its own).

    A goal-level model holds each decision for its ``goal_hold`` attribute's steps (saved with
    the model by ``train.py``; :data:`agents.goals.DEFAULT_HOLD` otherwise), a motion-level
    model each velocity command for its ``motion_hold`` steps (1 otherwise), as trained, reading
    its action as one of :data:`agents.motion.ARCS` when its ``motion_commands`` is ``"arcs"``.

    Raises:
        TypeError: ``policy`` has no ``predict`` method.
    """

    name = "sb3"

    def __init__(self, policy: Any, deterministic: bool = True,
                 action_type: str = "continuous", blackboard: Any = None) -> None:
        super().__init__(action_type)
        if not hasattr(policy, "predict"):
            raise TypeError(f"policy must be a Stable-Baselines3 model or have its "
                            f"predict(observation, deterministic), got {type(policy).__name__}")
        self.policy = policy
        self.deterministic = bool(deterministic)
        space = getattr(policy, "observation_space", None)
        self.goal_level = "frontiers" in getattr(space, "spaces", {})
        self.controller = None
        if self.goal_level:
            from agents.goals import DEFAULT_HOLD, GoalFrontier

            self.controller = GoalFrontier(action_type=action_type, blackboard=blackboard)
            self.hold = int(getattr(policy, "goal_hold", DEFAULT_HOLD))
            # a centralised critic's global state: the actor never reads it (SectorPolicy)
            state = space.spaces.get("state")
            self._critic_only = ({"state": np.zeros(state.shape, state.dtype)}
                                 if state is not None else {})
        else:
            self.hold = int(getattr(policy, "motion_hold", 1))
            self.commands = str(getattr(policy, "motion_commands", "continuous"))
        self._since = self.hold
        self._action: Any = None

    def bind(self, env: Any, agent: str) -> None:
        super().bind(env, agent)
        if self.controller is not None:
            self.controller.bind(env, agent)

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        if self.controller is not None:
            self.controller.reset(int(self.rng.integers(2**31)))
        self._since = self.hold

    @staticmethod
    def load_policy(path: str | Path, device: str = "cpu", n_robots: int | None = None) -> Any:
        """Load a model saved by ``train.py`` (a PPO ``.zip``).

        ``n_robots``: the team it will drive, when that is not the team it was trained with. A
        team policy reads its teammates as a set (``teammates`` rows, :mod:`agents.policy`), so
        its weights fit any team size: the model is rebuilt for ``n_robots − 1`` rows
        (:func:`team_space`) and the same weights loaded.

        Raises:
            FileNotFoundError: no file at ``path``.
            ValueError: ``n_robots`` outside 2–8, or another team size for a policy trained on
                ``two_robot_explore_v0`` (its single ``teammate`` input is not a set).
        """
        from stable_baselines3 import PPO
        from stable_baselines3.common.save_util import load_from_zip_file

        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"no saved model at {str(path)!r}")
        if n_robots is None:
            return PPO.load(path, device=device)
        # the trained space from the zip's data alone, so the model is built once
        data, _, _ = load_from_zip_file(path, device=device)
        trained = data["observation_space"]
        space = team_space(trained, n_robots)
        custom = None if space is trained else {"observation_space": space}
        return PPO.load(path, device=device, custom_objects=custom)

    def _predict(self, observation: dict[str, Any]) -> Any:
        """The policy's mode, or a sample drawn with this explorer's own generator (so a
        seeded episode repeats exactly): from an SB3 policy's action distribution, or through
        a policy's ``sample(observation, rng)`` (:meth:`agents.rllib.RLlibPolicy.sample`)."""
        if not self.deterministic and callable(getattr(self.policy, "sample", None)):
            return self.policy.sample(observation, self.rng)
        sb3 = getattr(self.policy, "policy", None)
        if self.deterministic or not hasattr(sb3, "get_distribution"):
            return self.policy.predict(observation, deterministic=self.deterministic)[0]
        import torch

        with torch.no_grad():
            dist = sb3.get_distribution(sb3.obs_to_tensor(observation)[0]).distribution
        return sample_action(dist, self.rng, self.policy.action_space)

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> np.ndarray | int:
        if self.controller is not None:
            if self._since >= self.hold:
                obs = {**observation, "frontiers": self.controller.frontier_features(info),
                       **self._critic_only}
                sector = self._predict(obs)
                self.controller.choose_sector(int(sector))
                self._since = 0
            self._since += 1
            return self.controller.act(observation, info)
        if self._since >= self.hold:
            action = self._predict(dict(observation))
            if self.commands != "continuous":
                from agents.motion import command

                action = command(self.commands, np.asarray(action).astype(np.int64))
            self._action = (int(action) if self.action_type == "discrete"
                            else np.asarray(action, dtype=np.float32))
            self._since = 0
        self._since += 1
        return self._action


def _check_team_size(n_robots: Any) -> None:
    """Raise unless ``n_robots`` is an integer from 2 to 8 (the env's team sizes)."""
    from envs.explore.config import MAX_ROBOTS

    if not 2 <= check_int(n_robots, "n_robots") <= MAX_ROBOTS:
        raise ValueError(f"n_robots must be between 2 and {MAX_ROBOTS}, got {n_robots}")


def team_space(space: Any, n_robots: int) -> Any:
    """A team policy's Dict observation ``space`` for a team of ``n_robots``: its ``teammates``
    rows (each bounded alike) repeated or cut to ``n_robots − 1``; ``space`` itself when it has
    that many. Everything else stays, the critic-only ``state`` included (an actor never reads
    it and :class:`SB3Explorer` fills it with zeros of its trained shape).

    Raises:
        ValueError: ``n_robots`` outside 2–8; a two-robot policy's space (``teammate``, not
            ``teammates``) for another team size.
    """
    from gymnasium import spaces

    _check_team_size(n_robots)
    rows = space.spaces.get("teammates")
    if rows is None:
        if n_robots == 2:
            return space
        raise ValueError(f"n_robots={n_robots}: this policy was trained on "
                         f"two_robot_explore_v0 (one 'teammate' input, not a set of "
                         f"'teammates'); train it with train.py --n-robots to drive other teams")
    if rows.shape[0] == n_robots - 1:
        return space
    low = np.repeat(rows.low[:1], n_robots - 1, axis=0)
    high = np.repeat(rows.high[:1], n_robots - 1, axis=0)
    return spaces.Dict({**space.spaces, "teammates": spaces.Box(low, high, dtype=rows.dtype)})


def sample_action(dist: Any, rng: np.random.Generator, space: Any) -> int | np.ndarray:
    """One action drawn with ``rng`` from a torch distribution over a batch of one: a
    ``Categorical`` gives an index, anything else its ``mean`` and ``stddev`` a diagonal
    Gaussian draw clipped to the ``Box`` ``space`` (in its dtype). Drawing with a numpy
    generator rather than torch's global one is what makes a sampled episode repeat."""
    import torch

    if isinstance(dist, torch.distributions.Categorical):
        p = dist.probs[0].double().numpy()
        return int(rng.choice(len(p), p=p / p.sum()))
    action = rng.normal(dist.mean[0].double().numpy(), dist.stddev[0].double().numpy())
    return np.clip(action, space.low, space.high).astype(space.dtype)


def sb3_team(policy: Any, deterministic: bool = True, action_type: str = "continuous",
             n_robots: int = 2) -> dict[str, SB3Explorer]:
    """``{"robot_0": ..., "robot_1": ..., ...}``: the ``n_robots`` robots all driven by
    ``policy`` (parameter sharing, as trained), their goal-level planners sharing one
    :class:`~agents.scripted.Blackboard` as in :class:`agents.goals.FrontierGoalEnv`.

    Raises:
        ValueError: ``n_robots`` is not an integer from 2 to 8 (the env's team sizes), or not
            the team ``policy``'s observation space was built for (load it for this team
            with ``SB3Explorer.load_policy(path, n_robots=...)``).
    """
    from agents.scripted import Blackboard

    _check_team_size(n_robots)
    space = getattr(policy, "observation_space", None)
    if hasattr(space, "spaces") and team_space(space, n_robots) is not space:
        rows = space.spaces["teammates"].shape[0] if "teammates" in space.spaces else 1
        raise ValueError(f"n_robots={n_robots}: the policy's observations are for a team of "
                         f"{rows + 1}; load it with SB3Explorer.load_policy(path, "
                         f"n_robots={n_robots}) to drive this team")
    board = Blackboard()
    return {f"robot_{i}": SB3Explorer(policy, deterministic, action_type, blackboard=board)
            for i in range(n_robots)}
