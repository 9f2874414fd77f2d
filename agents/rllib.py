"""RLlib (new API stack) for ``two_robot_explore`` and teams of ``N`` robots
(``multi_robot_explore``): PPO with parameter sharing through RLlib's
``ParallelPettingZooEnv``, sampling scaled out over Ray env runners (``train.py --backend
rllib``). Needs the ``rllib`` extra (``pip install 'topomerge[rllib]'``); importing this module
without it raises an ``ImportError`` that says so.

* **Env** — :func:`env_creator` (registered as :data:`ENV_NAME`) builds
  :func:`agents.goals.make_env` (goal or motion level; the config's ``n_robots`` is the
  team size), wraps it in :class:`LightInfoEnv` and
  then in ``ParallelPettingZooEnv``. ``LightInfoEnv`` keeps only finite numbers in the infos:
  ``two_robot_explore``'s infos also carry the robots' live occupancy grids and maps (and NaN
  merge errors before a merge), which RLlib would store in every episode step and ship from
  the env runners to the learner. It also mixes the env runner's index into reset seeds:
  RLlib seeds runner ``k``'s ``i``-th env with ``seed + k + i``, so without it runners would
  share worlds.
* **Policy** — :class:`TopoExplorerModule`, a ``TorchRLModule`` with the value function API,
  wrapping the SB3 path's encoder (:class:`agents.policy.TopoExplorerExtractor`: a CNN on the
  ``local_map`` image, an MLP on the vectors, a graph encoder on the padded topological map)
  and, at the goal level, its per-sector scorer. RLlib's default catalog has no encoder for a
  ``Dict`` of an image, vectors and a graph, and its ``FlattenObservations`` connector would
  feed the 64 × 64 map to an MLP as 4096 unrelated inputs; reusing the SB3 network keeps the
  image's 2-D structure and makes the two backends differ in the algorithm's implementation
  only. One module id (:data:`POLICY_ID`) serves every robot: parameter sharing.
* **Metrics** — :class:`ExploreMetrics` logs true/shared coverage, overlap, merges and merge
  errors at every episode end (``env_runners/explore/...`` in the training results).
* **Evaluation** — :class:`RLlibPolicy` gives a trained module SB3's ``predict``, so
  :class:`agents.sb3_explorer.SB3Explorer` drives it in :mod:`agents.evaluation` like an SB3
  model (goal-level decisions held ``goal_hold`` steps).

Checkpoints are RLlib's own (``Algorithm.save_to_path``), written by :func:`save_checkpoint`
into a temporary folder and renamed, with :data:`POLICY_FILE` (level and hold) beside them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from pettingzoo import ParallelEnv
from torch import nn

from agents.goals import LEVELS, default_hold, make_env
from agents.metrics import EPISODE_INFO_KEYS
from agents.motion import COMMANDS
from agents.policy import SectorLatent, SectorScorer, TopoExplorerExtractor
from agents.sb3_explorer import sample_action
from topo.fileio import atomic_write_dir

EXTRA_HINT = ("agents.rllib needs the 'rllib' extra (RLlib's dependencies: dm-tree, pyarrow, "
              "lz4, ...): pip install 'topomerge[rllib]'")

try:
    import tree  # noqa: F401  (dm-tree: RLlib needs it and ray's base install lacks it)
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.callbacks.callbacks import RLlibCallback
    from ray.rllib.core.columns import Columns
    from ray.rllib.core.rl_module.apis import ValueFunctionAPI
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModule, RLModuleSpec
    from ray.rllib.core.rl_module.torch import TorchRLModule
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
    from ray.tune.registry import register_env
except ImportError as exc:  # pragma: no cover - exercised with the extra uninstalled
    raise ImportError(f"{EXTRA_HINT} ({exc})") from exc

ENV_NAME = "topomerge_two_robot_explore"
"""The name :func:`register` gives :func:`env_creator` in Ray's registry."""

POLICY_ID = "shared"
"""The one RLModule every robot maps to (parameter sharing)."""

POLICY_FILE = "topomerge_policy.json"
"""Written into every checkpoint folder: the level and hold the policy was trained with."""

