"""The RLlib loop of ``train.py --backend rllib``: Ray start-up (:func:`start_ray`), the PPO
config of a run (:func:`rllib_config`) and training with periodic checkpoints, evaluations and
the best policy kept (:func:`train_rllib`). Needs the ``rllib`` extra, imported where used
(:mod:`agents.rllib` names the extra when it is missing).

``args`` is a ``train.Args`` (any object with its fields); what both backends share is in
:mod:`agents.training`.
"""

from __future__ import annotations

import functools
import math
import os
import time
from pathlib import Path
from typing import Any

import torch
from tqdm.auto import tqdm

from agents.training import BEST_RLLIB, evaluate_policy, keep_best, log_eval


def start_ray(args: Any) -> bool:
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


def rllib_config(args: Any) -> Any:
    """RLlib's ``PPOConfig`` for ``args`` (:func:`agents.rllib.ppo_config`), with the SB3
    path's hyperparameters: ``n_steps`` decisions per env per update, ``batch_size``
    transitions per gradient step."""
    from agents import rllib  # needs the rllib extra

    return rllib.ppo_config(
        env_config=args.env_config(), level=args.level, hold=args.hold,
        frontier_shaping=args.frontier_shaping, commands=args.motion_commands,
        sector_head=args.sector_head, mask_sectors=args.mask_sectors,
        cost_prior=args.cost_prior, seed=args.seed, num_env_runners=args.num_env_runners,
        envs_per_runner=args.envs_per_runner, train_batch_size=args.n_steps * args.n_envs,
        minibatch_size=args.batch_size, num_epochs=args.n_epochs, lr=args.learning_rate,
        gamma=args.gamma ** args.hold, gae_lambda=args.gae_lambda,
        entropy_coeff=args.ent_coef, clip_param=args.clip_range,
        num_gpus=0 if args.device == "cpu" else int(torch.cuda.is_available()))


def train_rllib(args: Any, run_dir: Path, checkpoint: Path | None) -> tuple[Any, int]:
    """Train (or resume from ``checkpoint``) with RLlib's PPO on the new API stack; save the
    algorithm checkpoint ``rllib/``. Returns the policy (:class:`agents.rllib.RLlibPolicy`)
    and the agent-steps trained."""
    import ray
    from torch.utils.tensorboard import SummaryWriter

    from agents import rllib  # needs the rllib extra

    scale = args.hold
    started = start_ray(args)
    algo = None
    writer = SummaryWriter(str(tb_folder(run_dir / "tb", "rllib_ppo", checkpoint is not None)))
    try:
        algo = rllib_config(args).build_algo()
        steps = 0
        if checkpoint is not None:
            algo.restore_from_path(str(checkpoint))
            steps = rllib.agent_steps(algo) * scale
        start = steps
        next_eval, next_checkpoint = (after(steps, args.eval_every),
                                      after(steps, args.checkpoint_every))
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
                next_checkpoint = after(steps, args.checkpoint_every)
            if steps >= next_eval and steps < args.total_timesteps:
                policy = rllib.RLlibPolicy(algo.get_module(rllib.POLICY_ID), args.hold)
                report = evaluate_policy(policy, args, run_dir, steps)
                log_eval(functools.partial(_add_scalar, writer, step=steps), report)
                keep_best(report, run_dir, lambda: rllib.save_checkpoint(
                    algo, run_dir / BEST_RLLIB, args.level, args.hold))
                next_eval = after(steps, args.eval_every)
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


def _add_scalar(writer: Any, key: str, value: float, *, step: int) -> None:
    writer.add_scalar(key, value, step)


def tb_folder(tb: Path, name: str, resumed: bool) -> Path:
    """``tb/<name>_<k>``: a new ``k`` per run, the latest one when resuming (as SB3 names
    its logs)."""
    taken = [int(p.name.rsplit("_", 1)[1]) for p in tb.glob(f"{name}_*")
             if p.name.rsplit("_", 1)[1].isdigit()]
    latest = max(taken, default=0)
    return tb / f"{name}_{latest if resumed and latest else latest + 1}"


def after(steps: int, every: int) -> float:
    """The first multiple of ``every`` above ``steps`` (``inf`` when ``every`` is 0)."""
    return (steps // every + 1) * every if every else math.inf
