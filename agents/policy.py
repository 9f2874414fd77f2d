"""The feature extractor for ``MultiInputPolicy`` on the ``two_robot_explore`` Dict observation.

Three encoders, concatenated:

* ``local_map`` (1 × L × L, uint8; SB3 scales images to [0, 1]) → a small CNN (4 × 4 patches,
  then one strided 3 × 3 conv);
* ``sonar``, ``odometry``, ``teammate`` (and ``frontiers`` when the observation has it:
  :class:`agents.goals.FrontierGoalEnv`) → one MLP layer, each input divided by its space's
  bound so every feature lies in [-1, 1]; a team of ``N`` robots (``multi_robot_explore_v0``)
  has ``teammates`` (N − 1 rows) instead of ``teammate``: each row goes through one shared
  layer and the rows' mean and max join that MLP's input (Deep Sets), so the weights do not
  depend on ``N`` or on the teammates' order;
* the padded graph (``graph_nodes`` N × F, ``graph_mask``, ``graph_adjacency``) → a per-node
  MLP, one round of mean-neighbour message passing, then masked mean- and max-pooling: a
  permutation-invariant summary (Deep Sets with one graph-convolution step) that ignores
  padding.

At the goals level, :class:`SectorPolicy` scores each frontier sector with one shared network
(the context above, that sector's ``frontiers`` row and its direction) instead of one linear
layer over the whole context: choosing "the sector whose frontier is cheap and large" is then one
rule learnt once for all sectors rather than eight separate ones.
"""

from __future__ import annotations

import functools

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.policies import MultiInputActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from agents.goals import COST_SCALE, FRONTIER_FEATURES
from topo.validation import check_real

VECTOR_KEYS = ("sonar", "odometry", "teammate")
OPTIONAL_VECTOR_KEYS = ("frontiers",)
TEAM_KEY = "teammates"
"""A team's observation of its ``N − 1`` teammates, one row each; replaces ``teammate``."""
GRAPH_KEYS = ("graph_nodes", "graph_mask", "graph_adjacency")


def _bound(space: spaces.Box) -> torch.Tensor:
    high = np.maximum(np.abs(space.low), np.abs(space.high)).astype(np.float32)
    return torch.as_tensor(np.where(np.isfinite(high) & (high > 0), high, 1.0))


class TopoExplorerExtractor(BaseFeaturesExtractor):
    """CNN + MLP + graph encoder for the explorer's Dict observation (module docstring).

    Args:
        observation_space: the env's per-robot ``Dict`` space.
        map_features, vector_features, graph_features: widths of the three encodings.
        pass_through: observation keys appended, flattened and scaled to [-1, 1], after the
            encodings (:class:`SectorPolicy` reads ``frontiers`` there).
        state_features: width of an MLP encoding of the ``state`` observation (the env's
            global state, :class:`agents.goals.FrontierGoalEnv`'s ``global_state``), placed
            between the three encodings and the pass-through keys; 0 (the default) ignores
            ``state``. :class:`SectorPolicy` gives it to the critic only.
        team_features: width of the per-teammate layer when the observation has
            ``teammates`` (ignored with ``teammate``).
    """

    def __init__(self, observation_space: spaces.Dict, map_features: int = 128,
                 vector_features: int = 64, graph_features: int = 64,
                 pass_through: tuple[str, ...] = (), state_features: int = 0,
                 team_features: int = 16) -> None:
        if not isinstance(observation_space, spaces.Dict):
            raise TypeError("TopoExplorerExtractor needs a Dict observation space, got "
                            f"{type(observation_space).__name__}")
        team = TEAM_KEY in observation_space.spaces and "teammate" not in observation_space.spaces
        vector_keys = tuple(k for k in VECTOR_KEYS if not (team and k == "teammate"))
        missing = [k for k in ("local_map", *vector_keys, *GRAPH_KEYS)
                   if k not in observation_space.spaces]
        missing += [k for k in pass_through if k not in observation_space.spaces]
        if state_features and "state" not in observation_space.spaces:
            missing.append("state")
        if missing:
            raise ValueError(f"observation space lacks keys {missing}")
        sp = observation_space.spaces
        n_through = int(sum(np.prod(sp[k].shape) for k in pass_through))
        self.state_features = int(state_features)
        super().__init__(observation_space, map_features + vector_features + graph_features
                         + self.state_features + n_through)
        self.pass_through = tuple(pass_through)
        if self.state_features:
            self.state_encoder = nn.Sequential(
                nn.Linear(int(np.prod(sp["state"].shape)), self.state_features), nn.ReLU())
        if self.pass_through:
            self.register_buffer("through_scale", torch.cat([_bound(sp[k]).flatten()
                                                             for k in self.pass_through]))

        channels = sp["local_map"].shape[0]
        # 4 × 4 patches (0.6 m at the default 0.15 m/pixel) then one 3 × 3 conv: cheaper to
        # train than three stride-2 convs and fine enough for where to go next
        self.cnn = nn.Sequential(
            nn.Conv2d(channels, 16, 4, stride=4), nn.ReLU(),
            nn.Conv2d(16, 32, 3, stride=2, padding=1), nn.ReLU(),
            nn.Flatten(),
        )
        with torch.no_grad():
            n_flat = self.cnn(torch.zeros(1, *sp["local_map"].shape)).shape[1]
        self.map_head = nn.Sequential(nn.Linear(n_flat, map_features), nn.ReLU())

        self.vector_keys = vector_keys + tuple(k for k in OPTIONAL_VECTOR_KEYS if k in sp)
        self.register_buffer("vector_scale", torch.cat([_bound(sp[k]).flatten()
                                                        for k in self.vector_keys]))
        n_vec = int(sum(np.prod(sp[k].shape) for k in self.vector_keys))
        self.team = team
        if team:
            rows = sp[TEAM_KEY]
            if len(rows.shape) != 2:
                raise ValueError(f"observation space {TEAM_KEY!r} must be (teammates, features), "
                                 f"got shape {rows.shape}")
            self.register_buffer("team_scale", _bound(rows).amax(dim=0))
            self.team_in = nn.Sequential(nn.Linear(rows.shape[1], team_features), nn.ReLU())
            n_vec += 2 * team_features
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
        if self.team:
            rows = self.team_in(obs[TEAM_KEY] / self.team_scale)  # (B, N - 1, T)
            vec = torch.cat([vec, rows.mean(1), rows.amax(1)], dim=1)
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
        parts = [m, v, g]
        if self.state_features:
            parts.append(self.state_encoder(obs["state"].flatten(1)))
        if self.pass_through:
            raw = torch.cat([obs[k].flatten(1) for k in self.pass_through], dim=1)
            parts.append(raw / self.through_scale)
        return torch.cat(parts, dim=1)