MODULE_PATH = ("learner_group", "learner", "rl_module", POLICY_ID)
"""Where the shared module lies inside an algorithm checkpoint."""

DEFAULT_MODEL_CONFIG = {"sector_head": False, "mask_empty": True, "cost_prior": 0.0, "pi": 64,
                        "vf": 64}
"""``model_config`` of :class:`TopoExplorerModule`: the per-sector scorer at the goal level
(masking sectors without a reachable frontier: ``mask_empty``; ``cost_prior`` as
:class:`agents.policy.SectorPolicy`'s), and the widths of the actor's
and the critic's layer (as ``train.py``'s SB3 ``net_arch``)."""

RLLIB_KEYS = frozenset({"vf_share_layers"})
"""``model_config`` keys RLlib's PPO adds itself; ignored (actor and critic always share the
encoder, as SB3's do)."""


# ------------------------------------------------------------------------------- env
def light_info(info: Mapping[str, Any]) -> dict[str, bool | int | float]:
    """The finite scalar entries of one agent's info (bools, ints, floats; NaN and inf,
    arrays, grids and maps dropped)."""
    out: dict[str, bool | int | float] = {}
    for key, value in info.items():
        if isinstance(value, (bool, np.bool_)):
            out[key] = bool(value)
        elif isinstance(value, (int, np.integer)):
            out[key] = int(value)
        elif isinstance(value, (float, np.floating)) and math.isfinite(value):
            out[key] = float(value)
    return out


class LightInfoEnv(ParallelEnv):
    """A ``ParallelEnv`` wrapper for RLlib: light infos (:func:`light_info`) and reset seeds
    mixed with a ``stream`` number (the env runner's index; module docstring).

    Args:
        env: a ``two_robot_explore`` ``ParallelEnv`` (or :class:`agents.goals.FrontierGoalEnv`).
        stream: an integer ``>= 0``; ``reset(seed=s)`` seeds ``env`` with a number derived from
            ``(s, stream)``, so equal seeds on different streams give different worlds.
    """

    def __init__(self, env: ParallelEnv, stream: int = 0) -> None:
        if not hasattr(env, "possible_agents"):
            raise TypeError(f"env must be a PettingZoo ParallelEnv, got {type(env).__name__}")
        if isinstance(stream, bool) or not isinstance(stream, (int, np.integer)) or stream < 0:
            raise ValueError(f"stream must be an integer >= 0, got {stream!r}")
        self.env = env
        self.stream = int(stream)
        self.possible_agents = list(env.possible_agents)
        self.agents: list[str] = []
        self.metadata = env.metadata
        self.render_mode = getattr(env, "render_mode", None)

    def observation_space(self, agent: str) -> spaces.Space:
        return self.env.observation_space(agent)

    def action_space(self, agent: str) -> spaces.Space:
        return self.env.action_space(agent)

    def reset(self, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict, dict]:
        if seed is not None:
            seed = int(np.random.SeedSequence([int(seed), self.stream]).generate_state(1)[0])
        obs, infos = self.env.reset(seed=seed, options=options)
        self.agents = list(self.env.agents)
        return obs, {a: light_info(i) for a, i in infos.items()}

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        obs, rewards, terms, truncs, infos = self.env.step(actions)
        self.agents = list(self.env.agents)
        return obs, rewards, terms, truncs, {a: light_info(i) for a, i in infos.items()}

    def render(self) -> Any:
        return self.env.render()

    def close(self) -> None:
        self.env.close()


def env_creator(env_config: Mapping[str, Any]) -> ParallelPettingZooEnv:
    """RLlib's env factory: ``env_config`` holds ``config`` (the env's ``EnvConfig`` fields),
    ``level``, ``hold``, ``frontier_shaping`` and ``commands`` (:func:`agents.goals.make_env`);
    RLlib's ``EnvContext`` adds the env runner's ``worker_index`` (the :class:`LightInfoEnv`
    stream)."""
    allowed = ["commands", "config", "frontier_shaping", "hold", "level"]
    unknown = set(env_config) - set(allowed)
    if unknown:
        raise ValueError(f"env_config has unknown keys {sorted(unknown)}; allowed: {allowed}")
    env = make_env(dict(env_config.get("config", {})), env_config.get("level", "motion"),
                   env_config.get("hold"), env_config.get("frontier_shaping", 0.0),
                   commands=env_config.get("commands", "continuous"))
    stream = int(getattr(env_config, "worker_index", 0) or 0)
    return ParallelPettingZooEnv(LightInfoEnv(env, stream=stream))


