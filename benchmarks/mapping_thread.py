"""Would a worker thread take topological extraction and merging off the env step's critical
path? Measured, not assumed: ``python benchmarks/mapping_thread.py``.

The env at its defaults re-extracts both robots' maps every 10 steps and merges them every 25
(``benchmarks/env_speed.md``: together ≈ 300 µs of an ≈ 850 µs step). The numba kernels
behind both release the GIL (``nogil=True``), so a worker thread could in principle overlap them
with the next steps' physics, sonar and grid updates. This script runs, on the same seeds and
actions:

- ``sync``: the env as it is (extraction and merge inside the step that schedules them);
- ``thread, lag L``: the same schedule, but each extraction (both robots) and each merge is
  submitted to a one-thread pool on a snapshot of its inputs and its result installed exactly
  ``L`` steps later — deterministic whatever the thread timing, the design a fixed-lag worker
  would have. ``L = 0`` joins at once: the thread's cost without any overlap.

and, separately, one extraction of both robots' maps called directly against the same call
submitted to the thread and joined (no env running beside it).

Output: steps/s by wall clock and by process CPU time, and the ratio to ``sync``, median of
``--repeats`` alternated runs. The verdict of 2026-12-01 is in ``benchmarks/env_speed.md``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from env_speed import _actions  # noqa: E402  (benchmarks/, the script's folder)

from envs import two_robot_explore_v0  # noqa: E402
from envs.two_robot_explore.env import TwoRobotExploreEnv  # noqa: E402
from envs.two_robot_explore.mapping import run_merge  # noqa: E402
from topo.extract import extract_topomap  # noqa: E402
from topo.grid import CellState  # noqa: E402

TOPO_EVERY = 10  # the env's default schedule, run by ThreadedMappingEnv itself


class ThreadedMappingEnv(TwoRobotExploreEnv):
    """The env with extraction and merging run by a worker thread, results installed ``lag``
    steps after they were scheduled: merges on the env's own schedule (``merge_every``),
    extraction every :data:`TOPO_EVERY` steps by this class (the env's is switched off)."""

    def __init__(self, lag: int, **kwargs) -> None:
        super().__init__(mapping={"topo_every": 0}, **kwargs)
        self.lag = lag
        self._pool = ThreadPoolExecutor(1)
        self._pending: list[tuple[int, Future, object]] = []

    def reset(self, seed=None, options=None):
        for _, fut, _ in self._pending:
            fut.result()
        self._pending = []
        return super().reset(seed=seed, options=options)

    def close(self) -> None:
        self._pool.shutdown()
        super().close()

    def _later(self, fut: Future, install) -> None:
        self._pending.append((self.steps + self.lag, fut, install))

    def _sense_and_map(self, travelled) -> None:
        super()._sense_and_map(travelled)
        if self.steps % TOPO_EVERY == 0:
            jobs = []
            for i, rmap in enumerate(self.maps):
                win = rmap.known_window()
                if win is None:
                    continue
                g = rmap.geometry
                origin = (g.origin[0] + win[1].start * g.resolution,
                          g.origin[1] + win[0].start * g.resolution)
                jobs.append((i, rmap.states[win] == CellState.FREE, origin, g.resolution))
            cfg = self._extract_config

            def extract_all():
                return [(i, extract_topomap(free, resolution=res, origin=origin, config=cfg))
                        for i, free, origin, res in jobs]

            def install(maps):
                for i, topomap in maps:
                    self.maps[i].topomap = topomap
                    self._cache_graph(i)

            self._later(self._pool.submit(extract_all), install)
        self._install_due()

    def _install_due(self) -> None:
        due = [p for p in self._pending if p[0] <= self.steps]
        self._pending = [p for p in self._pending if p[0] > self.steps]
        for _, fut, install in due:
            install(fut.result())

    def _fuse(self) -> None:
        self._merge()
        self._install_due()

    def _merge(self) -> None:
        try_grids = self._merge_due()
        if try_grids is None:
            return
        grids = [m.grid.copy() if try_grids else None for m in self.maps]
        fut = self._pool.submit(run_merge, self.maps[0].topomap, self.maps[1].topomap,
                                self.config.mapping.merge_method, *grids, try_grids=try_grids,
                                in_use=self.shared.transform)
        self._later(fut, lambda found: self._install_merge(*found))


def run(make, steps: int, seed: int = 0) -> tuple[float, float, float]:
    """(wall, CPU) steps/s of ``steps`` steps of ``make()``, after a 200-step warm-up, and the
    summed reward (``lag 0`` must reproduce ``sync``'s)."""
    env = make()
    acts = _actions(steps, seed)
    env.reset(seed=seed)
    for a in acts[:200]:
        env.step(a)
    env.reset(seed=seed)
    total = 0.0
    wall, cpu = time.perf_counter(), time.process_time()
    for a in acts:
        if not env.agents:
            env.reset()
        total += env.step(a)[1]["robot_0"]
    out = steps / (time.perf_counter() - wall), steps / (time.process_time() - cpu), total
    env.close()
    return out


def extraction_call(repeats: int) -> tuple[float, float]:
    """Median ms of one extraction of both robots' maps (after 400 steps): called directly, and
    submitted to a one-thread pool and joined."""
    env = two_robot_explore_v0.parallel_env()
    env.reset(seed=0)
    for a in _actions(400, 0):
        env.step(a)
    masks = [(m.states[m.known_window()] == CellState.FREE, m.geometry.resolution)
             for m in env.maps]
    cfg = env._extract_config

    def work():
        return [extract_topomap(free, resolution=res, config=cfg) for free, res in masks]

    pool = ThreadPoolExecutor(1)
    direct, threaded = [], []
    work(), pool.submit(work).result()
    for _ in range(repeats):
        t = time.perf_counter()
        work()
        direct.append(time.perf_counter() - t)
        t = time.perf_counter()
        pool.submit(work).result()
        threaded.append(time.perf_counter() - t)
    pool.shutdown()
    return statistics.median(direct) * 1e3, statistics.median(threaded) * 1e3


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--lags", default="0,5,10", help="comma-separated lags (steps)")
    args = parser.parse_args(argv)
    lags = [int(x) for x in args.lags.split(",")]
    variants = {"sync": two_robot_explore_v0.parallel_env}
    for lag in lags:
        variants[f"thread, lag {lag}"] = lambda lag=lag: ThreadedMappingEnv(lag)
    got: dict[str, list[tuple[float, float, float]]] = {k: [] for k in variants}
    for _ in range(args.repeats):
        for name, make in variants.items():
            got[name].append(run(make, args.steps))
    base_wall = statistics.median(r[0] for r in got["sync"])
    base_cpu = statistics.median(r[1] for r in got["sync"])
    print(f"# extraction and merging in a worker thread ({args.steps} steps, median of "
          f"{args.repeats} alternated runs)\n")
    print("| variant | steps/s | to sync | CPU steps/s | to sync | summed reward |")
    print("|---|---|---|---|---|---|")
    for name, runs in got.items():
        wall = statistics.median(r[0] for r in runs)
        cpu = statistics.median(r[1] for r in runs)
        print(f"| {name} | {wall:,.0f} | {wall / base_wall:.2f} | {cpu:,.0f} | "
              f"{cpu / base_cpu:.2f} | {runs[0][2]:.4f} |")
    direct, threaded = extraction_call(100)
    print(f"\none extraction of both maps: {direct:.2f} ms called directly, {threaded:.2f} ms "
          f"through the thread (submit + join, nothing running beside it)")


if __name__ == "__main__":
    main()
