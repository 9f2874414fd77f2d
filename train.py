"""Train an exploration policy with PPO, map fusion inside the RL loop, on Stable-Baselines3
(default) or RLlib (``--backend rllib``, sampling scaled out over a Ray cluster).

All robots share one policy (parameter sharing): with SB3 each robot of each env is one
sub-environment of a :class:`agents.sb3.ParallelVecEnv`; with RLlib every robot maps to one
RLModule through ``ParallelPettingZooEnv`` (:mod:`agents.rllib`). ``--n-robots N`` trains a team
of ``N`` robots (2, the default, is ``two_robot_explore_v0`` exactly; more is
``multi_robot_explore_v0``, whose ``teammates`` observation the policy encodes as a set:
:class:`agents.policy.TopoExplorerExtractor`), ``--comm-range R`` limits their contact to
``R`` metres (the env's ``comm.range``). The policy acts at one of two
levels (``--level``): ``goals`` (default) picks which frontier sector to explore next every
``--hold`` steps and a frontier planner drives there (:mod:`agents.goals`); ``motion`` outputs
the env's velocity commands every step. The reward is the env's team reward — the growth of the
*shared* map, i.e. of robot 0's map united with robot 1's map moved by the latest accepted
``fusion.merge_maps`` transform — so a wrong merge costs reward (``--reward-mode oracle`` uses the
true union instead, for ablations).

    python train.py --total-timesteps 200000 --n-envs 4 --seed 1
    python train.py --level motion --motion-commands arcs --hold 4 --frontier-shaping 1.0 \
        --reward-mode individual --ent-coef 0.01 --no-eval-deterministic \
        --total-timesteps 1000000                    # velocity commands (agents.motion)
    python train.py --central-critic --world-size-max 20    # goal level, MAPPO-style critic
    python train.py --backend rllib --num-env-runners 2            # a local Ray cluster
    python train.py --backend rllib --address auto --num-env-runners 8   # joins `ray start`'s
    python train.py --level motion --n-robots 4 --comm-range 5     # a team of four robots
    python train.py --help
    tensorboard --logdir runs

A run writes ``runs/<env>__<seed>__<time>/`` (``<env>`` is ``two_robot_explore_v0``, or
``multi_robot_explore_v0_n<N>`` for a team of ``N``): ``tb/`` (TensorBoard: reward, true and shared
coverage, merge acceptance and errors, episode length, agent-steps/s), ``checkpoints/`` (atomic,
resumable with ``--resume RUN_DIR``), ``eval.json`` / ``eval.md`` / ``eval_coverage.png``
(periodic evaluation of the policy against ``Frontier`` and ``RandomWalk`` on fixed seeds,
:mod:`agents.evaluation`), the final policy: ``model.zip`` (SB3, usable as
``--explorer sb3:RUN_DIR/model.zip``) or ``rllib/`` (an RLlib algorithm checkpoint,
:meth:`agents.rllib.RLlibPolicy.load`), and the best policy those evaluations saw
(``best_model.zip`` or ``rllib_best/``, with its step and scores in ``best.json``; as SB3's
``EvalCallback`` keeps one): a run can peak before its end.

Readable like CleanRL's ``ppo.py``: ``Args`` below, ``main(args)``, importable for tests.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Literal, get_args, get_origin, get_type_hints

import numpy as np
import torch
import tyro
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import VecMonitor
from tqdm.auto import tqdm

from agents import evaluation
from agents.goals import default_hold, make_env
from agents.metrics import EPISODE_INFO_KEYS
from agents.policy import SectorPolicy, TopoExplorerExtractor
from agents.sb3 import ParallelVecEnv
from agents.sb3_explorer import sb3_team
from topo.fileio import atomic_write, atomic_write_dir, atomic_write_json
from topo.validation import check_real

ENV_ID = "two_robot_explore_v0"
"""The env of a two-robot run (:func:`run_env_id` names any team's)."""

DEFAULT_WORLD_SIZE_MAX = 20.0
"""The largest training building by default (``Args.world_size_max``): the held-out worlds of
``benchmarks/training_eval.py`` are 10–20 m, and training on that range is the measured recipe
(``benchmarks/training.md``)."""


def run_env_id(n_robots: int) -> str:
    """The env part of a run's folder name: :data:`ENV_ID` for two robots,
    ``multi_robot_explore_v0_n<N>`` for a team of ``N``."""
    return ENV_ID if n_robots == 2 else f"multi_robot_explore_v0_n{n_robots}"


@dataclass
class Args:
    """PPO on two_robot_explore_v0 (or a team of N robots) with parameter sharing (all robots,
    one policy)."""

    backend: Literal["sb3", "rllib"] = "sb3"
    """PPO implementation: Stable-Baselines3 (worker processes on this machine) or RLlib
    (env runners on a Ray cluster; needs the ``rllib`` extra)."""
    total_timesteps: int = 200_000
    """Agent-steps to train for (each env step gives one per robot; at the goals level a
    decision counts its ``hold`` env steps)."""
    n_robots: int = 2
    """Robots in the team, 2–8: 2 trains on ``two_robot_explore_v0`` (as before), more on
    ``multi_robot_explore_v0``; one policy drives them all."""
    comm_range: float | None = None
    """Robots closer than this many metres are in contact and exchange maps (the env's
    ``comm.range``, multi-hop); default: always in contact."""
    known_poses: bool = False
    """The robots know their relative start poses (the env's ``mapping.merge_method="known"``:
    teammates are placed from the first step, no merging), in training and evaluation; the
    setting most multi-robot exploration work assumes (``benchmarks/training.md``)."""
    level: Literal["goals", "motion"] = "goals"
    """What the policy decides: a frontier sector every ``hold`` steps (a planner drives), or
    the velocity command every step."""
    hold: int | None = None
    """Env steps each decision is held: a goal (default 10) or a velocity command (action
    repeat; default 1, see :mod:`agents.motion`)."""
    frontier_shaping: float = 0.0
    """``level="motion"``: reward per metre of progress along the path to the nearest
    frontier (potential-based shaping, :class:`agents.motion.MotionEnv`); 0: none."""
    sector_head: bool = True
    """At the goals level, score every sector with one shared network
    (:class:`agents.policy.SectorPolicy`, or :class:`agents.rllib.TopoExplorerModule`'s
    sector head); ``False``: one linear layer from the context to the 8 logits."""
    mask_sectors: bool = True
    """With the sector scorer, never choose a sector without a reachable frontier (action
    masking read from the ``frontiers`` observation); ``False`` lets the policy pick an empty
    sector, where the planner falls back to the cheapest frontier anywhere."""
    cost_prior: float = 1.0
    """With the sector scorer, logits subtracted per metre by which a sector's frontier is
    dearer than the cheapest one: > 0 starts the policy as a soft ``Frontier`` that PPO
    refines (:class:`agents.policy.SectorPolicy`); 0 learns from scratch
    (``benchmarks/training.md`` compares both)."""
    central_critic: bool = False
    """At the goals level with the sector scorer (SB3): the value function also reads the
    env's global ``state()`` (MAPPO-style centralised critic; the actors stay decentralised,
    :class:`agents.policy.SectorPolicy`)."""
    seed: int = 1
    """Seed of everything: envs, policy initialisation, evaluation worlds."""
    n_envs: int = 4
    """Envs run in parallel (``n_robots`` each, so ``n_robots × n_envs`` policy
    sub-environments)."""
    n_workers: int | None = None
    """``--backend sb3``: worker processes stepping the envs (1: in this process); default one
    per CPU core, at
    most ``n_envs`` (on 2 cores: 946 against 657 agent-steps/s at the goals level,
    ``benchmarks/train_speed.py``)."""
    num_env_runners: int | None = None
    """``--backend rllib``: Ray actors sampling in parallel (0: sample in this process), the
    ``n_envs`` envs split between them; default one per CPU core, at most ``n_envs``."""
    address: str | None = None
    """``--backend rllib``: the Ray cluster to join (``auto``, or ``HEAD_IP:6379`` as printed by
    ``ray start --head``); default: start a local one for this run."""
    reward_mode: Literal["shared", "oracle", "individual"] = "shared"
    """Env reward: growth of the fused shared map, of the true union, or per robot."""
    device: str = "cpu"
    """Torch device for the policy ("cpu", "cuda", "auto"; with RLlib anything but "cpu" gives
    the learner a GPU when torch sees one)."""
    world_size: tuple[float, float] = (10.0, 10.0)
    """Procedural building size in metres."""
    world_size_max: float | None = None
    """``--backend sb3``: train on buildings of several sizes, the ``n_envs`` envs spread
    evenly from ``world_size`` to this side (metres), each env's episodes lengthened in
    proportion (``max_cycles`` is the first's); evaluation stays on ``world_size``. Default:
    :data:`DEFAULT_WORLD_SIZE_MAX` (20 m: the measured recipe, ``benchmarks/training.md``), or
    every env on ``world_size`` when that is as large or the backend is RLlib. Set it to
    ``max(world_size)`` for one size."""
    max_cycles: int = 500
    """Env steps per episode (truncation); with 10 m buildings Frontier reaches 85 % in
    about 300–500 steps, so T85 separates explorers."""
    learning_rate: float = 3e-4
    """Adam learning rate."""
    lr_schedule: Literal["constant", "linear"] = "constant"
    """``constant``, or ``linear``: from ``learning_rate`` down to 0 at ``total_timesteps``
    (SB3's ``LinearSchedule``; ``--backend sb3`` only). A constant rate let a motion policy
    fall back after its best point (``benchmarks/training.md``)."""
    n_steps: int | None = None
    """Rollout length (policy decisions) per sub-environment between updates; default 32 at
    the goals level (a decision spans ``hold`` steps), 128 at the motion level."""
    batch_size: int | None = None
    """Minibatch size; default 64 at the goals level, 256 at the motion level."""
    n_epochs: int = 4
    """Optimisation epochs per rollout."""
    gamma: float = 0.99
    """Discount factor per env step (a goal decision discounts by ``gamma ** hold``)."""
    gae_lambda: float = 0.95
    """GAE lambda."""
    ent_coef: float = 0.005
    """Entropy bonus."""
    motion_commands: Literal["continuous", "arcs"] = "continuous"
    """``level="motion"``: the action is the env's ``(v, ω)`` box, or one of the few
    velocity commands of :data:`agents.motion.ARCS` (ahead, arcs, turns on the spot)."""
    log_std_init: float = 0.0
    """``level="motion"``, SB3: initial log standard deviation of the Gaussian velocity
    command (SB3's ``log_std_init``; 0 is a standard deviation of 1, the whole action range)."""
    clip_range: float = 0.2
    """PPO clip range."""
    eval_every: int = 50_000
    """Agent-steps between evaluations (0: only at the end)."""
    eval_episodes: int = 4
    """Fixed-seed evaluation worlds per evaluation."""
    eval_baselines: tuple[str, ...] = ("frontier", "random_walk")
    """Scripted explorers evaluated on the same worlds (once per run)."""
    eval_deterministic: bool = True
    """Evaluate the policy's most likely action; ``False`` samples it (seeded per episode:
    :class:`agents.sb3_explorer.SB3Explorer`) — a discrete motion-level policy's most likely
    command can loop where sampling does not."""
    eval_max_cycles: int | None = None
    """Env steps per evaluation episode; default ``3 * max_cycles``. Longer than training's
    episodes so that T85 is measured rather than cut off: in 500 steps ``RandomWalk`` never
    reaches 85 % of a 10 m building, and a T that the episode end censors is only a bound."""
    checkpoint_every: int = 50_000
    """Agent-steps between checkpoints (0: only at the end)."""
    runs_dir: Path = Path("runs")
    """Where run folders go."""
    run_name: str | None = None
    """Run folder name (default: <env>__<seed>__<time>); an existing one is overwritten."""
    resume: Path | None = None
    """Continue a run: its folder (latest checkpoint) or a checkpoint (an SB3 ``.zip``, an
    RLlib checkpoint folder), with the backend it was trained with."""
    progress: bool = True
    """Show a progress bar."""
    torch_threads: int = 1
    """torch.set_num_threads (1 is fastest on 2 cores with envs busy)."""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    """Extra env config (EnvConfig fields) for training and evaluation."""

    def __post_init__(self) -> None:
        hints = get_type_hints(Args)
        for f in fields(self):  # tyro checks the command line, this code's calls
            value, choices = getattr(self, f.name), get_args(hints[f.name])
            if get_origin(hints[f.name]) is Literal and value not in choices:
                raise ValueError(f"{f.name} must be one of {list(choices)}, got {value!r}")
        goals = self.level == "goals"
        from envs.explore.config import CommConfig, EnvConfig

        EnvConfig(n_robots=self.n_robots)  # n_robots: an integer, 2 to 8 (names the value)
        if self.comm_range is not None:
            CommConfig(range=self.comm_range)  # comm.range: a real > 0 (names the value)
        if not isinstance(self.known_poses, bool):
            raise TypeError(f"known_poses must be True or False, got {self.known_poses!r}")
        if self.hold is None:
            self.hold = default_hold(self.level)
        if self.n_steps is None:
            self.n_steps = 32 if goals else 128
        if self.batch_size is None:
            self.batch_size = 64 if goals else 256
        if self.eval_max_cycles is None and isinstance(self.max_cycles, int):
            self.eval_max_cycles = 3 * self.max_cycles
        envs = self.n_envs if isinstance(self.n_envs, int) else 1
        if self.n_workers is None:
            self.n_workers = max(1, min(os.cpu_count() or 1, envs))
        if self.backend == "rllib":
            if self.num_env_runners is None:
                self.num_env_runners = max(1, min(os.cpu_count() or 1, envs))
            value = self.num_env_runners
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"num_env_runners must be an integer >= 0, got {value!r}")
            if isinstance(self.n_envs, int) and value > self.n_envs:
                raise ValueError(f"num_env_runners must be <= n_envs ({self.n_envs}) so that "
                                 f"every runner has an env, got {value}")
            if self.address is not None and (not isinstance(self.address, str)
                                             or not self.address):
                raise ValueError(f"address must be a non-empty string, got {self.address!r}")
        else:
            for name in ("num_env_runners", "address"):
                if getattr(self, name) is not None:
                    raise ValueError(f"{name} applies to backend='rllib' only, got "
                                     f"{getattr(self, name)!r} with backend={self.backend!r}")
        for name in ("total_timesteps", "n_envs", "n_workers", "n_steps", "batch_size",
                     "n_epochs", "eval_episodes", "torch_threads", "max_cycles", "hold",
                     "eval_max_cycles"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        for name in ("eval_every", "checkpoint_every", "seed"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
        if self.world_size_max is not None:
            top = self.world_size_max
            if isinstance(top, bool) or not isinstance(top, (int, float)) or not (
                    math.isfinite(top) and top >= max(self.world_size)):
                raise ValueError(f"world_size_max must be a side in metres >= max(world_size) "
                                 f"= {max(self.world_size)}, got {top!r}")
            if self.backend != "sb3":
                raise ValueError("world_size_max applies to backend='sb3' only")
        shaping = self.frontier_shaping = check_real(self.frontier_shaping, "frontier_shaping",
                                                     low=0.0, low_inclusive=True)
        self.cost_prior = check_real(self.cost_prior, "cost_prior", low=0.0, low_inclusive=True)
        if self.central_critic and not (goals and self.sector_head and self.backend == "sb3"):
            raise ValueError("central_critic applies to level='goals' with the sector head on "
                             "backend='sb3' only")
        if self.lr_schedule != "constant" and self.backend != "sb3":
            raise ValueError(f"lr_schedule={self.lr_schedule!r} applies to backend='sb3' only")
        if self.motion_commands == "arcs" and goals:
            raise ValueError("motion_commands='arcs' applies to level='motion' only")
        if shaping and goals:
            raise ValueError("frontier_shaping applies to level='motion' only (the goal "
                             "level's planner already drives to frontiers)")
        for name in ("learning_rate", "gamma", "gae_lambda", "clip_range"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0 < value <= 1):
                raise ValueError(f"{name} must be in (0, 1], got {value!r}")
        if self.run_name is not None and (not self.run_name or "/" in self.run_name
                                          or self.run_name in (".", "..")):
            raise ValueError(f"run_name must be a plain folder name, got {self.run_name!r}")
        if self.resume is not None and not Path(self.resume).exists():
            raise ValueError(f"resume: no run folder or checkpoint at {str(self.resume)!r}")
        from agents.registry import EXPLORERS

        for name in self.eval_baselines:
            if name not in EXPLORERS:
                raise ValueError(f"eval_baselines: unknown explorer {name!r}; allowed: "
                                 f"{sorted(EXPLORERS)}")

    @property
    def envs_per_runner(self) -> int:
        """``--backend rllib``: envs each env runner steps (``n_envs`` split evenly)."""
        return math.ceil(self.n_envs / max(1, self.num_env_runners or 0))

    @property
    def size_range_top(self) -> float | None:
        """The largest training building's side: ``world_size_max``, or its default
        (:data:`DEFAULT_WORLD_SIZE_MAX` on SB3 when ``world_size`` is smaller); ``None``: every
        env on ``world_size``."""
        if self.world_size_max is not None:
            return float(self.world_size_max)
        if self.backend == "sb3" and max(self.world_size) < DEFAULT_WORLD_SIZE_MAX:
            return DEFAULT_WORLD_SIZE_MAX
        return None

    def train_env_configs(self) -> list[dict[str, Any]]:
        """One env config per training env: :meth:`env_config`, with the sizes spread from
        ``world_size`` to :attr:`size_range_top` (``max_cycles`` scaled by the side)."""
        base = self.env_config()
        top = self.size_range_top
        if top is None:
            return [base] * self.n_envs
        out = []
        for k in range(self.n_envs):
            f = k / max(1, self.n_envs - 1)
            size = tuple(float(s + f * (top - s)) for s in self.world_size)
            scale = max(size) / max(self.world_size)
            out.append({**base, "world": {**base["world"], "size": size},
                        "max_cycles": int(round(self.max_cycles * scale))})
        return out

    def env_config(self) -> dict[str, Any]:
        """The env's ``EnvConfig`` fields for training (``env_kwargs`` merged in)."""
        cfg: dict[str, Any] = {"max_cycles": self.max_cycles, "reward_mode": self.reward_mode,
                               "world": {"size": tuple(self.world_size)}}
        if self.n_robots != 2:  # a two-robot run's config (and evaluation cache) as before
            cfg["n_robots"] = self.n_robots
        if self.comm_range is not None:
            cfg["comm"] = {"range": float(self.comm_range)}
        if self.known_poses:
            cfg["mapping"] = {"merge_method": "known"}
        for key, value in self.env_kwargs.items():
            if isinstance(value, dict) and isinstance(cfg.get(key), dict):
                cfg[key] = {**cfg[key], **value}
            else:
                cfg[key] = value
        return cfg


class _EnvFactory:
    """Builds one training env (:func:`agents.goals.make_env`); picklable for workers."""

    def __init__(self, config: dict[str, Any], args: Args) -> None:
        self.config, self.args = config, args

    def __call__(self) -> Any:
        a = self.args
        return make_env(self.config, a.level, a.hold, a.frontier_shaping, a.central_critic,
                        a.motion_commands)


# ------------------------------------------------------------------------------- callbacks
class InfoLogger(BaseCallback):
    """Logs env infos at episode ends (true/shared coverage, a team's contacts and fused
    robots, merge acceptance and errors, ``explore/episode_env_steps`` — SB3's
    ``rollout/ep_len_mean`` counts decisions) and agent-steps/s; drives the progress bar."""

    def __init__(self, total: int, progress: bool, steps_per_decision: int) -> None:
        super().__init__()
        self.total, self.progress, self.scale = total, progress, steps_per_decision
        self.bar: Any = None
        self.t0 = 0.0
        self.agent_steps = 0

    def _on_training_start(self) -> None:
        self.t0, self.agent_steps = time.perf_counter(), 0
        self.episode_steps = np.zeros(self.training_env.num_envs, dtype=np.int64)
        self.bar = tqdm(total=self.total, initial=self.num_timesteps * self.scale,
                        unit="step", disable=not self.progress, desc="train", smoothing=0.05)

    def _on_step(self) -> bool:
        steps = np.array([int(info.get("env_steps", 1)) for info in self.locals["infos"]])
        self.episode_steps += steps
        new = int(steps.sum())
        self.agent_steps += new
        self.bar.update(new)
        for k, (info, done) in enumerate(zip(self.locals["infos"], self.locals["dones"],
                                             strict=True)):
            if not done:
                continue
            self.logger.record_mean("explore/episode_env_steps", float(self.episode_steps[k]))
            self.episode_steps[k] = 0
            for key in EPISODE_INFO_KEYS:
                if key in info:
                    self.logger.record_mean(f"explore/{key}", float(info[key]))
            if "merge_accepted" in info:
                self.logger.record_mean("merge/accepted", float(info["merge_accepted"]))
                for key in ("merge_rotation_error_deg", "merge_translation_error_m"):
                    if info.get("merge_errors_valid", False):
                        self.logger.record_mean(f"merge/{key}", float(info[key]))
        elapsed = time.perf_counter() - self.t0
        if elapsed > 0:
            self.logger.record("time/agent_steps_per_s", self.agent_steps / elapsed)
        return True

    def _on_training_end(self) -> None:
        self.bar.close()


def save_model_atomic(model: PPO, path: Path) -> None:
    """``model.save`` into a temporary file in the same folder, then rename."""
    atomic_write(path, model.save)


class _Periodic(BaseCallback):
    """Calls :meth:`fire` with the agent-step count every ``every`` agent-steps (``0``: never;
    SB3 counts decisions, ``scale`` env steps each)."""

    def __init__(self, every: int, scale: int) -> None:
        super().__init__()
        self.every, self.scale = every, scale
        self.next = 0

    def _on_training_start(self) -> None:
        steps = self.num_timesteps * self.scale
        self.next = (steps // self.every + 1) * self.every if self.every else 0

    def _on_step(self) -> bool:
        steps = self.num_timesteps * self.scale
        if self.every and steps >= self.next:
            self.fire(steps)
            self.next += self.every
        return True

    def fire(self, steps: int) -> None:
        raise NotImplementedError


class Checkpointer(_Periodic):
    """Saves ``checkpoints/step_<N>.zip`` atomically every ``every`` agent-steps."""

    def __init__(self, folder: Path, every: int, scale: int = 1) -> None:
        super().__init__(every, scale)
        self.folder = folder

    def fire(self, steps: int) -> None:
        save_model_atomic(self.model, self.folder / f"step_{steps:09d}.zip")


class Evaluator(_Periodic):
    """Every ``every`` agent-steps, runs the current policy on the fixed evaluation worlds,
    writes the comparison with the scripted baselines (see :func:`evaluate`) and keeps the
    best policy so far (:func:`keep_best`)."""

    def __init__(self, args: Args, run_dir: Path, every: int) -> None:
        super().__init__(every, args.hold)
        self.args, self.run_dir = args, run_dir

    def fire(self, steps: int) -> None:
        report = evaluate(self.model, self.args, self.run_dir, steps)
        row = _policy_row(report)
        for key in ("T50", "T85", "final_coverage"):
            self.logger.record(f"eval/{key}", row[key])
        keep_best(report, self.run_dir,
                  lambda: save_model_atomic(self.model, self.run_dir / BEST_SB3))


# ------------------------------------------------------------------------------- evaluation
BEST_SB3, BEST_RLLIB, BEST_FILE = "best_model.zip", "rllib_best", "best.json"
"""The best evaluated policy (SB3 / RLlib) and its record, in the run folder."""


def _policy_row(report: dict[str, Any]) -> dict[str, Any]:
    return next(r for r in report["rows"] if r["explorer"] == "ppo")


def keep_best(report: dict[str, Any], run_dir: Path, save: Callable[[], object]) -> bool:
    """If ``report``'s policy row (:func:`evaluate`) ranks above the one in ``best.json``
    (:func:`agents.evaluation.rank_key`: lower mean T85, then higher final coverage), call
    ``save()`` (which writes the best policy) and then record the row in ``best.json``;
    returns whether it did. A resumed run keeps comparing with its earlier best."""
    row, path = _policy_row(report), run_dir / BEST_FILE
    if path.exists():
        best = json.loads(path.read_text())
        if evaluation.rank_key(best) <= evaluation.rank_key(row):
            return False
    save()
    atomic_write_json(path, {"step": int(report["step"]),
                             **{k: row[k] for k in ("T50", "T85", "T95", "final_coverage",
                                                    "reached_T85")}})
    return True


def evaluate(policy: Any, args: Args, run_dir: Path, step: int) -> dict[str, Any]:
    """Evaluate ``policy`` (an SB3 model or an :class:`agents.rllib.RLlibPolicy`) against
    ``args.eval_baselines`` on the run's fixed worlds (:func:`agents.evaluation.evaluate`):
    writes ``eval.json``, ``eval.md`` and ``eval_coverage.png`` into ``run_dir``."""
    team = sb3_team(policy, deterministic=args.eval_deterministic, n_robots=args.n_robots)
    return evaluation.evaluate(team, run_dir, step, env_config=args.env_config(),
                               seed=args.seed, episodes=args.eval_episodes,
                               max_cycles=args.eval_max_cycles, baselines=args.eval_baselines)


# ------------------------------------------------------------------------------- SB3
def train_sb3(args: Args, run_dir: Path, checkpoint: Path | None) -> tuple[PPO, int]:
    """Train (or resume from ``checkpoint``) with Stable-Baselines3; save ``model.zip``.
    Returns the model and the agent-steps trained."""
    scale = args.hold
    venv = ParallelVecEnv([_EnvFactory(config, args)
                           for config in args.train_env_configs()], n_workers=args.n_workers)
    venv = VecMonitor(venv)
    venv.seed(args.seed)
    try:
        if checkpoint is not None:
            model = PPO.load(checkpoint, env=venv, device=args.device,
                             tensorboard_log=str(run_dir / "tb"))
        else:
            sectors = args.level == "goals" and args.sector_head
            model = PPO(
                SectorPolicy if sectors else "MultiInputPolicy", venv,
                learning_rate=(LinearSchedule(args.learning_rate, 0.0, 1.0)
                               if args.lr_schedule == "linear" else args.learning_rate),
                n_steps=args.n_steps, batch_size=args.batch_size, n_epochs=args.n_epochs,
                gamma=args.gamma ** scale, gae_lambda=args.gae_lambda, ent_coef=args.ent_coef,
                clip_range=args.clip_range, seed=args.seed, device=args.device, verbose=0,
                tensorboard_log=str(run_dir / "tb"),
                policy_kwargs={"features_extractor_class": TopoExplorerExtractor,
                               "net_arch": {"pi": [64], "vf": [64]},
                               **({"log_std_init": args.log_std_init}
                                  if args.level == "motion" and args.motion_commands
                                  == "continuous" else {}),
                               **({"mask_empty": args.mask_sectors,
                                   "cost_prior": args.cost_prior} if sectors else {})},
            )
            # saved with the model, read by SB3Explorer
            if args.level == "goals":
                model.goal_hold = args.hold
            else:
                model.motion_hold, model.motion_commands = args.hold, args.motion_commands
        callbacks = CallbackList([
            InfoLogger(args.total_timesteps, args.progress, scale),
            Checkpointer(run_dir / "checkpoints", args.checkpoint_every, scale),
            Evaluator(args, run_dir, args.eval_every),
        ])
        # SB3 counts decisions; a resumed run finishes the budget
        remaining = math.ceil(args.total_timesteps / scale) - model.num_timesteps
        if remaining > 0:
            model.learn(total_timesteps=remaining, callback=callbacks,
                        reset_num_timesteps=checkpoint is None, tb_log_name="ppo")
        save_model_atomic(model, run_dir / "model.zip")
    finally:
        venv.close()
    return model, model.num_timesteps * scale


# ------------------------------------------------------------------------------- RLlib
def _start_ray(args: Args) -> bool:
    """Join ``args.address`` or start a new local Ray cluster (even when ``ray start`` runs one
    here) with a CPU per env runner, at least the machine's; returns whether this call started
    Ray (and so must stop it)."""
    import ray

    if ray.is_initialized():
        return False
    kwargs: dict[str, Any] = {"include_dashboard": False, "logging_level": "ERROR"}
    if args.address is None:
        kwargs.update(address="local", num_cpus=max(os.cpu_count() or 1, args.num_env_runners))
    else:
        kwargs["address"] = args.address
    ray.init(**kwargs)
    return True


def rllib_config(args: Args) -> Any:
    """RLlib's ``PPOConfig`` for ``args`` (:func:`agents.rllib.ppo_config`), with the SB3
    path's hyperparameters: ``n_steps`` decisions per env per update, ``batch_size``
    transitions per gradient step."""
    from agents import rllib  # needs the rllib extra

    return rllib.ppo_config(
        env_config=args.env_config(), level=args.level, hold=args.hold,
        frontier_shaping=args.frontier_shaping, commands=args.motion_commands,
        sector_head=args.sector_head,
        mask_sectors=args.mask_sectors,
        cost_prior=args.cost_prior, seed=args.seed,
        num_env_runners=args.num_env_runners,
        envs_per_runner=args.envs_per_runner, train_batch_size=args.n_steps * args.n_envs,
        minibatch_size=args.batch_size, num_epochs=args.n_epochs, lr=args.learning_rate,
        gamma=args.gamma ** args.hold, gae_lambda=args.gae_lambda,
        entropy_coeff=args.ent_coef, clip_param=args.clip_range,
        num_gpus=0 if args.device == "cpu" else int(torch.cuda.is_available()))


def train_rllib(args: Args, run_dir: Path, checkpoint: Path | None) -> tuple[Any, int]:
    """Train (or resume from ``checkpoint``) with RLlib's PPO on the new API stack; save the
    algorithm checkpoint ``rllib/``. Returns the policy (:class:`agents.rllib.RLlibPolicy`)
    and the agent-steps trained."""
    import ray
    from torch.utils.tensorboard import SummaryWriter

    from agents import rllib  # needs the rllib extra

    scale = args.hold
    started = _start_ray(args)
    algo = None
    writer = SummaryWriter(str(_tb_folder(run_dir / "tb", "rllib_ppo", checkpoint is not None)))
    try:
        algo = rllib_config(args).build_algo()
        steps = 0
        if checkpoint is not None:
            algo.restore_from_path(str(checkpoint))
            steps = rllib.agent_steps(algo) * scale
        start = steps
        next_eval, next_checkpoint = (_after(steps, args.eval_every),
                                      _after(steps, args.checkpoint_every))
        bar = tqdm(total=args.total_timesteps, initial=steps, unit="step", desc="train",
                   disable=not args.progress, smoothing=0.05)
        times = rllib.IterationTimes()
        t0 = time.perf_counter()
        while steps < args.total_timesteps:
            result = algo.train()
            steps = rllib.agent_steps(algo) * scale
            bar.update(steps - bar.n)
            logged = {**rllib.scalars(result),
                      **times.update(result, restored=checkpoint is not None)}
            for key, value in logged.items():
                writer.add_scalar(key, value, steps)
            writer.add_scalar("time/agent_steps_per_s",
                              (steps - start) / (time.perf_counter() - t0), steps)
            if steps >= next_checkpoint:
                rllib.save_checkpoint(algo, run_dir / "checkpoints" / f"step_{steps:09d}",
                                      args.level, args.hold)
                next_checkpoint = _after(steps, args.checkpoint_every)
            if steps >= next_eval and steps < args.total_timesteps:
                policy = rllib.RLlibPolicy(algo.get_module(rllib.POLICY_ID), args.hold)
                report = evaluate(policy, args, run_dir, steps)
                _log_eval(writer, report, steps)
                keep_best(report, run_dir, lambda: rllib.save_checkpoint(
                    algo, run_dir / BEST_RLLIB, args.level, args.hold))
                next_eval = _after(steps, args.eval_every)
        bar.close()
        rllib.save_checkpoint(algo, run_dir / "rllib", args.level, args.hold)
        policy = rllib.RLlibPolicy(algo.get_module(rllib.POLICY_ID), args.hold)
    finally:
        writer.close()
        if algo is not None:
            algo.stop()
        if started:
            ray.shutdown()
    return policy, steps


def _tb_folder(tb: Path, name: str, resumed: bool) -> Path:
    """``tb/<name>_<k>``: a new ``k`` per run, the latest one when resuming (as SB3 names
    its logs)."""
    taken = [int(p.name.rsplit("_", 1)[1]) for p in tb.glob(f"{name}_*")
             if p.name.rsplit("_", 1)[1].isdigit()]
    latest = max(taken, default=0)
    return tb / f"{name}_{latest if resumed and latest else latest + 1}"


def _after(steps: int, every: int) -> float:
    """The first multiple of ``every`` above ``steps`` (``inf`` when ``every`` is 0)."""
    return (steps // every + 1) * every if every else math.inf


def _log_eval(writer: Any, report: dict[str, Any], steps: int) -> None:
    row = _policy_row(report)
    for key in ("T50", "T85", "final_coverage"):
        writer.add_scalar(f"eval/{key}", row[key], steps)


# ------------------------------------------------------------------------------- main
def _resume_checkpoint(resume: Path, backend: str) -> tuple[Path, Path]:
    """The run folder and the checkpoint to resume from: ``resume`` itself when it is a
    checkpoint (an SB3 ``.zip``, an RLlib checkpoint folder), else the latest of the run
    folder's ``checkpoints/`` and final policy."""
    resume = Path(resume)
    if backend == "sb3":
        final, pattern, is_checkpoint = resume / "model.zip", "step_*.zip", resume.is_file()
    else:
        from agents.rllib import POLICY_FILE

        final, pattern = resume / "rllib", "step_*"
        is_checkpoint = (resume / POLICY_FILE).is_file()
    if is_checkpoint:
        parent = resume.parent
        return (parent.parent if parent.name == "checkpoints" else parent), resume
    candidates = sorted((resume / "checkpoints").glob(pattern)) + (
        [final] if final.exists() else [])
    if not candidates:
        raise ValueError(f"resume: {str(resume)!r} has no checkpoints/{pattern} or "
                         f"{final.name}")
    return resume, max(candidates, key=lambda p: p.stat().st_mtime)


def main(args: Args) -> Path:
    """Train (or resume) and return the run folder (see the module docstring)."""
    torch.set_num_threads(args.torch_threads)
    if args.resume is not None:
        run_dir, checkpoint = _resume_checkpoint(args.resume, args.backend)
    else:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        run_dir = Path(args.runs_dir) / (
            args.run_name or f"{run_env_id(args.n_robots)}__{args.seed}__{stamp}")
        checkpoint = None
        # an overwritten run folder's best policy is another run's
        (run_dir / BEST_FILE).unlink(missing_ok=True)
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_json(run_dir / "args.json", json.loads(json.dumps(asdict(args), default=str)))

    train = train_rllib if args.backend == "rllib" else train_sb3
    policy, steps = train(args, run_dir, checkpoint)
    report = evaluate(policy, args, run_dir, steps)
    if args.backend == "sb3":
        final, best = "model.zip", BEST_SB3
        keep_best(report, run_dir, lambda: save_model_atomic(policy, run_dir / best))
    else:
        final, best = "rllib", BEST_RLLIB
        keep_best(report, run_dir, lambda: atomic_write_dir(
            run_dir / best,
            lambda tmp: shutil.copytree(run_dir / final, tmp, dirs_exist_ok=True)))
    print((run_dir / "eval.md").read_text())
    record = json.loads((run_dir / BEST_FILE).read_text())
    print(f"run folder: {run_dir}  (policy: {run_dir / final}; best evaluated: "
          f"{run_dir / best}, step {record['step']})")
    return run_dir


if __name__ == "__main__":
    main(tyro.cli(Args))