def register() -> None:
    """Register :func:`env_creator` as :data:`ENV_NAME` (in this process; Ray ships the
    registry to the env runners)."""
    register_env(ENV_NAME, env_creator)


# ------------------------------------------------------------------------------- policy
def _orthogonal(module: nn.Module, gain: float) -> None:
    for m in module.modules():
        if isinstance(m, (nn.Linear, nn.Conv2d)):
            nn.init.orthogonal_(m.weight, gain=gain)
            if m.bias is not None:
                m.bias.data.fill_(0.0)


class _Latent(nn.Module):
    """One tanh layer each for the actor and the critic over the shared features (SB3's
    ``MlpExtractor`` with ``net_arch={"pi": [pi], "vf": [vf]}``)."""

    def __init__(self, features_dim: int, pi: int, vf: int) -> None:
        super().__init__()
        self.policy_net = nn.Sequential(nn.Linear(features_dim, pi), nn.Tanh())
        self.value_net = nn.Sequential(nn.Linear(features_dim, vf), nn.Tanh())

    def forward_actor(self, features: torch.Tensor) -> torch.Tensor:
        return self.policy_net(features)

    def forward_critic(self, features: torch.Tensor) -> torch.Tensor:
        return self.value_net(features)


class TopoExplorerModule(TorchRLModule, ValueFunctionAPI):
    """PPO's actor-critic for the explorer's ``Dict`` observation (module docstring).

    The observation space must be ``two_robot_explore``'s per-robot ``Dict`` (plus
    ``frontiers`` at the goal level); the action space ``Discrete`` (categorical logits) or
    ``Box`` (a diagonal Gaussian: the mean from the network, a learnt state-independent log
    standard deviation, as SB3's PPO). ``uint8`` observations (the ``local_map`` image) are
    scaled to ``[0, 1]`` as SB3 does. ``model_config``: :data:`DEFAULT_MODEL_CONFIG`'s keys.

    Raises:
        TypeError: the observation space is not a ``Dict`` or the action space neither
            ``Discrete`` nor ``Box``.
        ValueError: unknown ``model_config`` keys; ``sector_head`` without a ``frontiers``
            observation of one row per action.
    """

    def setup(self) -> None:
        given = {k: v for k, v in (self.model_config or {}).items() if k not in RLLIB_KEYS}
        unknown = set(given) - set(DEFAULT_MODEL_CONFIG)
        if unknown:
            raise ValueError(f"model_config has unknown keys {sorted(unknown)}; allowed: "
                             f"{sorted(DEFAULT_MODEL_CONFIG)}")
        cfg = {**DEFAULT_MODEL_CONFIG, **given}
        obs_space, act_space = self.observation_space, self.action_space
        if not isinstance(obs_space, spaces.Dict):
            raise TypeError("TopoExplorerModule needs a Dict observation space, got "
                            f"{type(obs_space).__name__}")
        if not isinstance(act_space, (spaces.Discrete, spaces.Box)):
            raise TypeError(f"TopoExplorerModule needs a Discrete or Box action space, got "
                            f"{act_space}")
        self.sector_head = bool(cfg["sector_head"])
        frontiers = obs_space.spaces.get("frontiers")
        if self.sector_head and (not isinstance(act_space, spaces.Discrete) or frontiers is None
                                 or frontiers.shape[0] != act_space.n):
            raise ValueError("model_config sector_head=True needs a Discrete action space and a "
                             "'frontiers' observation of shape (n_actions, F)")
        pi, vf = int(cfg["pi"]), int(cfg["vf"])
        self.image_keys = tuple(k for k, s in obs_space.spaces.items()
                                if isinstance(s, spaces.Box) and s.dtype == np.uint8)
        self.encoder = TopoExplorerExtractor(
            obs_space, pass_through=("frontiers",) if self.sector_head else ())
        n = self.encoder.features_dim
        self.log_std: nn.Parameter | None = None
        if self.sector_head:
            sectors, row = frontiers.shape
            self.latent = SectorLatent(n, sectors * row, pi, vf)
            self.actor = SectorScorer(pi, sectors, row, pi, bool(cfg["mask_empty"]),
                                      cfg["cost_prior"], name="model_config cost_prior")
        else:
            self.latent = _Latent(n, pi, vf)
            if isinstance(act_space, spaces.Discrete):
                self.actor = nn.Linear(pi, int(act_space.n))
            else:
                dim = int(np.prod(act_space.shape))
                self.actor = nn.Linear(pi, dim)
                self.log_std = nn.Parameter(torch.zeros(dim))
        self.critic = nn.Linear(vf, 1)
        # SB3's initialisation (ortho_init), so both backends start alike
        _orthogonal(self.encoder, math.sqrt(2))
        _orthogonal(self.latent, math.sqrt(2))
        _orthogonal(self.actor, math.sqrt(2))
        last = self.actor.net[-1] if self.sector_head else self.actor
        _orthogonal(last, 0.01)
        _orthogonal(self.critic, 1.0)

    def _features(self, batch: Mapping[str, Any]) -> torch.Tensor:
        obs = batch[Columns.OBS]
        scaled = {k: v.float() / 255.0 if k in self.image_keys else v.float()
                  for k, v in obs.items()}
        return self.encoder(scaled)

    def _logits(self, features: torch.Tensor) -> torch.Tensor:
        out = self.actor(self.latent.forward_actor(features))
        if self.log_std is None:
            return out
        return torch.cat([out, self.log_std.expand_as(out)], dim=-1)

    def _forward(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        return {Columns.ACTION_DIST_INPUTS: self._logits(self._features(batch))}

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        features = self._features(batch)
        return {Columns.ACTION_DIST_INPUTS: self._logits(features),
                Columns.EMBEDDINGS: features}

    def compute_values(self, batch: dict[str, Any],
                       embeddings: torch.Tensor | None = None) -> torch.Tensor:
        if embeddings is None:
            embeddings = self._features(batch)
        return self.critic(self.latent.forward_critic(embeddings)).squeeze(-1)


# ------------------------------------------------------------------------------- metrics
EPISODE_KEYS = EPISODE_INFO_KEYS
"""Infos logged (mean over episode ends) under ``explore/``
(:data:`agents.metrics.EPISODE_INFO_KEYS`)."""


class ExploreMetrics(RLlibCallback):
    """At each episode end, logs robot 0's last info: ``explore/`` true and shared coverage,
    overlap, merges (a team's contacts and fused robots too), the episode's env steps;
    ``merge/`` acceptance and (when a merge exists) its rotation and translation errors. Means
    over the last 100 episodes."""

    def on_episode_end(self, *, episode: Any, metrics_logger: Any = None, env_runner: Any = None,
                       **kwargs: Any) -> None:
        if metrics_logger is None:
            return
        infos = episode.get_infos(-1)
        if not infos:
            return
        info = infos[min(infos)]

        def log(key: tuple[str, str], value: float) -> None:
            metrics_logger.log_value(key, float(value), reduce="mean", window=100)

        for key in EPISODE_KEYS:
            if key in info:
                log(("explore", key), info[key])
        hold = 1
        if env_runner is not None:
            env_config = env_runner.config.env_config
            hold = int(env_config.get("hold") or default_hold(env_config.get("level")))
        log(("explore", "episode_env_steps"),
            (episode.env_t - 1) * hold + int(info.get("env_steps", hold)))
        if "merge_accepted" in info:
            log(("merge", "accepted"), info["merge_accepted"])
        for key in ("merge_rotation_error_deg", "merge_translation_error_m"):
            if key in info:
                log(("merge", key), info[key])


# ------------------------------------------------------------------------------- config
def ppo_config(*, env_config: Mapping[str, Any], level: str = "goals", hold: int | None = None,
               frontier_shaping: float = 0.0, commands: str = "continuous",
               sector_head: bool = True,
               mask_sectors: bool = True, cost_prior: float = 0.0,
               seed: int = 0, num_env_runners: int = 1,
               envs_per_runner: int = 1, train_batch_size: int = 256, minibatch_size: int = 64,
               num_epochs: int = 4, lr: float = 3e-4, gamma: float = 0.99,
               gae_lambda: float = 0.95, entropy_coeff: float = 0.005,
               clip_param: float = 0.2, num_gpus: int = 0) -> PPOConfig:
    """RLlib's ``PPOConfig`` on the new API stack for ``two_robot_explore`` (module docstring).

    Args:
        env_config: the env's ``EnvConfig`` fields (``n_robots``: the team size).
        level, hold, frontier_shaping, commands: :func:`agents.goals.make_env`'s (``gamma``
            is per decision: pass ``gamma ** hold`` for a per-step discount; ``commands="arcs"``
            at the motion level: a categorical policy over :data:`agents.motion.ARCS`).
        sector_head: :class:`TopoExplorerModule`'s per-sector scorer (goal level only).
        mask_sectors: with the sector scorer, sectors without a reachable frontier cannot be
            chosen (:class:`agents.policy.SectorPolicy`'s ``mask_empty``).
        cost_prior: :class:`agents.policy.SectorPolicy`'s (logits per metre of cost gap).
        seed: RLlib's seed (env runner ``k`` seeds its envs from ``seed + k``).
        num_env_runners: Ray actors sampling in parallel (``0``: sample in the driver).
        envs_per_runner: envs each runner steps in turn.
        train_batch_size: env steps (decisions of every robot) per PPO update; each gives
            one transition per robot to the shared policy.
        minibatch_size: transitions per gradient step.
        num_epochs, lr, gae_lambda, entropy_coeff, clip_param: PPO's (as SB3's defaults
            elsewhere: value loss weight 0.5, gradient norm clipped at 0.5, no KL penalty).
        num_gpus: GPUs of the (one, local) learner.

    Raises:
        ValueError: an unknown ``level`` or ``commands``; ``commands="arcs"`` at the goal level.
    """
    if level not in LEVELS:
        raise ValueError(f"level must be one of {list(LEVELS)}, got {level!r}")
    if commands not in COMMANDS:
        raise ValueError(f"commands must be one of {list(COMMANDS)}, got {commands!r}")
    if commands != "continuous" and level != "motion":
        raise ValueError(f"commands={commands!r} applies to level='motion' only")
    register()
    if hold is None:
        hold = default_hold(level)
    model_config = {**DEFAULT_MODEL_CONFIG, "sector_head": bool(sector_head and level == "goals"),
                    "mask_empty": bool(mask_sectors), "cost_prior": float(cost_prior)}
    return (
        PPOConfig()
        .environment(ENV_NAME, env_config={"config": dict(env_config), "level": level,
                                           "hold": hold, "frontier_shaping": frontier_shaping,
                                           "commands": commands},
                     disable_env_checking=True)
        .multi_agent(policies={POLICY_ID},
                     policy_mapping_fn=_shared_policy)
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={
            POLICY_ID: RLModuleSpec(module_class=TopoExplorerModule,
                                    model_config=model_config)}))
        .env_runners(num_env_runners=num_env_runners, num_envs_per_env_runner=envs_per_runner,
                     num_cpus_per_env_runner=1)
        .learners(num_learners=0, num_gpus_per_learner=num_gpus)
        .training(train_batch_size_per_learner=train_batch_size, minibatch_size=minibatch_size,
                  num_epochs=num_epochs, lr=lr, gamma=gamma, lambda_=gae_lambda,
                  entropy_coeff=entropy_coeff, clip_param=clip_param, vf_loss_coeff=0.5,
                  grad_clip=0.5, use_kl_loss=False)
        .callbacks(ExploreMetrics)
        .debugging(seed=seed, log_level="ERROR")
        .reporting(metrics_num_episodes_for_smoothing=100)
    )


