"""Re-evaluate finished ``train.py`` runs with the current code and print the comparison table
of ``benchmarks/training.md``: the policy's T85 against ``Frontier`` and ``RandomWalk`` on each
run's own fixed evaluation worlds.

Usage::

    python benchmarks/training_eval.py runs/seed1 runs/seed2 --episodes 10 --out out/training_eval

Each run is evaluated by ``train.evaluate`` (the same worlds and episode length as the run's
own evaluation: ``eval_max_cycles``, default 3 × ``max_cycles``) into ``OUT/<run name>/``; the
scripted baselines are computed once per set of worlds. Runs of either backend work (SB3's
``model.zip``, RLlib's ``rllib/``). Use it after changing the explorers or
the env, so that every row of a table comes from the same code.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import fields
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import train  # noqa: E402
from agents.evaluation import eval_worlds, run_explorer, summarise  # noqa: E402
from agents.goals import SECTOR_RULES, SectorRule  # noqa: E402
from topo.fileio import atomic_write_bytes  # noqa: E402


def run_args(run_dir: Path, episodes: int | None) -> train.Args:
    """The ``train.Args`` a run was made with (``args.json``), evaluation-only changes applied."""
    saved = json.loads((run_dir / "args.json").read_text())
    known = {f.name for f in fields(train.Args)}
    kwargs = {k: v for k, v in saved.items() if k in known and k not in ("resume", "runs_dir")}
    for key in ("world_size", "eval_baselines"):
        kwargs[key] = tuple(kwargs[key])
    if episodes is not None:
        kwargs["eval_episodes"] = episodes
    return train.Args(**kwargs)


def rule_row(rule: str, args: train.Args, cache: Path) -> dict:
    """The summary row of :class:`SectorRule` ``rule`` on ``args``' evaluation worlds (cached
    per seed in ``cache``, keyed by the worlds and the env config)."""
    config, seeds, key = eval_worlds(args.env_config(), args.seed, args.eval_episodes,
                                     args.eval_max_cycles)
    if cache.exists() and (stored := json.loads(cache.read_text()))["key"] == key:
        return stored["row"]
    team = {a: SectorRule(rule, hold=args.hold) for a in ("robot_0", "robot_1")}
    row = summarise(rule, run_explorer(team, config, seeds))
    atomic_write_bytes(cache, json.dumps({"key": key, "row": row}).encode())
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path,
                        help="run folders (with model.zip or rllib/)")
    parser.add_argument("--episodes", type=int, default=None,
                        help="evaluation worlds per run (default: the run's eval_episodes)")
    parser.add_argument("--out", type=Path, default=Path("out/training_eval"))
    parser.add_argument("--rules", nargs="*", default=[], choices=SECTOR_RULES,
                        help="goal-level rules evaluated on each seed's worlds too")
    opts = parser.parse_args()
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    rows = []
    for run in opts.runs:
        args = run_args(run, opts.episodes)
        missing = {"frontier", "random_walk"} - set(args.eval_baselines)
        args.eval_baselines = tuple(args.eval_baselines) + tuple(sorted(missing))
        if (run / "model.zip").is_file():
            model = PPO.load(run / "model.zip", device="cpu")
            steps = model.num_timesteps * args.steps_per_decision
        elif (run / "rllib").is_dir():  # --backend rllib: its final evaluation has the count
            from agents.rllib import RLlibPolicy

            model = RLlibPolicy.load(run / "rllib")
            steps = json.loads((run / "eval.json").read_text())["step"]
        else:
            raise SystemExit(f"{run}: no model.zip or rllib/ (not a finished train.py run)")
        out = opts.out / run.name
        out.mkdir(parents=True, exist_ok=True)
        cache = opts.out / f"baselines_seed{args.seed}.json"  # shared by runs of one seed
        if cache.exists():
            atomic_write_bytes(out / "eval_baselines.json", cache.read_bytes())
        report = train.evaluate(model, args, out, steps)
        atomic_write_bytes(cache, (out / "eval_baselines.json").read_bytes())
        by = {r["explorer"]: r for r in report["rows"]}
        for rule in opts.rules:
            by[rule] = rule_row(rule, args, opts.out / f"rule_{rule}_seed{args.seed}.json")
        rows.append((run.name, args, steps, by))
        print(f"{run.name}: done", flush=True)

    print("\n| run | level | reward | agent-steps | PPO T85 | Frontier T85 | PPO / Frontier | "
          "RandomWalk T85 | PPO better than RandomWalk by | PPO T95 | Frontier T95 | "
          "PPO reached 85 % |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, args, steps, by in rows:
        ppo, fr, rw = by["ppo"], by["frontier"], by["random_walk"]
        # RandomWalk's T85 is a lower bound when some episode never got there
        bound = "≥ " if rw["reached_T85"] < 1 else ""
        print(f"| {name} | {args.level} | {args.reward_mode} | {steps} | {ppo['T85']:.0f} | "
              f"{fr['T85']:.0f} | {ppo['T85'] / fr['T85']:.2f} | {bound}{rw['T85']:.0f} | "
              f"{bound}{1 - ppo['T85'] / rw['T85']:.0%} | {ppo['T95']:.0f} | {fr['T95']:.0f} | "
              f"{ppo['reached_T85']:.0%} |")
    if opts.rules:
        print("\n| run | " + " | ".join(f"{r} T85" for r in ("ppo", *opts.rules)) + " |")
        print("|---|" + "---|" * (1 + len(opts.rules)))
        for name, _args, _steps, by in rows:
            print(f"| {name} | " + " | ".join(f"{by[r]['T85']:.0f}" for r in ("ppo", *opts.rules))
                  + " |")

if __name__ == "__main__":
    main()