class SectorLatent(nn.Module):
    """SB3 ``mlp_extractor`` for :class:`SectorPolicy`: the actor's latent is an MLP of the
    context followed by the raw per-sector rows (the features' last ``n_raw`` columns); the
    critic sees the context and the ``n_state`` global-state columns before the rows (a
    centralised critic), which the actor never reads. The RLlib backend's module
    (:class:`agents.rllib.TopoExplorerModule`) is built from the same two blocks."""

    def __init__(self, features_dim: int, n_raw: int, pi: int, vf: int,
                 n_state: int = 0) -> None:
        super().__init__()
        self.n_raw, self.n_state = n_raw, n_state
        self.context_dim = pi
        self.latent_dim_pi, self.latent_dim_vf = pi + n_raw, vf
        self.policy_net = nn.Sequential(nn.Linear(features_dim - n_raw - n_state, pi),
                                        nn.Tanh())
        self.value_net = nn.Sequential(nn.Linear(features_dim - n_raw, vf), nn.Tanh())

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)

    def forward_actor(self, features: torch.Tensor) -> torch.Tensor:
        context = features[:, :-(self.n_raw + self.n_state)]
        return torch.cat([self.policy_net(context), features[:, -self.n_raw:]], dim=1)

    def forward_critic(self, features: torch.Tensor) -> torch.Tensor:
        return self.value_net(features[:, :-self.n_raw])


MASKED_LOGIT = -1e8
"""Logit of a masked sector: probability 0 and a finite entropy (as ``sb3-contrib``'s
``MaskableCategorical``)."""


class SectorScorer(nn.Module):
    """The action head of :class:`SectorPolicy`: logit of sector ``k`` =
    ``MLP([context, frontiers[k], one_hot(k)]) − cost_prior · gap_k``, the same MLP for every
    sector, ``gap_k`` the metres by which sector ``k``'s frontier is dearer than the cheapest
    (the ``cost_gap`` column of :data:`agents.goals.FRONTIER_FEATURES`). With ``mask_empty``,
    sectors whose first ``frontiers`` column (a reachable frontier is there) is 0 get
    :data:`MASKED_LOGIT`, unless no sector has one.

    Raises:
        ValueError: ``cost_prior`` < 0, or > 0 with rows other than ``FRONTIER_FEATURES``'s
            (``name`` is the parameter named in the message).
    """

    def __init__(self, context_dim: int, sectors: int, row: int, hidden: int,
                 mask_empty: bool = False, cost_prior: float = 0.0,
                 name: str = "cost_prior") -> None:
        super().__init__()
        cost_prior = check_real(cost_prior, name, low=0.0, low_inclusive=True)
        if cost_prior and row != len(FRONTIER_FEATURES):
            raise ValueError(f"{name} needs the {len(FRONTIER_FEATURES)} frontiers columns of "
                             f"agents.goals.FRONTIER_FEATURES, got {row}")
        self.context_dim, self.sectors, self.row = context_dim, sectors, row
        self.mask_empty = bool(mask_empty)
        self.prior = cost_prior * COST_SCALE  # per unit of the cost_gap feature
        self.prior_column = FRONTIER_FEATURES.index("cost_gap")
        self.register_buffer("direction", torch.eye(sectors))
        self.net = nn.Sequential(nn.Linear(context_dim + row + sectors, hidden), nn.Tanh(),
                                 nn.Linear(hidden, 1))

    def forward(self, latent: torch.Tensor) -> torch.Tensor:
        b = latent.shape[0]
        context = latent[:, :self.context_dim].unsqueeze(1).expand(b, self.sectors, -1)
        rows = latent[:, self.context_dim:].reshape(b, self.sectors, self.row)
        x = torch.cat([context, rows, self.direction.expand(b, -1, -1)], dim=2)
        logits = self.net(x).squeeze(-1)
        if self.prior:
            logits = logits - self.prior * rows[..., self.prior_column]
        if not self.mask_empty:
            return logits
        empty = rows[..., 0] < 0.5
        empty &= ~empty.all(dim=1, keepdim=True)
        return logits.masked_fill(empty, MASKED_LOGIT)


