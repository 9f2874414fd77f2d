"""How fast a scripted team explores large buildings: team steps per second against the raw
env stepped with the same actions in the same run.

    python benchmarks/explorer_speed.py [--sizes 20 40 80] [--steps 2000 6000 6000]
        [--explorers frontier coordinated_frontier] [--seed 100] [--robots N] [--json F]

For each building size (``world={"size": (S, S)}``) and explorer: one episode of ``--steps``
steps (``max_cycles``), the team's ``act()`` timed per robot and the env's ``step()`` timed;
then a fresh env reset with the same seed is stepped with the recorded actions alone (the env
floor: what the env costs without explorers). Columns: team steps/s and ms/step (explorers +
env), the explorers' share of that time, the env floor (steps/s of the replay), the true
coverage reached, and per robot the planning cost: ``act()`` ms per step, plans, ms per plan
and the robot's known area at the end (so that cost per plan can be read against the area it
plans over). The CPU columns are the same from the process's CPU time (``time.process_time``):
on a machine shared with other jobs they move less than wall time.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _env(size: float, steps: int, robots: int | None):
    from envs import two_robot_explore_v0

    kwargs = {"max_cycles": steps, "world": {"size": (size, size)}}
    if robots is not None and robots != 2:
        from envs import multi_robot_explore_v0  # the N-robot env (issue 32)

        return multi_robot_explore_v0.parallel_env(n_robots=robots, **kwargs)
    return two_robot_explore_v0.parallel_env(**kwargs)


def measure(explorer: str, size: float, steps: int, seed: int,
            robots: int | None = None) -> dict:
    """One timed episode and its replay on the raw env (module docstring)."""
    from agents.registry import make_team

    env = _env(size, steps, robots)
    team = make_team(explorer, env=env)
    obs, infos = env.reset(seed=seed)
    for explorer_, s in zip(team.values(), np.random.SeedSequence(seed).spawn(len(team)),
                            strict=True):
        explorer_.reset(int(s.generate_state(1)[0]))
    act_s = dict.fromkeys(team, 0.0)
    act_cpu = 0.0
    env_s = env_cpu = 0.0
    log = []
    coverage = 0.0
    while env.agents:
        actions = {}
        c0 = time.process_time()
        for a in env.agents:
            t0 = time.perf_counter()
            actions[a] = team[a].act(obs[a], infos[a])
            act_s[a] += time.perf_counter() - t0
        c1 = time.process_time()
        act_cpu += c1 - c0
        log.append(actions)
        t0 = time.perf_counter()
        obs, _r, _t, _u, infos = env.step(actions)
        env_s += time.perf_counter() - t0
        env_cpu += time.process_time() - c1
        if infos:
            coverage = float(next(iter(infos.values()))["true_coverage"])
    raw = env.unwrapped
    robots_out = {}
    for a, e in team.items():
        snap = raw.robot_map(a)
        plans = getattr(e, "events", {}).get("plans", 0)
        robots_out[a] = {"act_ms_per_step": act_s[a] / len(log) * 1e3, "plans": plans,
                         "ms_per_plan": act_s[a] / plans * 1e3 if plans else float("nan"),
                         "known_m2": snap.known_cells * snap.grid.resolution ** 2}
    replay = _env(size, steps, robots)
    replay.reset(seed=seed)
    t0, c0 = time.perf_counter(), time.process_time()
    for actions in log:
        replay.step(actions)
    floor_s, floor_cpu = time.perf_counter() - t0, time.process_time() - c0
    total = sum(act_s.values()) + env_s
    return {"explorer": explorer, "size": size, "steps": len(log),
            "steps_per_s": len(log) / total, "ms_per_step": total / len(log) * 1e3,
            "explorer_share": sum(act_s.values()) / total,
            "env_floor_steps_per_s": len(log) / floor_s, "env_in_run_ms": env_s / len(log) * 1e3,
            "cpu_steps_per_s": len(log) / (act_cpu + env_cpu),
            "cpu_explorer_ms": act_cpu / len(log) * 1e3,
            "cpu_env_floor_steps_per_s": len(log) / floor_cpu,
            "coverage": coverage, "robots": robots_out}


def print_table(rows: list[dict]) -> None:
    """The speed table and the per-robot planning cost table (markdown)."""
    print("| explorer | building | steps | team steps/s | ms/step | explorer share | "
          "env floor steps/s | env ms/step in run | CPU: team steps/s | CPU: explorers "
          "ms/step | CPU: env floor steps/s | true coverage |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['explorer']} | {r['size']:g} m | {r['steps']} | {r['steps_per_s']:.0f} | "
              f"{r['ms_per_step']:.2f} | {r['explorer_share']:.0%} | "
              f"{r['env_floor_steps_per_s']:.0f} | {r['env_in_run_ms']:.2f} | "
              f"{r['cpu_steps_per_s']:.0f} | {r['cpu_explorer_ms']:.2f} | "
              f"{r['cpu_env_floor_steps_per_s']:.0f} | {r['coverage']:.2f} |")
    print("\n| explorer | building | robot | act() ms/step | plans | ms/plan | known m² | "
          "ms/plan per 100 m² known |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        for a, p in r["robots"].items():
            print(f"| {r['explorer']} | {r['size']:g} m | {a} | {p['act_ms_per_step']:.3f} | "
                  f"{p['plans']} | {p['ms_per_plan']:.2f} | {p['known_m2']:.0f} | "
                  f"{p['ms_per_plan'] / max(p['known_m2'], 1e-9) * 100:.3f} |")


def main() -> None:
    import torch

    torch.set_num_threads(1)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=float, nargs="+", default=[20.0, 40.0, 80.0])
    parser.add_argument("--steps", type=int, nargs="+", default=[2000, 6000, 6000],
                        help="episode length per size (one value: the same for all)")
    parser.add_argument("--explorers", nargs="+", default=["frontier", "coordinated_frontier"])
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--robots", type=int, default=None,
                        help="team size (default: the two-robot env)")
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    args = parser.parse_args()
    steps = args.steps if len(args.steps) > 1 else args.steps * len(args.sizes)
    if len(steps) != len(args.sizes):
        parser.error(f"--steps must give one value or one per size ({len(args.sizes)}), "
                     f"got {len(steps)}")
    rows = []
    for size, n in zip(args.sizes, steps, strict=True):
        for e in args.explorers:
            rows.append(measure(e, size, n, args.seed, args.robots))
            r = rows[-1]
            print(f"{e} {size:g} m: {r['steps_per_s']:.0f} steps/s, floor "
                  f"{r['env_floor_steps_per_s']:.0f}", flush=True)
    print()
    print_table(rows)
    if args.json is not None:
        from topo.fileio import atomic_write_json

        atomic_write_json(args.json, rows)


if __name__ == "__main__":
    main()
