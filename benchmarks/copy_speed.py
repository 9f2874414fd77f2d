"""Cost of copying ``two_robot_explore_v0`` (``pickle`` and ``copy.deepcopy``), against stepping.

A copy replays the episode since ``reset`` (the env's manual, Copies), so restoring costs about
what the steps since ``reset`` cost, less the observations and infos a replay does not build.
For each setting and each episode length ``N`` (steps since ``reset``; seed 0, the default 20 m
world, a new random command every 10 steps as in ``benchmarks/_actions.py``) this prints, in CPU
milliseconds (the machine is shared; wall time in brackets): the original's ``N`` steps (the
reference, the same process), ``pickle.dumps``, ``pickle.loads`` (the replay) and
``copy.deepcopy``, each restore per 1000 restored steps, its ratio to stepping, and the
pickle's size. Medians of ``--repeats`` restores.

Usage::

    python benchmarks/copy_speed.py                  # ~1 min
    python benchmarks/copy_speed.py --steps 500 2000 --repeats 5
"""

from __future__ import annotations

import argparse
import copy
import pickle
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

from _actions import fixed_actions

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from envs import two_robot_explore_v0  # noqa: E402

SETTINGS = {
    "defaults": {},
    "no topo/merge": {"mapping": {"topo_every": 0, "merge_every": 0}},
}


def _timed(fn: Callable[[], object]) -> tuple[float, float, object]:
    """``(CPU s, wall s, result)`` of one call of ``fn``."""
    c0, w0 = time.process_time(), time.perf_counter()
    out = fn()
    return time.process_time() - c0, time.perf_counter() - w0, out


def _medians(fn: Callable[[], object], repeats: int) -> tuple[float, float]:
    """Median CPU and wall seconds of ``repeats`` calls of ``fn``."""
    runs = [_timed(fn)[:2] for _ in range(repeats)]
    return statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)


def _episode(kwargs: dict, steps: int):
    """An env after ``reset(seed=0)`` and ``steps`` steps, and the CPU and wall time of those
    steps (``reset`` included)."""
    env = two_robot_explore_v0.parallel_env(max_cycles=steps, **kwargs)
    acts = fixed_actions(steps, 0)

    def run():
        env.reset(seed=0)
        for k in range(steps):
            env.step(acts[k])

    cpu, wall, _ = _timed(run)
    return env, cpu, wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, nargs="+", default=[250, 1000, 3000])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    _episode({}, 300)  # compiled kernels (those of the grid merges too) load outside the timings
    print("| setting | steps since reset | stepping ms | dumps ms | loads ms (replay) "
          "| deepcopy ms | loads ms / 1000 steps | loads / stepping | pickle bytes |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, kwargs in SETTINGS.items():
        for steps in args.steps:
            env, cpu, wall = _episode(kwargs, steps)
            data = pickle.dumps(env)
            dumps = _medians(lambda env=env: pickle.dumps(env), args.repeats)
            loads = _medians(lambda data=data: pickle.loads(data), args.repeats)
            deep = _medians(lambda env=env: copy.deepcopy(env), args.repeats)
            print(f"| {name} | {steps} | {cpu * 1e3:.0f} ({wall * 1e3:.0f}) "
                  f"| {dumps[0] * 1e3:.2f} ({dumps[1] * 1e3:.2f}) "
                  f"| {loads[0] * 1e3:.0f} ({loads[1] * 1e3:.0f}) "
                  f"| {deep[0] * 1e3:.0f} ({deep[1] * 1e3:.0f}) "
                  f"| {loads[0] * 1e6 / steps:.0f} | {loads[0] / cpu:.2f} | {len(data):,} |",
                  flush=True)


if __name__ == "__main__":
    main()