class SectorPolicy(MultiInputActorCriticPolicy):
    """PPO policy for :class:`agents.goals.FrontierGoalEnv`: :class:`TopoExplorerExtractor`
    for the context, then one shared scorer per frontier sector (module docstring).

    ``net_arch`` may give ``pi`` / ``vf`` widths (one layer each, default 64); the scorer's
    hidden width is ``pi``'s. The action space must be ``Discrete(S)`` and the observation
    must have ``frontiers`` of shape ``(S, F)``. With ``mask_empty`` (the default), sectors
    whose first ``frontiers`` column is 0 (no reachable frontier there) cannot be chosen: the
    policy decides among the frontiers that exist instead of falling back to the cheapest one
    (action masking, as ``sb3-contrib``'s ``MaskablePPO`` but read from the observation, so
    saved policies need nothing else at inference).

    ``cost_prior`` (logits per metre, ``>= 0``) subtracts that much per metre by which a
    sector's frontier is dearer than the cheapest one (the ``cost_gap`` column of
    :data:`agents.goals.FRONTIER_FEATURES`): the untrained policy is then a soft ``Frontier``
    and PPO learns where to deviate from it (a residual on the scripted rule) instead of
    rediscovering it.

    When the observation has ``state`` (the env's global state:
    :class:`agents.goals.FrontierGoalEnv`'s ``global_state``), the value function reads it
    through its own ``state_features``-wide encoder and the actor does not: a centralised
    critic with decentralised actors (MAPPO, Yu et al. 2022). At inference only the actor
    runs, so ``state`` may be zeros (:class:`agents.sb3_explorer.SB3Explorer` passes zeros).
    """

    def __init__(self, observation_space: spaces.Dict, action_space: spaces.Space,
                 lr_schedule, net_arch: dict | None = None, mask_empty: bool = True,
                 cost_prior: float = 0.0, state_features: int = 128, **kwargs) -> None:
        if not isinstance(action_space, spaces.Discrete):
            raise TypeError(f"SectorPolicy needs a Discrete action space, got {action_space}")
        frontiers = observation_space.spaces.get("frontiers") if isinstance(
            observation_space, spaces.Dict) else None
        if frontiers is None or frontiers.shape[0] != action_space.n:
            raise ValueError("SectorPolicy needs a 'frontiers' observation of shape "
                             f"({action_space.n}, F), one row per action")
        net_arch = net_arch or {"pi": [64], "vf": [64]}
        self._widths = (int(net_arch.get("pi", [64])[0]), int(net_arch.get("vf", [64])[0]))
        self._sectors, self._row = frontiers.shape
        self._mask_empty = bool(mask_empty)
        self._cost_prior = cost_prior
        self._state_features = int(state_features)
        self._n_state = self._state_features if "state" in observation_space.spaces else 0
        kwargs.setdefault("features_extractor_class", TopoExplorerExtractor)
        kwargs["features_extractor_kwargs"] = {**kwargs.get("features_extractor_kwargs", {}),
                                               "pass_through": ("frontiers",),
                                               "state_features": self._n_state}
        super().__init__(observation_space, action_space, lr_schedule, net_arch=net_arch,
                         **kwargs)

    def _get_constructor_parameters(self) -> dict:
        return {**super()._get_constructor_parameters(), "mask_empty": self._mask_empty,
                "cost_prior": self._cost_prior, "state_features": self._state_features}

    def _build_mlp_extractor(self) -> None:
        pi, vf = self._widths
        self.mlp_extractor = SectorLatent(self.features_dim, self._sectors * self._row, pi, vf,
                                          self._n_state)

    def _build(self, lr_schedule) -> None:
        super()._build(lr_schedule)
        pi = self._widths[0]
        self.action_net = SectorScorer(pi, self._sectors, self._row, pi, self._mask_empty,
                                       self._cost_prior)
        if self.ortho_init:
            self.action_net.apply(functools.partial(self.init_weights, gain=np.sqrt(2)))
            self.init_weights(self.action_net.net[-1], gain=0.01)
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1),
                                              **self.optimizer_kwargs)
