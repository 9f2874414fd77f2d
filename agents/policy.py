"""The feature extractor for ``MultiInputPolicy`` on the ``two_robot_explore`` Dict observation.

Three encoders, concatenated:

* ``local_map`` (1 × L × L, uint8; SB3 scales images to [0, 1]) → a small CNN (4 × 4 patches,
  then one strided 3 × 3 conv);
* ``sonar``, ``odometry``, ``teammate`` (and ``frontiers`` when the observation has it:
  :class:`agents.goals.FrontierGoalEnv`) → one MLP layer, each input divided by its space's
  bound so every feature lies in [-1, 1];
* the padded graph (``graph_nodes`` N × F, ``graph_mask``, ``graph_adjacency``) → a per-node
  MLP, one round of mean-neighbour message passing, then masked mean- and max-pooling: a
  permutation-invariant summary (Deep Sets with one graph-convolution step) that ignores
  padding.
"""

from __future__ import annotations

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

VECTOR_KEYS = ("sonar", "odometry", "teammate")
OPTIONAL_VECTOR_KEYS = ("frontiers",)
GRAPH_KEYS = ("graph_nodes", "graph_mask", "graph_adjacency")


def _bound(space: spaces.Box) -> torch.Tensor:
    high = np.maximum(np.abs(space.low), np.abs(space.high)).astype(np.float32)
    return torch.as_tensor(np.where(np.isfinite(high) & (high > 0), high, 1.0))


class TopoExplorerExtractor(BaseFeaturesExtractor):
    """CNN + MLP + graph encoder for the explorer's Dict observation (module docstring).

    Args:
        observation_space: the env's per-robot ``Dict`` space.
        map_features, vector_features, graph_features: widths of the three encodings.
    """

    def __init__(self, observation_space: spaces.Dict, map_features: int = 128,
                 vector_features: int = 64, graph_features: int = 64) -> None:
        if not isinstance(observation_space, spaces.Dict):
            raise TypeError("TopoExplorerExtractor needs a Dict observation space, got "
                            f"{type(observation_space).__name__}")
        missing = [k for k in ("local_map", *VECTOR_KEYS, *GRAPH_KEYS)
                   if k not in observation_space.spaces]
        if missing:
            raise ValueError(f"observation space lacks keys {missing}")
        super().__init__(observation_space, map_features + vector_features + graph_features)
        sp = observation_space.spaces

        channels = sp["local_map"].shape[0]
        # 4 × 4 patches (0.6 m at the default 0.15 m/pixel) then one 3 × 3 conv: 7× cheaper to
        # train than three stride-2 convs (170 → 24 ms per 256-batch step on one thread) and
        # fine enough for where to go next
        self.cnn = nn.Sequential(
            nn.Conv2d(channels, 16, 4, stride=4), nn.ReLU(),
            nn.Conv2d(16, 32, 3, stride=2, padding=1), nn.ReLU(),
            nn.Flatten(),
        )
        with torch.no_grad():
            n_flat = self.cnn(torch.zeros(1, *sp["local_map"].shape)).shape[1]
        self.map_head = nn.Sequential(nn.Linear(n_flat, map_features), nn.ReLU())

        self.vector_keys = VECTOR_KEYS + tuple(k for k in OPTIONAL_VECTOR_KEYS if k in sp)
        self.register_buffer("vector_scale", torch.cat([_bound(sp[k]).flatten()
                                                        for k in self.vector_keys]))
        n_vec = int(sum(np.prod(sp[k].shape) for k in self.vector_keys))
        self.vector = nn.Sequential(nn.Linear(n_vec, vector_features), nn.ReLU())

        node_space = sp["graph_nodes"]
        self.register_buffer("node_scale", _bound(node_space).amax(dim=0))
        n_feat = node_space.shape[1]
        self.node_in = nn.Sequential(nn.Linear(n_feat, graph_features), nn.ReLU())
        self.node_msg = nn.Linear(graph_features, graph_features)
        self.graph_head = nn.Sequential(nn.Linear(2 * graph_features, graph_features), nn.ReLU())

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        m = self.map_head(self.cnn(obs["local_map"]))
        vec = torch.cat([obs[k].flatten(1) for k in self.vector_keys], dim=1) / self.vector_scale
        v = self.vector(vec)

        mask = obs["graph_mask"].unsqueeze(-1)  # (B, N, 1)
        h = self.node_in(obs["graph_nodes"] / self.node_scale) * mask
        adj = obs["graph_adjacency"] * mask * mask.transpose(1, 2)
        deg = adj.sum(-1, keepdim=True).clamp(min=1.0)
        h = torch.relu(h + self.node_msg(adj @ h / deg)) * mask
        count = mask.sum(1).clamp(min=1.0)
        mean = h.sum(1) / count
        top = (h - (1.0 - mask) * 1e4).amax(1) * (mask.sum(1) > 0)
        g = self.graph_head(torch.cat([mean, top], dim=1))
        return torch.cat([m, v, g], dim=1)