def _shared_policy(agent_id: str, episode: Any = None, **kwargs: Any) -> str:
    return POLICY_ID


def agent_steps(algo: Any) -> int:
    """Agent decisions (every robot's) an RLlib ``Algorithm`` has sampled so far, restored
    checkpoints included."""
    per_agent = algo.metrics.peek(("env_runners", "num_agent_steps_sampled_lifetime"),
                                  default={})
    return int(sum(per_agent.values()))


def scalars(result: Mapping[str, Any]) -> dict[str, float]:
    """The TensorBoard scalars of one ``Algorithm.train()`` result, named as the SB3 path's:
    ``rollout/ep_rew_mean`` (per robot) and ``ep_len_mean`` (decisions), ``train/`` losses,
    ``explore/`` and ``merge/`` (:class:`ExploreMetrics`). Non-finite values are left out."""
    out: dict[str, float] = {}
    runners = result.get("env_runners", {})
    returns = runners.get("agent_episode_returns_mean", {})
    if returns:
        out["rollout/ep_rew_mean"] = float(np.mean(list(returns.values())))
    if "episode_len_mean" in runners:
        out["rollout/ep_len_mean"] = float(runners["episode_len_mean"])
    for group in ("explore", "merge"):
        for key, value in runners.get(group, {}).items():
            out[f"{group}/{key}"] = float(value)
    learner = result.get("learners", {}).get(POLICY_ID, {})
    for ours, theirs in (("policy_loss", "policy_loss"), ("value_loss", "vf_loss"),
                         ("entropy", "entropy"), ("explained_variance", "vf_explained_var")):
        if theirs in learner:
            out[f"train/{ours}"] = float(learner[theirs])
    return {k: v for k, v in out.items() if math.isfinite(v)}


