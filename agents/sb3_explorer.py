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
    def load_policy(path: str | Path, device: str = "cpu") -> Any:
        """Load a model saved by ``train.py`` (a PPO ``.zip``)."""
        from stable_baselines3 import PPO

        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"no saved model at {str(path)!r}")
        return PPO.load(path, device=device)

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
        ValueError: ``n_robots`` is not an integer from 2 to 8 (the env's team sizes).
    """
    from agents.scripted import Blackboard
    from envs.two_robot_explore.config import MAX_ROBOTS

    if not 2 <= check_int(n_robots, "n_robots") <= MAX_ROBOTS:
        raise ValueError(f"n_robots must be between 2 and {MAX_ROBOTS}, got {n_robots}")
    board = Blackboard()
    return {f"robot_{i}": SB3Explorer(policy, deterministic, action_type, blackboard=board)
            for i in range(n_robots)}
