"""What ``train.py`` runs, once its settings are checked: the checks that need the disk or an
env (:func:`check_device`, :func:`check_env`, :func:`start_run`, which makes the run folder),
the run itself (:func:`train_and_evaluate`), periodic and final evaluations with the best
policy kept (:func:`evaluate_policy`, :func:`keep_best`), resuming
(:func:`resume_checkpoint`), and Stable-Baselines3's PPO with its callbacks
(:func:`train_sb3`). RLlib's loop is :mod:`agents.rllib_training`.

``args`` below is a ``train.Args`` (any object with its fields): ``agents`` never imports
``train``. Kept out of ``train.py`` so that the script reads as its settings and ``main``.
"""

from __future__ import annotations

import json
import math
import re
import shutil
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import VecMonitor
from tqdm.auto import tqdm

from agents import evaluation
from agents.goals import make_env
from agents.metrics import EPISODE_INFO_KEYS
from agents.policy import SectorPolicy, TopoExplorerExtractor
from agents.sb3 import ParallelVecEnv
from agents.sb3_explorer import sb3_team
from topo.fileio import atomic_write, atomic_write_dir, atomic_write_json

BEST_SB3, BEST_RLLIB, BEST_FILE = "best_model.zip", "rllib_best", "best.json"
"""The best evaluated policy (SB3 / RLlib) and its record, in the run folder."""

DEVICES = "'cpu', 'cuda', 'cuda:N', 'mps' or 'auto'"
"""The torch devices a run accepts (:func:`check_device`)."""


# ------------------------------------------------------------------------------- checks
def check_device(device: object) -> None:
    """Raise ``ValueError`` naming ``device`` unless it is one of :data:`DEVICES` that this
    machine can use (``cuda`` without a GPU runs on the CPU, as SB3 does); checked before a
    run so that a bad one is not a torch traceback halfway into it."""
    if not isinstance(device, str) or not re.fullmatch(r"cpu|auto|mps|cuda(:\d+)?", device):
        raise ValueError(f"device must be {DEVICES}, got {device!r}")
    if device == "mps" and not torch.backends.mps.is_available():
        raise ValueError("device 'mps' is not available on this machine; allowed: 'cpu', "
                         "'auto'" + (", 'cuda'" if torch.cuda.is_available() else ""))
    if device.startswith("cuda:") and torch.cuda.is_available() and (
            int(device[5:]) >= torch.cuda.device_count()):
        raise ValueError(f"device {device!r}: this machine has {torch.cuda.device_count()} "
                         f"CUDA device(s), cuda:0 to cuda:{torch.cuda.device_count() - 1}")


def check_env(config: Mapping[str, Any], args: Any) -> None:
    """Build the training env of ``config`` in this process and reset it once with the run's
    seed: a setting the env refuses (a world too small for the team, a bad size) is one
    ``ValueError`` here, before any worker process or run folder exists, rather than a worker
    dying mid-run. Raises the env's ``ValueError``/``TypeError`` prefixed ``env settings:``."""
    try:
        env = make_env(config, args.level, args.hold, args.frontier_shaping, args.central_critic,
                       args.motion_commands)
        try:
            env.reset(seed=args.seed)
        finally:
            env.close()
    except (ValueError, TypeError) as exc:
        raise type(exc)(f"env settings: {exc}") from exc


def resume_checkpoint(resume: Path, backend: str) -> tuple[Path, Path]:
    """The run folder and the checkpoint to resume from: ``resume`` itself when it is a
    checkpoint (an SB3 ``.zip``, an RLlib checkpoint folder), else the latest of the run
    folder's ``checkpoints/`` and final policy. Raises ``ValueError`` if there is none."""
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


