"""Evaluate an explorer against scripted baselines on fixed worlds, as ``train.py`` does after
(and during) training with either backend (Stable-Baselines3 or RLlib).

A policy is evaluated on ``episodes`` fixed procedural worlds whose seeds derive from the run
seed (:func:`eval_seeds`, disjoint from the training envs' seeds), with episodes of
``max_cycles`` steps; the scripted baselines (``Frontier``, ``RandomWalk``, ...) run on the
same worlds once and are cached in the run folder. :func:`evaluate` writes, atomically:

* ``eval.json`` — the summary rows (T50/T85/T95, reached 85 %, final coverage, overlap,
  collisions; :class:`agents.metrics.EpisodeRecorder`) and the seeds;
* ``eval.md`` — the same rows as a Markdown table;
* ``eval_coverage.png`` — mean true coverage against env steps, one curve per explorer;
* ``eval_baselines.json`` — the baselines' episodes, keyed by the worlds and the env config.

Everything takes plain arguments (env config dicts, seeds, explorers), so scripts and both
training backends share it.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import Explorer, run_episode
from agents.metrics import EpisodeRecorder
from topo.validation import check_int

SUMMARY_KEYS = ("T50", "T85", "T95", "final_coverage", "overlap", "collisions")
"""Episode metrics averaged into a summary row (plus ``reached_T85``)."""


def eval_seeds(seed: int, episodes: int) -> list[int]:
    """``episodes`` world seeds derived from the run ``seed`` (a separate ``SeedSequence``,
    so they are disjoint from the training envs' ``seed + k``)."""
    seed = check_int(seed, "seed", low=0)
    episodes = check_int(episodes, "episodes", low=1)
    ss = np.random.SeedSequence([seed, 0xE7A1])
    return [int(s) for s in ss.generate_state(episodes)]


def eval_worlds(env_config: Mapping[str, Any], seed: int, episodes: int,
                max_cycles: int) -> tuple[dict[str, Any], list[int], dict[str, Any]]:
    """The evaluation's env config (``env_config`` with ``max_cycles`` steps per episode), its
    seeds (:func:`eval_seeds`) and the JSON key identifying both (for caching results)."""
    max_cycles = check_int(max_cycles, "max_cycles", low=1)
    config = {**env_config, "max_cycles": max_cycles}
    seeds = eval_seeds(seed, episodes)
    return config, seeds, {"seeds": seeds, "config": json.loads(json.dumps(config, default=str))}


def run_explorer(team: Mapping[str, Explorer] | str, config: Mapping[str, Any],
                 seeds: Sequence[int]) -> list[dict[str, Any]]:
    """Metrics (:meth:`agents.metrics.EpisodeRecorder.summary`) of ``team`` (one explorer per
    robot, or an explorer's name for :func:`agents.registry.make_team`) on the env ``config``
    describes
    (``two_robot_explore_v0``, or ``multi_robot_explore_v0`` for its ``n_robots`` > 2:
    :func:`envs.parallel_env_for`), one episode per seed."""
    from agents.registry import make_team
    from envs import parallel_env_for

    out = []
    for seed in seeds:
        env = parallel_env_for(config)
        if isinstance(team, str):
            team = make_team(team, env=env)
        rec = EpisodeRecorder()
        try:
            run_episode(env, team, seed=seed, callback=rec)
        finally:
            env.close()
        out.append(rec.summary())
    return out


def summarise(name: str, episodes: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """One table row: the mean of :data:`SUMMARY_KEYS` and of ``reached_T85`` over
    ``episodes`` (at least one)."""
    if not episodes:
        raise ValueError(f"summarise({name!r}): episodes is empty; need at least one")
    row: dict[str, Any] = {"explorer": name, "episodes": len(episodes)}
    for key in SUMMARY_KEYS:
        row[key] = float(np.mean([e[key] for e in episodes]))
    row["reached_T85"] = float(np.mean([e["reached_T85"] for e in episodes]))
    return row


def rank_key(row: Mapping[str, Any]) -> tuple[float, float]:
    """Sort key of a summary row (:func:`summarise`), lower is better: the mean T85, then the
    final coverage, higher first. Early in training most episodes never reach 85 % and their
    T85s all count as the episode length, so the coverage they end at decides."""
    return float(row["T85"]), -float(row["final_coverage"])


def _jsonable(episodes: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{**e, "coverage": np.asarray(e["coverage"]).tolist()} for e in episodes]


def evaluate(team: Mapping[str, Explorer], run_dir: str | Path, step: int, *,
             env_config: Mapping[str, Any], seed: int, episodes: int, max_cycles: int,
             baselines: Sequence[str] = ("frontier", "random_walk"),
             name: str = "ppo") -> dict[str, Any]:
    """Evaluate ``team`` (the policy, one explorer per robot) and the scripted ``baselines``
    (names of :data:`agents.registry.EXPLORERS`) on the fixed worlds of
    :func:`eval_worlds`; write the files of the module docstring into ``run_dir``.

    Args:
        team: ``{"robot_0": Explorer, "robot_1": Explorer, ...}`` driving the policy's robots
            (one per robot of ``env_config``'s team).
        run_dir: the run folder (created if missing).
        step: agent-steps trained so far (for the titles and ``eval.json``).
        env_config, seed, episodes, max_cycles: the worlds (:func:`eval_worlds`).
        baselines: scripted explorers to compare with (cached in ``eval_baselines.json``).
        name: the policy's row name.

    Returns:
        ``{"step", "seeds", "rows", "max_cycles"}`` (what ``eval.json`` holds).
    """
    from topo.fileio import atomic_write_bytes, atomic_write_json

    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    config, seeds, key = eval_worlds(env_config, seed, episodes, max_cycles)
    cache = run_dir / "eval_baselines.json"
    stored = json.loads(cache.read_text()) if cache.exists() else {}
    cached: dict[str, list[dict]] = stored["explorers"] if stored.get("key") == key else {}
    for baseline in baselines:
        if baseline not in cached:
            cached[baseline] = _jsonable(run_explorer(baseline, config, seeds))
    atomic_write_json(cache, {"key": key, "explorers": cached})

    curves = {name: _jsonable(run_explorer(team, config, seeds)),
              **{b: cached[b] for b in baselines}}
    rows = [summarise(n, eps) for n, eps in curves.items()]
    report = {"step": step, "seeds": seeds, "rows": rows, "max_cycles": max_cycles}
    atomic_write_json(run_dir / "eval.json", report)
    lines = [f"Evaluation at {step} agent-steps on {len(seeds)} fixed worlds "
             f"({max_cycles}-step episodes; T = steps to that true coverage, "
             f"not reached = {max_cycles + 1})", "",
             "| explorer | T50 | T85 | T95 | reached 85% | final coverage | overlap | "
             "collisions |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['explorer']} | {r['T50']:.0f} | {r['T85']:.0f} | {r['T95']:.0f} | "
                     f"{r['reached_T85']:.0%} | {r['final_coverage']:.2f} | {r['overlap']:.2f} "
                     f"| {r['collisions']:.1f} |")
    atomic_write_bytes(run_dir / "eval.md", ("\n".join(lines) + "\n").encode())
    plot_coverage(curves, run_dir / "eval_coverage.png", step)
    return report


def plot_coverage(curves: Mapping[str, Sequence[Mapping[str, Any]]], path: str | Path,
                  step: int) -> None:
    """Mean true-coverage curve per explorer (episodes padded with their last value) to
    ``path``, atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from topo.plotting import save_figure

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, eps in curves.items():
        n = max(len(e["coverage"]) for e in eps)
        padded = np.array([np.pad(e["coverage"], (0, n - len(e["coverage"])), mode="edge")
                           for e in eps])
        ax.plot(np.arange(1, n + 1), padded.mean(axis=0), label=label)
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
