"""MAPPO on ``two_robot_explore_v0`` (or a team of ``N`` robots, ``multi_robot_explore_v0``)
with TorchRL: a short, complete example of the env in TorchRL's multi-agent stack (the
``torchrl`` extra).

    python -m agents.torchrl_mappo --frames 20000 --world-size 10 10
    python -m agents.torchrl_mappo --n-robots 4 --comm-range 5

TorchRL's ``PettingZooWrapper`` groups the robots as ``"robot"`` (observations, actions,
rewards and dones of shape ``(..., N, ...)``) and adds the env's global ``state``. The actor is
decentralised with shared parameters (``MultiAgentMLP``): each robot sees the concatenation of
its ``sonar``, ``odometry``, ``teammate`` and ``graph_mask`` observations (49 numbers; a team
has ``teammates``, ``N − 1`` rows of 7 flattened in their place: ``44 + 7 (N − 1)``) and
outputs a ``TanhNormal`` over its ``(v, ω)`` command. The critic is MAPPO's centralised value:
an MLP of the env's ``state()`` (true poses, coverage, world maps; manual, State), one value
per robot. The loss is ``ClipPPOLoss`` with GAE, trained on each collected batch for a few
epochs of minibatches, as in TorchRL's multi-agent PPO tutorial.

It shows the wiring, not a tuned agent: the actor sees neither the ``local_map`` image nor the
graph, so it learns to move and avoid walls, not to explore as ``train.py``'s goal-level PPO
does. :func:`main` returns the per-iteration mean reward and the throughput.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

try:
    import torchrl  # noqa: F401
except ImportError as exc:  # the extra is missing: say which
    raise ImportError("agents.torchrl_mappo needs the torchrl extra: pip install "
                      "'topomerge[torchrl]'") from exc
import torch
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, ReplayBuffer, SamplerWithoutReplacement
from torchrl.envs import CatTensors, FlattenObservation, RewardSum, TransformedEnv
from torchrl.envs.libs.pettingzoo import PettingZooWrapper
from torchrl.modules import MLP, MultiAgentMLP, ProbabilisticActor, TanhNormal
from torchrl.objectives import ClipPPOLoss, ValueEstimators

from envs import parallel_env_for
from topo.validation import check_int, check_real

GROUP = "robot"
"""TorchRL's group of the robots (``PettingZooWrapper`` groups agents by name prefix)."""

ACTOR_KEYS = ("sonar", "odometry", "teammate", "graph_mask")
"""Observation keys the actor of two robots reads (concatenated)."""


def actor_keys(n_robots: int) -> tuple[str, ...]:
    """The observation keys the actor reads: :data:`ACTOR_KEYS`, with ``teammates`` (flattened)
    for ``teammate`` in a team of more than two."""
    if n_robots == 2:
        return ACTOR_KEYS
    return tuple("teammates" if k == "teammate" else k for k in ACTOR_KEYS)