TIMER_EMA_COEFF = 0.01
"""The weight of the newest value in RLlib's timers (``EmaStats``' default)."""


class IterationTimes:
    """Seconds one training iteration spent sampling (the env runners) and updating (the
    learner, while the runners wait): what bounds the gain of more runners.

    RLlib reports its ``timers`` as exponential moving averages ``E_n = c x_n + (1 - c)
    E_{n-1}`` (``c`` = :data:`TIMER_EMA_COEFF`, ``E_1 = x_1``); :meth:`update` recovers ``x_n``
    from consecutive results. A pair that does not fit within the iteration's wall time (another
    averaging, or the first iteration after a restore) is not reported.
    """

    KEYS = (("sample_s", "env_runner_sampling_timer"), ("learn_s", "learner_update_timer"))

    def __init__(self) -> None:
        self.previous: dict[str, float] | None = None
        self.first = True

    def update(self, result: Mapping[str, Any], restored: bool = False) -> dict[str, float]:
        """``{"time/sample_s": ..., "time/learn_s": ...}`` of this result's iteration, or
        ``{}`` when they cannot be recovered; ``restored``: the algorithm was restored before
        its first iteration here (its averages started earlier)."""
        timers = result.get("timers", {})
        now = {ours: float(timers[theirs]) for ours, theirs in self.KEYS if theirs in timers}
        previous, self.previous = self.previous, now
        first, self.first = self.first, False
        if len(now) < len(self.KEYS):
            return {}
        if first and not restored:
            values = now
        elif previous is None or first:
            return {}
        else:
            c = TIMER_EMA_COEFF
            values = {k: (now[k] - (1 - c) * previous[k]) / c for k in now}
        wall = float(result.get("time_this_iter_s", math.inf))
        if min(values.values()) < 0 or sum(values.values()) > 1.01 * wall:
            return {}
        return {f"time/{k}": v for k, v in values.items()}


