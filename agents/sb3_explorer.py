"""``SB3Explorer``: a trained Stable-Baselines3 policy behind the :class:`Explorer` interface, so
learned policies drive evaluations and generate map-pair datasets like scripted ones
(``--explorer sb3:PATH``)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import Explorer


class SB3Explorer(Explorer):
    """Acts with a saved SB3 model (PPO by default) from the robot's observation.

    Args:
        policy: a loaded SB3 model (``BaseAlgorithm``); load once with :meth:`load_policy` and
            share it between the two robots (parameter sharing, as trained).
        deterministic: use the policy's mode instead of sampling.
        action_type: must match what the model was trained with.
    """

    name = "sb3"

    def __init__(self, policy: Any, deterministic: bool = True,
                 action_type: str = "continuous") -> None:
        super().__init__(action_type)
        if not hasattr(policy, "predict"):
            raise TypeError(f"policy must be a Stable-Baselines3 model, got "
                            f"{type(policy).__name__}")
        self.policy = policy
        self.deterministic = bool(deterministic)

    @staticmethod
    def load_policy(path: str | Path, device: str = "cpu") -> Any:
        """Load a model saved by ``train.py`` (a PPO ``.zip``)."""
        from stable_baselines3 import PPO

        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"no saved model at {str(path)!r}")
        return PPO.load(path, device=device)

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> np.ndarray | int:
        action, _ = self.policy.predict(dict(observation), deterministic=self.deterministic)
        if self.action_type == "discrete":
            return int(action)
        return np.asarray(action, dtype=np.float32)