@dataclass
class MappoArgs:
    """MAPPO on two_robot_explore_v0 or a team of N robots with TorchRL (``python -m
    agents.torchrl_mappo --help``)."""

    frames: int = 20_000
    """Total env steps collected (each step is one frame of every robot)."""
    frames_per_batch: int = 2_000
    """Env steps per collected batch (one PPO iteration)."""
    epochs: int = 4
    """Passes over each batch."""
    minibatch: int = 500
    """Env steps per minibatch."""
    lr: float = 3e-4
    """Adam learning rate."""
    gamma: float = 0.99
    """Discount."""
    lmbda: float = 0.95
    """GAE lambda."""
    clip: float = 0.2
    """PPO clip range."""
    entropy: float = 1e-3
    """Entropy bonus coefficient."""
    cells: int = 128
    """Hidden units per layer (two layers) of the actor and the critic."""
    max_cycles: int = 300
    """Env episode length."""
    world_size: tuple[float, float] = (10.0, 10.0)
    """Procedural building size, metres."""
    seed: int = 0
    """Seed of the env, the networks and the sampling."""
    n_robots: int = 2
    """Robots in the team, 2–8 (2: ``two_robot_explore_v0``, more: ``multi_robot_explore_v0``)."""
    comm_range: float | None = None
    """The env's ``comm.range``, metres (default: always in contact)."""

    def __post_init__(self) -> None:
        from envs.explore.config import EnvConfig

        EnvConfig.from_kwargs(**self.env_config())  # n_robots, comm.range: named when bad
        for name in ("frames", "frames_per_batch", "epochs", "minibatch", "cells", "max_cycles"):
            check_int(getattr(self, name), name, low=1)
        check_int(self.seed, "seed", low=0)
        for name in ("lr", "clip"):
            check_real(getattr(self, name), name, low=0.0)
        check_real(self.entropy, "entropy", low=0.0, low_inclusive=True)
        for name in ("gamma", "lmbda"):
            check_real(getattr(self, name), name, low=0.0, high=1.0)
        if self.frames_per_batch % self.minibatch:
            raise ValueError(f"frames_per_batch ({self.frames_per_batch}) must be a multiple of "
                             f"minibatch, got minibatch={self.minibatch}")

    def env_config(self) -> dict[str, Any]:
        """The env's ``EnvConfig`` fields (``n_robots`` and ``comm`` only when set)."""
        cfg: dict[str, Any] = {"max_cycles": self.max_cycles,
                               "world": {"size": tuple(self.world_size)}}
        if self.n_robots != 2:
            cfg["n_robots"] = self.n_robots
        if self.comm_range is not None:
            cfg["comm"] = {"range": self.comm_range}
        return cfg


def make_env(args: MappoArgs) -> Any:
    """The env wrapped for TorchRL: ``PettingZooWrapper`` with the state, the actor's input
    concatenated under ``(GROUP, "observation_vector")`` (a team's ``teammates`` rows
    flattened first), episode rewards summed."""
    base = PettingZooWrapper(env=parallel_env_for(args.env_config()), return_state=True,
                             seed=args.seed)
    env = TransformedEnv(base)
    keys = actor_keys(args.n_robots)
    if "teammates" in keys:
        env.append_transform(FlattenObservation(
            -2, -1, in_keys=[(GROUP, "observation", "teammates")],
            out_keys=[(GROUP, "observation", "teammates_flat")]))
        keys = tuple("teammates_flat" if k == "teammates" else k for k in keys)
    env.append_transform(CatTensors(
        in_keys=[(GROUP, "observation", k) for k in keys],
        out_key=(GROUP, "observation_vector"), del_keys=False))
    return env.append_transform(
        RewardSum(in_keys=[(GROUP, "reward")], out_keys=[(GROUP, "episode_reward")]))


def make_modules(env: Any, args: MappoArgs) -> tuple[Any, Any]:
    """The decentralised actor (shared parameters) and the centralised critic of the state."""
    n_agents = len(env.group_map[GROUP])
    obs_dim = env.observation_spec[GROUP, "observation_vector"].shape[-1]
    action_spec = env.full_action_spec_unbatched[GROUP, "action"]
    actor_net = torch.nn.Sequential(
        MultiAgentMLP(n_agent_inputs=obs_dim, n_agent_outputs=2 * action_spec.shape[-1],
                      n_agents=n_agents, centralised=False, share_params=True, depth=2,
                      num_cells=args.cells, activation_class=torch.nn.Tanh),
        NormalParamExtractor())
    actor = ProbabilisticActor(
        module=TensorDictModule(actor_net, in_keys=[(GROUP, "observation_vector")],
                                out_keys=[(GROUP, "loc"), (GROUP, "scale")]),
        spec=action_spec, in_keys=[(GROUP, "loc"), (GROUP, "scale")],
        out_keys=[(GROUP, "action")], distribution_class=TanhNormal,
        distribution_kwargs={"low": action_spec.space.low, "high": action_spec.space.high},
        return_log_prob=True, log_prob_key=(GROUP, "sample_log_prob"))
    state_dim = env.observation_spec["state"].shape[-1]
    critic = TensorDictModule(StateValue(state_dim, n_agents, args.cells), in_keys=["state"],
                              out_keys=[(GROUP, "state_value")])
    return actor, critic