# ------------------------------------------------------------------------------- checkpoints
def save_checkpoint(algo: Any, path: str | Path, level: str, hold: int) -> Path:
    """``algo.save_to_path`` into a temporary folder beside ``path``, add :data:`POLICY_FILE`,
    then move it to ``path`` (replacing an older checkpoint there;
    :func:`topo.fileio.atomic_write_dir`). Returns ``path``."""

    def write(tmp: Path) -> None:
        algo.save_to_path(str(tmp))
        (tmp / POLICY_FILE).write_text(json.dumps({"level": level, "hold": int(hold)}) + "\n")

    return atomic_write_dir(path, write)


class RLlibPolicy:
    """A trained :class:`TopoExplorerModule` with SB3's ``predict``, so
    :class:`agents.sb3_explorer.SB3Explorer` drives it (module docstring).

    Args:
        module: the shared RLModule (``algo.get_module(POLICY_ID)`` or from a checkpoint).
        hold: env steps each decision is held (``train.py``'s ``hold``); default
            :data:`~agents.goals.DEFAULT_HOLD` for a goal-level module (one that observes
            ``frontiers``), 1 at the motion level. Exposed as ``goal_hold`` / ``motion_hold``,
            the attributes :class:`~agents.sb3_explorer.SB3Explorer` reads, with
            ``motion_commands``: ``"arcs"`` for a motion-level module with a ``Discrete``
            action space (an index into :data:`agents.motion.ARCS`), else ``"continuous"``.
    """

    def __init__(self, module: RLModule, hold: int | None = None) -> None:
        if not hasattr(module, "forward_inference"):
            raise TypeError(f"module must be an RLlib RLModule, got {type(module).__name__}")
        self.module = module
        self.observation_space = module.observation_space
        self.action_space = module.action_space
        goals = "frontiers" in getattr(self.observation_space, "spaces", {})
        if hold is None:
            hold = default_hold("goals" if goals else "motion")
        self.goal_hold = self.motion_hold = int(hold)
        self.motion_commands = ("arcs" if not goals and isinstance(self.action_space,
                                                                    spaces.Discrete)
                                else "continuous")

    @classmethod
    def load(cls, checkpoint: str | Path) -> RLlibPolicy:
        """The policy of an algorithm checkpoint folder written by :func:`save_checkpoint`."""
        checkpoint = Path(checkpoint)
        meta = checkpoint / POLICY_FILE
        if not meta.is_file():
            raise FileNotFoundError(f"no RLlib checkpoint of train.py at {str(checkpoint)!r} "
                                    f"(missing {POLICY_FILE})")
        module = RLModule.from_checkpoint(checkpoint.joinpath(*MODULE_PATH))
        return cls(module, json.loads(meta.read_text())["hold"])

    def _dist_inputs(self, observation: Mapping[str, Any]) -> torch.Tensor:
        obs = {k: torch.as_tensor(np.asarray(observation[k])[None])
               for k in self.observation_space.spaces}
        with torch.no_grad():
            return self.module.forward_inference({Columns.OBS: obs})[Columns.ACTION_DIST_INPUTS]

    def _action(self, action: np.ndarray) -> np.ndarray | int:
        if isinstance(self.action_space, spaces.Discrete):
            return int(action)
        return np.clip(action, self.action_space.low, self.action_space.high).astype(
            self.action_space.dtype)

    def predict(self, observation: Mapping[str, Any],
                deterministic: bool = True) -> tuple[np.ndarray | int, None]:
        """The action for one robot's observation: the distribution's mode when
        ``deterministic``, else a sample (torch's generator; :meth:`sample` takes one)."""
        dist = self.module.get_inference_action_dist_cls().from_logits(
            self._dist_inputs(observation))
        if deterministic:
            dist = dist.to_deterministic()
        return self._action(dist.sample()[0].numpy()), None

    def sample(self, observation: Mapping[str, Any], rng: np.random.Generator
               ) -> np.ndarray | int:
        """An action sampled with ``rng`` (categorical logits at ``Discrete``; a diagonal
        Gaussian of mean and log-std at ``Box``, clipped to the space), so that
        :class:`~agents.sb3_explorer.SB3Explorer` repeats a seeded sampled episode."""
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        inputs = self._dist_inputs(observation).double()
        if isinstance(self.action_space, spaces.Discrete):
            dist = torch.distributions.Categorical(logits=inputs)
        else:
            mean, log_std = inputs.chunk(2, dim=-1)
            dist = torch.distributions.Normal(mean, log_std.exp())
        return sample_action(dist, rng, self.action_space)
