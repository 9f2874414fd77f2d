"""Train an exploration policy with PPO, map fusion inside the RL loop, on Stable-Baselines3
(default) or RLlib (``--backend rllib``, sampling scaled out over a Ray cluster).

All robots share one policy (parameter sharing): with SB3 each robot of each env is one
sub-environment of a :class:`agents.sb3.ParallelVecEnv`; with RLlib every robot maps to one
RLModule (:mod:`agents.rllib`). ``--n-robots N`` trains a team of ``N`` robots (2 is
``two_robot_explore_v0``, more ``multi_robot_explore_v0``), ``--comm-range R`` limits their
contact to ``R`` metres. The policy picks a frontier sector every ``--hold`` steps for a
planner to drive to (``--level goals``, :mod:`agents.goals`) or the velocity command every step
(``--level motion``, :mod:`agents.motion`). The reward is the env's team reward, the growth of
the *shared* map (fused with the accepted ``fusion`` merges), so a wrong merge costs reward.

    python train.py --total-timesteps 200000 --n-envs 4 --seed 1
    python train.py --level motion --motion-commands arcs --hold 4 --frontier-shaping 1.0
    python train.py --central-critic --world-size-max 20    # goal level, MAPPO-style critic
    python train.py --backend rllib --address auto --num-env-runners 8   # joins `ray start`'s
    python train.py --level motion --n-robots 4 --comm-range 5     # a team of four robots
    tensorboard --logdir runs

Settings are checked before anything starts: a bad one, or an env the settings cannot build
(one is built and reset here first), is one line ``train.py: error: ...`` and exit status 2,
with no run folder left behind. A run writes ``runs/<env>__<seed>__<time>/`` (an existing
folder is refused unless ``--overwrite``): ``args.json``, ``tb/`` (TensorBoard), ``checkpoints/``
(atomic, resumable with ``--resume RUN_DIR``), ``eval.json`` / ``eval.md`` /
``eval_coverage.png`` (periodic evaluations against scripted baselines on fixed seeds,
:mod:`agents.evaluation`), the final policy ``model.zip`` (SB3, usable as ``--explorer
sb3:RUN_DIR/model.zip``) or ``rllib/`` (:meth:`agents.rllib.RLlibPolicy.load`), and the best
policy the evaluations saw (``best_model.zip`` or ``rllib_best/``, its step in ``best.json``).

Readable like CleanRL's ``ppo.py``: ``Args`` and ``main(args)`` (importable for tests); the
backends' loops are :mod:`agents.training` and :mod:`agents.rllib_training`.
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Literal, get_args, get_origin, get_type_hints

import torch
import tyro

from agents.goals import default_hold
from agents.training import check_device, start_run, train_and_evaluate
from topo.validation import check_real, config_from

ENV_ID = "two_robot_explore_v0"
"""The env of a two-robot run (:func:`run_env_id` names any team's)."""

DEFAULT_WORLD_SIZE_MAX = 20.0
"""The largest training building by default (``Args.world_size_max``): the held-out worlds of
``benchmarks/training_eval.py`` are 10–20 m, and ``docs/notes/training.md`` trains on that
range."""


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
    setting most multi-robot exploration work assumes (``docs/notes/training.md``)."""
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
    (``docs/notes/training.md`` compares both)."""
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
    per CPU core, at most ``n_envs`` (``benchmarks/train_speed.py`` measures the gain)."""
    num_env_runners: int | None = None
    """``--backend rllib``: Ray actors sampling in parallel (0: sample in this process), the
    ``n_envs`` envs split between them; default one per CPU core, at most ``n_envs``."""
    address: str | None = None
    """``--backend rllib``: the Ray cluster to join (``auto``, or ``HEAD_IP:6379`` as printed by
    ``ray start --head``); default: start a local one for this run."""
    reward_mode: Literal["shared", "oracle", "individual"] = "shared"
    """Env reward: growth of the fused shared map, of the true union, or per robot."""
    device: str = "cpu"
    """Torch device for the policy: "cpu", "cuda", "cuda:N", "mps" or "auto" (with RLlib
    anything but "cpu" gives the learner a GPU when torch sees one)."""
    world_size: tuple[float, float] = (10.0, 10.0)
    """Procedural building size in metres."""
    world_size_max: float | None = None
    """``--backend sb3``: train on buildings of several sizes, the ``n_envs`` envs spread
    evenly from ``world_size`` to this side (metres), each env's episodes lengthened in
    proportion (``max_cycles`` is the first's); evaluation stays on ``world_size``. Default:
    :data:`DEFAULT_WORLD_SIZE_MAX` (20 m: the measured recipe, ``docs/notes/training.md``), or
    every env on ``world_size`` when that is as large or the backend is RLlib. Set it to
    ``max(world_size)`` for one size."""
    max_cycles: int = 500
    """Env steps per episode (truncation); long enough in 10 m buildings for ``Frontier`` to
    reach 85 % coverage, so T85 separates explorers (``docs/notes/training.md``)."""
    learning_rate: float = 3e-4
    """Adam learning rate."""
    lr_schedule: Literal["constant", "linear"] = "constant"
    """``constant``, or ``linear``: from ``learning_rate`` down to 0 at ``total_timesteps``
    (SB3's ``LinearSchedule``; ``--backend sb3`` only). A constant rate let a motion policy
    fall back after its best point (``docs/notes/training.md``)."""
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
    episodes so that T85 is measured rather than cut off (slow explorers such as
    ``RandomWalk`` need longer), since a T that the episode end censors is only a bound."""
    checkpoint_every: int = 50_000
    """Agent-steps between checkpoints (0: only at the end)."""
    runs_dir: Path = Path("runs")
    """Where run folders go."""
    run_name: str | None = None
    """Run folder name (default: <env>__<seed>__<time>); an existing one is refused unless
    ``overwrite``."""
    overwrite: bool = False
    """Replace the run in an existing run folder of that name (its best policy record and
    checkpoints are another run's and are removed); ``--resume`` continues one instead."""
    resume: Path | None = None
    """Continue a run: its folder (latest checkpoint) or a checkpoint (an SB3 ``.zip``, an
    RLlib checkpoint folder), with the backend it was trained with."""
    progress: bool = True
    """Show a progress bar."""
    torch_threads: int = 1
    """torch.set_num_threads (1 leaves the other cores to the envs)."""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    """Extra env config (EnvConfig fields) for training and evaluation."""

    def __post_init__(self) -> None:
        hints = get_type_hints(Args)
        for f in fields(self):  # tyro checks the command line, this code's calls
            value, hint = getattr(self, f.name), hints[f.name]
            if get_origin(hint) is Literal and value not in get_args(hint):
                raise ValueError(f"{f.name} must be one of {list(get_args(hint))}, got "
                                 f"{value!r}")
            if any(isinstance(v, float) and not math.isfinite(v)
                   for v in (value if isinstance(value, tuple) else (value,))):
                raise ValueError(f"{f.name} must be finite, got {value!r}")
        goals = self.level == "goals"
        from envs.explore.config import CommConfig, EnvConfig

        EnvConfig(n_robots=self.n_robots)  # n_robots: an integer, 2 to 8 (names the value)
        if self.comm_range is not None:
            CommConfig(range=self.comm_range)  # comm.range: a real > 0 (names the value)
        for name in ("known_poses", "overwrite"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"{name} must be True or False, got {getattr(self, name)!r}")
        check_device(self.device)
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
        for name in ("ent_coef", "log_std_init"):
            check_real(getattr(self, name), name)
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
        for config in self.train_env_configs():  # every field the env checks, named
            try:
                config_from(EnvConfig, config, "env_kwargs")
            except (ValueError, TypeError) as exc:
                raise type(exc)(f"env settings: {exc}") from exc

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


@dataclass
class _CommandLine(Args):
    """The flags as tyro parses them, unchecked: :func:`cli` builds the :class:`Args`, so that a
    bad setting is one line of its own rather than tyro's box."""

    def __post_init__(self) -> None:
        pass


def main(args: Args) -> Path:
    """Train (or resume) and return the run folder (see the module docstring)."""
    torch.set_num_threads(args.torch_threads)
    run_dir, checkpoint = start_run(args, run_env_id(args.n_robots))
    train_and_evaluate(args, run_dir, checkpoint)
    return run_dir


def cli(argv: list[str] | None = None) -> Path:
    """``main`` from the command line (``argv``, default ``sys.argv``): a setting that cannot
    run is one line ``train.py: error: ...`` on stderr and exit status 2, no traceback."""
    parsed = tyro.cli(_CommandLine, args=argv, description=" ".join((Args.__doc__ or "").split()))
    try:
        args = Args(**{f.name: getattr(parsed, f.name) for f in fields(Args)})
        torch.set_num_threads(args.torch_threads)
        start = start_run(args, run_env_id(args.n_robots))
    except (ValueError, TypeError) as exc:
        print(f"train.py: error: {' '.join(str(exc).split())}", file=sys.stderr)
        raise SystemExit(2) from None
    train_and_evaluate(args, *start)
    return start[0]


if __name__ == "__main__":
    cli()
