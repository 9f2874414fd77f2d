"""Train an exploration policy with PPO (Stable-Baselines3), map fusion inside the RL loop.

Both robots share one policy (parameter sharing): each robot of each env is one sub-environment
of a :class:`agents.sb3.ParallelVecEnv`. The policy acts at one of two levels (``--level``):
``goals`` (default) picks which frontier sector to explore next every ``--hold`` steps and a
frontier planner drives there (:mod:`agents.goals`); ``motion`` outputs the env's velocity
commands every step. The reward is the env's team reward — the growth of the
*shared* map, i.e. of robot 0's map united with robot 1's map moved by the latest accepted
``fusion.merge_maps`` transform — so a wrong merge costs reward (``--reward-mode oracle`` uses the
true union instead, for ablations).

    python train.py --total-timesteps 200000 --n-envs 4 --seed 1
    python train.py --help
    tensorboard --logdir runs

A run writes ``runs/<env>__<seed>__<time>/``: ``tb/`` (TensorBoard: reward, true and shared
coverage, merge acceptance and errors, episode length, steps/s), ``checkpoints/`` (atomic,
resumable with ``--resume RUN_DIR``), ``eval.json`` / ``eval.md`` / ``eval_coverage.png``
(periodic evaluation of the policy against ``Frontier`` and ``RandomWalk`` on fixed seeds) and
``model.zip`` (the final policy, usable as ``--explorer sb3:RUN_DIR/model.zip``).

Readable like CleanRL's ``ppo.py``: ``Args`` below, ``main(args)``, importable for tests.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
import tyro
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.vec_env import VecMonitor
from tqdm.auto import tqdm

from agents.base import run_episode
from agents.metrics import EpisodeRecorder
from agents.policy import SectorPolicy, TopoExplorerExtractor
from agents.sb3 import ParallelVecEnv
from agents.sb3_explorer import SB3Explorer
from agents.scripted import make_team
from fusion.pairs import atomic_write_json
from topo._io import atomic_write, atomic_write_bytes

ENV_ID = "two_robot_explore_v0"


@dataclass
class Args:
    """PPO on two_robot_explore_v0 with parameter sharing (both robots, one policy)."""

    total_timesteps: int = 200_000
    """Agent-steps to train for (each env step gives two: one per robot; at the goals level
    a decision counts its ``hold`` env steps)."""
    level: Literal["goals", "motion"] = "goals"
    """What the policy decides: a frontier sector every ``hold`` steps (a planner drives), or
    the velocity command every step."""
    hold: int = 10
    """Env steps each goal decision is held (``level="goals"``)."""
    sector_head: bool = True
    """At the goals level, score every sector with one shared network
    (:class:`agents.policy.SectorPolicy`); ``False``: SB3's ``MultiInputPolicy`` (one linear
    layer from the context to the 8 logits)."""
    seed: int = 1
    """Seed of everything: envs, policy initialisation, evaluation worlds."""
    n_envs: int = 4
    """Envs run in parallel (2 robots each, so 2 × n_envs policy sub-environments)."""
    n_workers: int | None = None
    """Worker processes stepping the envs (1: in this process); default one per CPU core, at
    most ``n_envs`` (on 2 cores: 946 against 657 agent-steps/s at the goals level,
    ``benchmarks/train_speed.py``)."""
    reward_mode: Literal["shared", "oracle", "individual"] = "shared"
    """Env reward: growth of the fused shared map, of the true union, or per robot."""
    device: str = "cpu"
    """Torch device for the policy ("cpu", "cuda", "auto")."""
    world_size: tuple[float, float] = (10.0, 10.0)
    """Procedural building size in metres."""
    max_cycles: int = 500
    """Env steps per episode (truncation); with 10 m buildings Frontier reaches 85 % in
    about 300–500 steps, so T85 separates explorers."""
    learning_rate: float = 3e-4
    """Adam learning rate."""
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
    clip_range: float = 0.2
    """PPO clip range."""
    eval_every: int = 50_000
    """Agent-steps between evaluations (0: only at the end)."""
    eval_episodes: int = 4
    """Fixed-seed evaluation worlds per evaluation."""
    eval_baselines: tuple[str, ...] = ("frontier", "random_walk")
    """Scripted explorers evaluated on the same worlds (once per run)."""
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
    """Continue a run: its folder (latest checkpoint) or a checkpoint .zip."""
    progress: bool = True
    """Show a progress bar."""
    torch_threads: int = 1
    """torch.set_num_threads (1 is fastest on 2 cores with envs busy)."""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    """Extra env config (EnvConfig fields) for training and evaluation."""

    def __post_init__(self) -> None:
        goals = self.level == "goals"
        if self.n_steps is None:
            self.n_steps = 32 if goals else 128
        if self.batch_size is None:
            self.batch_size = 64 if goals else 256
        if self.eval_max_cycles is None and isinstance(self.max_cycles, int):
            self.eval_max_cycles = 3 * self.max_cycles
        if self.n_workers is None:
            envs = self.n_envs if isinstance(self.n_envs, int) else 1
            self.n_workers = max(1, min(os.cpu_count() or 1, envs))
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
        if self.level not in ("goals", "motion"):
            raise ValueError(f"level must be one of ['goals', 'motion'], got {self.level!r}")
        if self.reward_mode not in ("shared", "oracle", "individual"):
            raise ValueError("reward_mode must be one of ['shared', 'oracle', 'individual'], "
                             f"got {self.reward_mode!r}")
        for name in ("learning_rate", "gamma", "gae_lambda", "clip_range"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0 < value <= 1):
                raise ValueError(f"{name} must be in (0, 1], got {value!r}")
        if self.run_name is not None and (not self.run_name or "/" in self.run_name
                                          or self.run_name in (".", "..")):
            raise ValueError(f"run_name must be a plain folder name, got {self.run_name!r}")
        if self.resume is not None and not Path(self.resume).exists():
            raise ValueError(f"resume: no run folder or checkpoint at {str(self.resume)!r}")
        from agents.scripted import EXPLORERS

        for name in self.eval_baselines:
            if name not in EXPLORERS:
                raise ValueError(f"eval_baselines: unknown explorer {name!r}; allowed: "
                                 f"{sorted(EXPLORERS)}")

    @property
    def steps_per_decision(self) -> int:
        """Env steps per policy decision: ``hold`` at the goals level, else 1."""
        return self.hold if self.level == "goals" else 1

    def env_config(self) -> dict[str, Any]:
        cfg = {"max_cycles": self.max_cycles, "reward_mode": self.reward_mode,
               "world": {"size": tuple(self.world_size)}}
        for key, value in self.env_kwargs.items():
            if isinstance(value, dict) and isinstance(cfg.get(key), dict):
                cfg[key] = {**cfg[key], **value}
            else:
                cfg[key] = value
        return cfg


def make_env(config: dict[str, Any], level: str = "motion", hold: int = 10) -> Any:
    """One ``two_robot_explore_v0`` ParallelEnv, wrapped in
    :class:`agents.goals.FrontierGoalEnv` at the goals level (a top-level function: picklable
    for workers)."""
    from envs.two_robot_explore_v0 import parallel_env

    env = parallel_env(**config)
    if level == "goals":
        from agents.goals import FrontierGoalEnv

        env = FrontierGoalEnv(env, hold=hold)
    return env


class _EnvFactory:
    def __init__(self, config: dict[str, Any], level: str, hold: int) -> None:
        self.config, self.level, self.hold = config, level, hold

    def __call__(self) -> Any:
        return make_env(self.config, self.level, self.hold)


# ------------------------------------------------------------------------------- callbacks
class InfoLogger(BaseCallback):
    """Logs env infos at episode ends (true/shared coverage, merge acceptance and errors,
    ``explore/episode_env_steps`` — SB3's ``rollout/ep_len_mean`` counts decisions) and
    agent-steps/s; drives the progress bar."""

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
            for key in ("true_coverage", "shared_coverage", "overlap", "merges"):
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
    """Every ``every`` agent-steps, runs the current policy on the fixed evaluation worlds and
    writes the comparison with the scripted baselines (see :func:`evaluate`)."""

    def __init__(self, args: Args, run_dir: Path, every: int) -> None:
        super().__init__(every, args.steps_per_decision)
        self.args, self.run_dir = args, run_dir

    def fire(self, steps: int) -> None:
        report = evaluate(self.model, self.args, self.run_dir, steps)
        for row in report["rows"]:
            if row["explorer"] == "ppo":
                for key in ("T50", "T85", "final_coverage"):
                    self.logger.record(f"eval/{key}", row[key])


# ------------------------------------------------------------------------------- evaluation
def eval_seeds(args: Args) -> list[int]:
    """The fixed evaluation worlds: seeds derived from the run seed, disjoint from training's
    (training envs are seeded ``seed + k``; these come from a separate SeedSequence)."""
    ss = np.random.SeedSequence([args.seed, 0xE7A1])
    return [int(s) for s in ss.generate_state(args.eval_episodes)]


def eval_worlds(args: Args) -> tuple[dict[str, Any], list[int], dict[str, Any]]:
    """The evaluation's env config (``eval_max_cycles`` steps), its seeds (:func:`eval_seeds`)
    and the JSON key that identifies both (for caching results on them)."""
    config = {**args.env_config(), "max_cycles": args.eval_max_cycles}
    seeds = eval_seeds(args)
    return config, seeds, {"seeds": seeds, "config": json.loads(json.dumps(config, default=str))}


def run_explorer(team: dict, config: dict[str, Any], seeds: list[int]) -> list[dict]:
    """Metrics of ``team`` on each evaluation seed (:class:`agents.metrics.EpisodeRecorder`)."""
    out = []
    for seed in seeds:
        env = make_env(config)
        rec = EpisodeRecorder()
        try:
            run_episode(env, team, seed=seed, callback=rec)
        finally:
            env.close()
        out.append(rec.summary())
    return out


def _summarise(name: str, episodes: list[dict]) -> dict[str, Any]:
    row: dict[str, Any] = {"explorer": name, "episodes": len(episodes)}
    for key in ("T50", "T85", "T95", "final_coverage", "overlap", "collisions"):
        row[key] = float(np.mean([e[key] for e in episodes]))
    row["reached_T85"] = float(np.mean([e["reached_T85"] for e in episodes]))
    return row


def evaluate(model: PPO, args: Args, run_dir: Path, step: int) -> dict[str, Any]:
    """Evaluate the policy and the baselines on the fixed worlds; write ``eval.json``,
    ``eval.md`` and ``eval_coverage.png`` (atomically) into ``run_dir``."""
    config, seeds, key = eval_worlds(args)
    cache = run_dir / "eval_baselines.json"
    stored = json.loads(cache.read_text()) if cache.exists() else {}
    baselines: dict[str, list[dict]] = stored["explorers"] if stored.get("key") == key else {}
    for name in args.eval_baselines:
        if name not in baselines:
            eps = run_explorer(make_team(name), config, seeds)
            baselines[name] = [{**e, "coverage": e["coverage"].tolist()} for e in eps]
    atomic_write_json(cache, {"key": key, "explorers": baselines})

    policy = {a: SB3Explorer(model) for a in ("robot_0", "robot_1")}
    ppo = [{**e, "coverage": e["coverage"].tolist()} for e in run_explorer(policy, config, seeds)]
    curves = {"ppo": ppo, **baselines}
    rows = [_summarise(name, eps) for name, eps in curves.items()]
    report = {"step": step, "seeds": seeds, "rows": rows, "max_cycles": args.eval_max_cycles}
    atomic_write_json(run_dir / "eval.json", report)
    lines = [f"Evaluation at {step} agent-steps on {len(seeds)} fixed worlds "
             f"({args.eval_max_cycles}-step episodes; T = steps to that true coverage, "
             f"not reached = {args.eval_max_cycles + 1})", "",
             "| explorer | T50 | T85 | T95 | reached 85% | final coverage | overlap | "
             "collisions |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['explorer']} | {r['T50']:.0f} | {r['T85']:.0f} | {r['T95']:.0f} | "
                     f"{r['reached_T85']:.0%} | {r['final_coverage']:.2f} | {r['overlap']:.2f} "
                     f"| {r['collisions']:.1f} |")
    atomic_write_bytes(run_dir / "eval.md", ("\n".join(lines) + "\n").encode())
    _plot_coverage(curves, run_dir / "eval_coverage.png", step)
    return report


def _plot_coverage(curves: dict[str, list[dict]], path: Path, step: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from topo.plotting import save_figure

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name, eps in curves.items():
        n = max(len(e["coverage"]) for e in eps)
        padded = np.array([np.pad(e["coverage"], (0, n - len(e["coverage"])), mode="edge")
                           for e in eps])
        ax.plot(np.arange(1, n + 1), padded.mean(axis=0), label=name)
    for level in (0.5, 0.85, 0.95):
        ax.axhline(level, color="0.7", lw=0.8, ls="--")
    ax.set_xlabel("env step")
    ax.set_ylabel("true coverage (mean over evaluation worlds)")
    ax.set_title(f"Coverage vs steps after {step} agent-steps")
    ax.set_ylim(0, 1)
    ax.legend()
    ax.grid(alpha=0.3)
    save_figure(fig, path)
    plt.close(fig)


# ------------------------------------------------------------------------------- main
def _resume_checkpoint(resume: Path) -> tuple[Path, Path]:
    resume = Path(resume)
    if resume.is_file():
        return resume.parent.parent, resume
    checkpoints = sorted((resume / "checkpoints").glob("step_*.zip"))
    final = resume / "model.zip"
    candidates = checkpoints + ([final] if final.exists() else [])
    if not candidates:
        raise ValueError(f"resume: {str(resume)!r} has no checkpoints/step_*.zip or model.zip")
    return resume, max(candidates, key=lambda p: p.stat().st_mtime)


def main(args: Args) -> Path:
    """Train (or resume) and return the run folder (see the module docstring)."""
    torch.set_num_threads(args.torch_threads)
    if args.resume is not None:
        run_dir, checkpoint = _resume_checkpoint(args.resume)
    else:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        run_dir = Path(args.runs_dir) / (args.run_name or f"{ENV_ID}__{args.seed}__{stamp}")
        checkpoint = None
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_json(run_dir / "args.json", json.loads(json.dumps(asdict(args), default=str)))

    config = args.env_config()
    scale = args.steps_per_decision
    venv = ParallelVecEnv([_EnvFactory(config, args.level, args.hold)
                           for _ in range(args.n_envs)], n_workers=args.n_workers)
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
                learning_rate=args.learning_rate,
                n_steps=args.n_steps, batch_size=args.batch_size, n_epochs=args.n_epochs,
                gamma=args.gamma ** scale, gae_lambda=args.gae_lambda, ent_coef=args.ent_coef,
                clip_range=args.clip_range, seed=args.seed, device=args.device, verbose=0,
                tensorboard_log=str(run_dir / "tb"),
                policy_kwargs={"features_extractor_class": TopoExplorerExtractor,
                               "net_arch": {"pi": [64], "vf": [64]}},
            )
            if args.level == "goals":
                model.goal_hold = args.hold  # saved with the model, read by SB3Explorer
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
        evaluate(model, args, run_dir, model.num_timesteps * scale)
    finally:
        venv.close()
    print((run_dir / "eval.md").read_text())
    print(f"run folder: {run_dir}  (policy: {run_dir / 'model.zip'})")
    return run_dir


if __name__ == "__main__":
    main(tyro.cli(Args))
