"""SuperSuit vectorisation of ``two_robot_explore_v0``: throughput in-process and with 2 worker
processes, with the env's light infos and with the heavy infos it used to return.

    python benchmarks/supersuit_speed.py [--envs 4] [--steps 200] [--rounds 5] [--size 20]

Each configuration is ``supersuit.concat_vec_envs_v1(pettingzoo_env_to_vec_env_v1(env),
envs, num_cpus=k)``: ``k = 0`` (SuperSuit also runs ``k = 1`` in-process) steps every env in
this process; ``k = 2`` starts two worker processes sharing the ``envs`` copies, which send
observations through shared memory and rewards, dones and infos through pipes. "heavy" wraps
each env so that its infos also carry what they carried before they were made light: each
robot's ``OccupancyGrid`` and ``TopoMap``, megabytes pickled through the pipes every step.

All four are built first; then ``--rounds`` rounds each time ``--steps`` steps of every
configuration in turn (random actions, episodes auto-reset), so that they see the same machine
load; a configuration's speed is its best round. Printed per configuration: agent-steps/s (one
agent-step = one robot's step), the ratio to in-process (the speed-up of two processes on a
2-core machine, the target), and CPU seconds per 1000 agent-steps of this process and its
workers (IPC overhead shows there even when other jobs hold the cores). The load average before
and after is printed: other jobs on the cores cap the 2-process speed-up.

Needs the ``bench`` extra (SuperSuit).
"""

from __future__ import annotations

import argparse
import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np
from pettingzoo.utils.wrappers import BaseParallelWrapper

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from envs import two_robot_explore_v0  # noqa: E402


class HeavyInfos(BaseParallelWrapper):
    """A ``ParallelEnv`` wrapper adding each robot's grid and topological map to its infos,
    as the env's infos held them before they were made light."""

    def _heavy(self, infos: dict) -> dict:
        for agent, info in infos.items():
            snap = self.env.unwrapped.robot_map(agent)
            info["grid"], info["topomap"] = snap.grid, snap.topomap
        return infos

    def reset(self, seed=None, options=None):
        obs, infos = self.env.reset(seed=seed, options=options)
        return obs, self._heavy(infos)

    def step(self, actions):
        obs, rewards, terms, truncs, infos = self.env.step(actions)
        return obs, rewards, terms, truncs, self._heavy(infos)


class _Factory:
    """Picklable env factory (worker processes build their own envs)."""

    def __init__(self, size: float, heavy: bool) -> None:
        self.size, self.heavy = size, heavy

    def __call__(self):
        env = two_robot_explore_v0.parallel_env(world={"size": (self.size, self.size)})
        return HeavyInfos(env) if self.heavy else env


def _cpu_seconds(pids: list[int]) -> float:
    """User + system CPU seconds of processes ``pids`` so far (Linux ``/proc``)."""
    total = 0.0
    for pid in pids:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


class Config:
    """One vectorised configuration, built once and timed in rounds."""

    def __init__(self, size: float, heavy: bool, envs: int, cpus: int) -> None:
        import supersuit as ss

        self.label = ("heavy" if heavy else "light", "2 processes" if cpus else "in-process")
        self.venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(
            _Factory(size, heavy)()), envs, num_cpus=cpus, base_class="gymnasium")
        self.pids = [p.pid for p in getattr(self.venv, "procs", [])]
        self.venv.reset(seed=0)
        n = self.venv.num_envs
        self.actions = np.random.default_rng(0).uniform(-1, 1, (50, n, 2)).astype(np.float32)
        for k in range(20):
            *_, infos = self.venv.step(self.actions[k % 50])
        self.info_bytes = len(pickle.dumps(infos))
        self.best = 0.0
        self.cpu_per_step: list[float] = []

    def time(self, steps: int) -> None:
        """One round: ``steps`` vectorised steps."""
        n = self.venv.num_envs
        c0 = time.process_time() + _cpu_seconds(self.pids)
        t0 = time.perf_counter()
        for k in range(steps):
            self.venv.step(self.actions[k % 50])
        wall = time.perf_counter() - t0
        cpu = time.process_time() + _cpu_seconds(self.pids) - c0
        self.best = max(self.best, steps * n / wall)
        self.cpu_per_step.append(cpu / (steps * n))

    def close(self) -> None:
        self.venv.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=4, help="env copies (2 robots each)")
    parser.add_argument("--steps", type=int, default=200, help="vectorised steps per round")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--size", type=float, default=20.0, help="procedural world side, m")
    args = parser.parse_args()
    print(f"# SuperSuit concat_vec_envs_v1: {args.envs} envs ({2 * args.envs} agents), "
          f"{args.size:g} m worlds, {args.steps} steps per round, best of {args.rounds} "
          f"rounds; load average before {os.getloadavg()[0]:.2f}\n")
    configs = [Config(args.size, heavy, args.envs, cpus) for heavy in (False, True)
               for cpus in (0, 2)]
    for _ in range(args.rounds):
        for config in configs:
            config.time(args.steps)
    print("| infos | vectorisation | agent-steps/s | vs in-process | CPU s / 1000 agent-steps "
          "| infos per step (pickled) |")
    print("|---|---|---|---|---|---|")
    for k, config in enumerate(configs):
        ref = configs[k - k % 2]
        print(f"| {config.label[0]} | {config.label[1]} | {config.best:,.0f} | "
              f"{config.best / ref.best:.2f} | {1e3 * float(np.median(config.cpu_per_step)):.2f} "
              f"| {config.info_bytes / 1e3:,.1f} kB |")
        config.close()
    print(f"\nload average after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