def start_run(args: Any, env_id: str) -> tuple[Path, Path | None]:
    """Check what needs the disk or an env, then make the run folder with ``args.json``: the
    folder (``args.runs_dir/<run_name>``, default ``<env_id>__<seed>__<time>``) must be new
    unless ``args.overwrite`` (which removes the old run's ``best.json`` and checkpoints) or
    ``args.resume`` (:func:`resume_checkpoint`); one training env, the smallest world, builds
    and resets here (:func:`check_env`). Returns the folder and the checkpoint to resume from
    (``None``: a new run). Raises ``ValueError``/``TypeError`` before writing anything."""
    if args.resume is not None:
        run_dir, checkpoint = resume_checkpoint(args.resume, args.backend)
    else:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        run_dir = Path(args.runs_dir) / (args.run_name or f"{env_id}__{args.seed}__{stamp}")
        checkpoint = None
        if run_dir.exists() and not args.overwrite:
            raise ValueError(f"run_name: the run folder {str(run_dir)!r} exists; pass "
                             f"--overwrite to replace its run, or --resume {run_dir} to "
                             f"continue it")
    check_env(args.train_env_configs()[0], args)
    if checkpoint is None:  # an overwritten run's best policy and checkpoints are another's
        (run_dir / BEST_FILE).unlink(missing_ok=True)
        shutil.rmtree(run_dir / "checkpoints", ignore_errors=True)
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_json(run_dir / "args.json", json.loads(json.dumps(asdict(args), default=str)))
    return run_dir, checkpoint


# ------------------------------------------------------------------------------- evaluation
def policy_row(report: Mapping[str, Any]) -> dict[str, Any]:
    """The trained policy's row of an evaluation report (:func:`evaluate_policy`)."""
    return next(r for r in report["rows"] if r["explorer"] == "ppo")


def keep_best(report: Mapping[str, Any], run_dir: Path, save: Callable[[], object]) -> bool:
    """If ``report``'s policy row (:func:`evaluate_policy`) ranks above the one in
    ``best.json`` (:func:`agents.evaluation.rank_key`: lower mean T85, then higher final
    coverage), call ``save()`` (which writes the best policy) and then record the row in
    ``best.json``; returns whether it did. A resumed run keeps comparing with its earlier
    best, as SB3's ``EvalCallback`` keeps one: a run can peak before its end."""
    row, path = policy_row(report), run_dir / BEST_FILE
    if path.exists():
        best = json.loads(path.read_text())
        if evaluation.rank_key(best) <= evaluation.rank_key(row):
            return False
    save()
    atomic_write_json(path, {"step": int(report["step"]),
                             **{k: row[k] for k in ("T50", "T85", "T95", "final_coverage",
                                                    "reached_T85")}})
    return True


def evaluate_policy(policy: Any, args: Any, run_dir: Path, step: int) -> dict[str, Any]:
    """Evaluate ``policy`` (an SB3 model or an :class:`agents.rllib.RLlibPolicy`) against
    ``args.eval_baselines`` on the run's fixed worlds (:func:`agents.evaluation.evaluate`):
    writes ``eval.json``, ``eval.md`` and ``eval_coverage.png`` into ``run_dir``."""
    team = sb3_team(policy, deterministic=args.eval_deterministic, n_robots=args.n_robots)
    return evaluation.evaluate(team, run_dir, step, env_config=args.env_config(),
                               seed=args.seed, episodes=args.eval_episodes,
                               max_cycles=args.eval_max_cycles, baselines=args.eval_baselines)


def log_eval(record: Callable[[str, float], object], report: Mapping[str, Any]) -> None:
    """Log the policy's T50, T85 and final coverage of ``report`` as ``eval/...`` scalars."""
    row = policy_row(report)
    for key in ("T50", "T85", "final_coverage"):
        record(f"eval/{key}", row[key])


# ------------------------------------------------------------------------------- SB3
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
        """Save the model as it is at ``steps`` agent-steps."""
        save_model_atomic(self.model, self.folder / f"step_{steps:09d}.zip")