class StateValue(torch.nn.Module):
    """MAPPO's centralised critic: an MLP of the env's global state, the same value for each
    of ``n_agents`` agents (shape ``(..., n_agents, 1)``)."""

    def __init__(self, state_dim: int, n_agents: int, cells: int) -> None:
        super().__init__()
        self.n_agents = n_agents
        self.net = MLP(in_features=state_dim, out_features=1, num_cells=[cells, cells],
                       activation_class=torch.nn.Tanh)

    def forward(self, state: torch.Tensor) -> torch.Tensor:
        value = self.net(state)
        return value.unsqueeze(-2).expand(*value.shape[:-1], self.n_agents, 1)


def main(args: MappoArgs) -> dict[str, Any]:
    """Train; returns ``{"iterations": [{"frames", "mean_reward", "episode_reward", "loss"}],
    "agent_steps_per_s", "actor"}`` (``episode_reward``: mean over episodes finished in the
    batch, NaN if none; ``actor``: the trained policy module)."""
    torch.manual_seed(args.seed)
    env = make_env(args)
    actor, critic = make_modules(env, args)
    collector = Collector(env, actor, frames_per_batch=args.frames_per_batch,
                          total_frames=args.frames, auto_register_policy_transforms=True)
    buffer = ReplayBuffer(storage=LazyTensorStorage(args.frames_per_batch),
                          sampler=SamplerWithoutReplacement(), batch_size=args.minibatch)
    loss = ClipPPOLoss(actor_network=actor, critic_network=critic, clip_epsilon=args.clip,
                       entropy_coeff=args.entropy, normalize_advantage=False)
    loss.set_keys(reward=(GROUP, "reward"), action=(GROUP, "action"),
                  sample_log_prob=(GROUP, "sample_log_prob"), value=(GROUP, "state_value"),
                  done=(GROUP, "done"), terminated=(GROUP, "terminated"))
    loss.make_value_estimator(ValueEstimators.GAE, gamma=args.gamma, lmbda=args.lmbda)
    optim = torch.optim.Adam(loss.parameters(), lr=args.lr)
    out: dict[str, Any] = {"iterations": []}
    frames, t0 = 0, time.perf_counter()
    for batch in collector:
        with torch.no_grad():
            loss.value_estimator(batch, params=loss.critic_network_params,
                                 target_params=loss.target_critic_network_params)
        buffer.extend(batch.reshape(-1))
        losses = []
        for _ in range(args.epochs):
            for _ in range(args.frames_per_batch // args.minibatch):
                parts = loss(buffer.sample())
                total = parts["loss_objective"] + parts["loss_critic"] + parts["loss_entropy"]
                total.backward()
                torch.nn.utils.clip_grad_norm_(loss.parameters(), 1.0)
                optim.step()
                optim.zero_grad()
                losses.append(total.item())
        collector.update_policy_weights_()
        frames += batch.numel()
        done = batch["next", GROUP, "done"]
        finished = batch["next", GROUP, "episode_reward"][done]
        out["iterations"].append({
            "frames": frames,
            "mean_reward": float(batch["next", GROUP, "reward"].mean()),
            "episode_reward": float(finished.mean()) if finished.numel() else float("nan"),
            "loss": float(np.mean(losses)),
        })
    out["agent_steps_per_s"] = frames * len(env.group_map[GROUP]) / (time.perf_counter() - t0)
    out["actor"] = actor
    collector.shutdown()
    env.close()
    return out


if __name__ == "__main__":
    import tyro

    torch.set_num_threads(1)  # small networks: one thread is faster on a shared machine
    result = main(tyro.cli(MappoArgs))
    for row in result["iterations"]:
        print(f"frames {row['frames']:>7}  mean reward {row['mean_reward']:+.4f}  episode "
              f"reward {row['episode_reward']:+.2f}  loss {row['loss']:.3f}")
    print(f"{result['agent_steps_per_s']:.0f} agent-steps/s (collection and training)")