class Evaluator(_Periodic):
    """Every ``every`` agent-steps, runs the current policy on the fixed evaluation worlds,
    writes the comparison with the scripted baselines (:func:`evaluate_policy`) and keeps the
    best policy so far (:func:`keep_best`)."""

    def __init__(self, args: Any, run_dir: Path, every: int) -> None:
        super().__init__(every, args.hold)
        self.args, self.run_dir = args, run_dir

    def fire(self, steps: int) -> None:
        """Evaluate the policy as it is at ``steps`` agent-steps and keep it if best."""
        report = evaluate_policy(self.model, self.args, self.run_dir, steps)
        log_eval(self.logger.record, report)
        keep_best(report, self.run_dir,
                  lambda: save_model_atomic(self.model, self.run_dir / BEST_SB3))


class EnvFactory:
    """Builds one training env (:func:`agents.goals.make_env`); picklable for workers."""

    def __init__(self, config: Mapping[str, Any], args: Any) -> None:
        self.config, self.args = config, args

    def __call__(self) -> Any:
        a = self.args
        return make_env(self.config, a.level, a.hold, a.frontier_shaping, a.central_critic,
                        a.motion_commands)


def _new_model(args: Any, venv: Any, run_dir: Path) -> PPO:
    """A fresh PPO model of ``args`` on ``venv``, with the level and hold that
    :class:`agents.sb3_explorer.SB3Explorer` reads saved on it."""
    sectors = args.level == "goals" and args.sector_head
    continuous = args.level == "motion" and args.motion_commands == "continuous"
    model = PPO(
        SectorPolicy if sectors else "MultiInputPolicy", venv,
        learning_rate=(LinearSchedule(args.learning_rate, 0.0, 1.0)
                       if args.lr_schedule == "linear" else args.learning_rate),
        n_steps=args.n_steps, batch_size=args.batch_size, n_epochs=args.n_epochs,
        gamma=args.gamma ** args.hold, gae_lambda=args.gae_lambda, ent_coef=args.ent_coef,
        clip_range=args.clip_range, seed=args.seed, device=args.device, verbose=0,
        tensorboard_log=str(run_dir / "tb"),
        policy_kwargs={"features_extractor_class": TopoExplorerExtractor,
                       "net_arch": {"pi": [64], "vf": [64]},
                       **({"log_std_init": args.log_std_init} if continuous else {}),
                       **({"mask_empty": args.mask_sectors, "cost_prior": args.cost_prior}
                          if sectors else {})},
    )
    if args.level == "goals":
        model.goal_hold = args.hold
    else:
        model.motion_hold, model.motion_commands = args.hold, args.motion_commands
    return model


def train_sb3(args: Any, run_dir: Path, checkpoint: Path | None) -> tuple[PPO, int]:
    """Train (or resume from ``checkpoint``) with Stable-Baselines3; save ``model.zip``.
    Returns the model and the agent-steps trained."""
    scale = args.hold
    venv = ParallelVecEnv([EnvFactory(config, args) for config in args.train_env_configs()],
                          n_workers=args.n_workers)
    venv = VecMonitor(venv)
    venv.seed(args.seed)
    try:
        if checkpoint is not None:
            model = PPO.load(checkpoint, env=venv, device=args.device,
                             tensorboard_log=str(run_dir / "tb"))
        else:
            model = _new_model(args, venv, run_dir)
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


def train_and_evaluate(args: Any, run_dir: Path, checkpoint: Path | None) -> None:
    """Train (or resume from ``checkpoint``) in ``run_dir`` on ``args.backend``, evaluate the
    final policy, keep the best one (:func:`keep_best`) and print the evaluation table. A run
    that fails before writing anything but ``args.json`` removes its folder: no run folder is
    left of a run that never started."""
    if args.backend == "rllib":
        from agents.rllib_training import train_rllib as train
    else:
        train = train_sb3
    try:
        policy, steps = train(args, run_dir, checkpoint)
    except BaseException:
        if {p.name for p in run_dir.iterdir()} <= {"args.json"}:
            shutil.rmtree(run_dir)
        raise
    report = evaluate_policy(policy, args, run_dir, steps)
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
