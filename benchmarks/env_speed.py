"""Speed of ``two_robot_explore_v0``: env steps/s, a per-stage breakdown, the raw floor, world
size scaling, and memory over a long run.

The **raw floor** is the pymunk substeps of both robots plus the same sonar ray casts
(``segments × rays × 2`` per step), nothing else, measured in the same run on the same world.
It is measured two ways:

- casting through pymunk's public ``Space.segment_query_first`` — the issue's definition ("about
  3,000 steps/s here" when it was written), the floor the 40 % target is read against;
- casting as the env does (its own ``Sonar._cast``: the world's compiled ray caster,
  ``envs/explore/raycast.py``, a whole scan in one call), several times faster: what
  physics and casts cost the env itself.

The env is reported as steps/s and as its ratio to each.

The host's speed drifts by ±10 % over minutes (the floor alone has read 4,500–5,800 steps/s
on one machine in a day), and an env's speed depends on its world and the robots' paths, so the
section "Seeds" measures, for each of seeds 0–4 (its own world), the env and both floors one
right after the other on that world and prints each seed's ratios and their median: the ratio
to read against the target.

**Copies** (``--copies``, instead of the rest): the cost of copying the env (``pickle`` and
``copy.deepcopy``), against stepping. A copy replays the episode since ``reset`` (the env's
manual, Copies), so restoring costs about what the steps since ``reset`` cost, less the
observations and infos a replay does not build. For each setting and each episode length ``N``
(steps since ``reset``; seed 0, the default 20 m world, a new random command every 10 steps as in
``benchmarks/_actions.py``) this prints, in CPU milliseconds (the machine is shared; wall time in
brackets): the original's ``N`` steps (the reference, the same process), ``pickle.dumps``,
``pickle.loads`` (the replay) and ``copy.deepcopy``, each restore per 1000 restored steps, its
ratio to stepping, and the pickle's size. Medians of ``--repeats`` restores.

Usage::

    python benchmarks/env_speed.py                 # defaults, ~1.5 min
    python benchmarks/env_speed.py --soak 100000   # plus a 100k-step memory/free-space soak
    python benchmarks/env_speed.py --copies        # the copy table only, ~1 min
    python benchmarks/env_speed.py --copies 500 2000 --repeats 5

Stage timings wrap the env's hooks with ``time.perf_counter`` (a few % overhead, so the
breakdown's total is a little above the untimed run).

Steps/s are wall-clock (what the speed target counts); the "CPU" columns divide by the process's
CPU time instead, which other jobs on a shared machine disturb much less, so their ratios are
the fairer comparison when the machine is busy (the two agree on a quiet one).
"""

from __future__ import annotations

import argparse
import copy
import functools
import math
import pickle
import platform
import resource
import statistics
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from _actions import fixed_actions

from envs import two_robot_explore_v0
from envs.explore import env as env_module
from envs.explore import mapping, merging, raycast, robot, sonar
from envs.explore.config import MappingConfig


@dataclass(frozen=True, slots=True)
class Speed:
    """Steps per second of one timed loop: by wall clock and by this process's CPU time."""

    wall: float
    cpu: float


class _Clock:
    """Wall and CPU time since construction, as a :class:`Speed` for ``steps`` steps."""

    def __init__(self) -> None:
        self._wall = time.perf_counter()
        self._cpu = time.process_time()

    def speed(self, steps: int) -> Speed:
        return Speed(steps / (time.perf_counter() - self._wall),
                     steps / (time.process_time() - self._cpu))


def run_env(steps: int, seed: int = 0, **kwargs) -> tuple[Speed, object]:
    """Steps/s of the env over ``steps`` steps (resetting when an episode ends)."""
    par = two_robot_explore_v0.parallel_env(max_cycles=steps, **kwargs)
    par.reset(seed=seed)
    acts = fixed_actions(steps, seed)
    clock = _Clock()
    for k in range(steps):
        if not par.agents:
            par.reset()
        par.step(acts[k])
    return clock.speed(steps), par


def run_floor(par, steps: int, seed: int = 0, public: bool = False) -> Speed:
    """Steps/s of physics + ray casts alone, on ``par``'s current world and start poses; the
    casts call chipmunk as the env does, or pymunk's public query with ``public``."""
    world = par.world
    cfg = par.config
    starts = np.array([r.start for r in par.robots])
    robots = [robot.Robot(i, starts[i], cfg.robot) for i in range(2)]
    space = robot.build_space(world.segments, robots)
    caster = raycast.RayCaster(world.segments, cfg.robot.radius)
    son = sonar.Sonar(cfg.sonar, cfg.robot.radius)
    acts = fixed_actions(steps, seed)
    w_max = math.radians(cfg.robot.max_turn_rate)
    dt, substeps = cfg.robot.dt, cfg.robot.substeps
    query = space.segment_query_first
    clock = _Clock()
    for k in range(steps):
        for r, name in zip(robots, ("robot_0", "robot_1"), strict=True):
            v, w = acts[k][name]
            r.command(float(v) * cfg.robot.max_speed, float(w) * w_max)
        robot.simulate(space, robots, dt, substeps)
        if not public:  # the env's own casts
            poses = [r.true_pose() for r in robots]
            for i, pose in enumerate(poses):
                caster.discs[i] = pose[:2]
            for i, pose in enumerate(poses):
                son._cast(caster, pose, i)
            continue
        for r in robots:
            p = r.body.position
            pose = np.array([p.x, p.y, r.body.angle])
            starts_, ends = son.ray_segments(pose)
            f = r.sensor_filter
            for a, b in zip(starts_.tolist(), ends.tolist(), strict=True):
                query(a, b, 0.0, f)
    return clock.speed(steps)


class StageTimer:
    """Wraps functions/methods to accumulate their exclusive wall time under a stage name (time
    spent in another wrapped function called from inside goes to that one's stage)."""

    def __init__(self) -> None:
        self.total = defaultdict(float)
        self._saved = []
        self._children = [0.0]

    def wrap(self, owner, name: str, stage: str) -> None:
        fn = getattr(owner, name)
        self._saved.append((owner, name, fn))
        total = self.total
        children = self._children

        @functools.wraps(fn)
        def timed(*args, **kwargs):
            children.append(0.0)
            t = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                elapsed = time.perf_counter() - t
                inner = children.pop()
                total[stage] += elapsed - inner
                children[-1] += elapsed

        setattr(owner, name, timed)

    def restore(self) -> None:
        for owner, name, fn in reversed(self._saved):
            setattr(owner, name, fn)
        self._saved.clear()


def breakdown(steps: int, seed: int = 0) -> tuple[dict[str, float], float]:
    """Seconds per stage over ``steps`` steps, and the whole run's seconds."""
    timer = StageTimer()
    env_cls = env_module.TwoRobotExploreEnv
    timer.wrap(env_module, "parse_actions", "actions")
    timer.wrap(env_cls, "_simulate", "physics (substeps)")
    timer.wrap(robot.Robot, "update_odometry", "odometry")
    timer.wrap(sonar.Sonar, "measure", "sonar ray casts")
    timer.wrap(mapping.RobotMap, "integrate", "grid updates (2 robot maps)")
    timer.wrap(mapping.SharedMap, "add", "shared map")
    timer.wrap(mapping.OracleCoverage, "add", "true coverage (sweeps)")
    timer.wrap(mapping.RobotMap, "extract", "topo extraction (every 25)")
    timer.wrap(merging, "run_merge", "merges (every 25)")
    timer.wrap(env_cls, "_rewards", "rewards/ends")
    timer.wrap(env_cls, "_observe", "observations")
    timer.wrap(env_cls, "_infos", "infos")
    try:
        t0 = time.perf_counter()
        run_env(steps, seed)
        whole = time.perf_counter() - t0
    finally:
        timer.restore()
    return dict(timer.total), whole


def _current_rss_mib() -> float:
    """Resident set size now (Linux ``/proc``; NaN elsewhere)."""
    status = Path("/proc/self/status")
    if not status.exists():
        return math.nan
    for line in status.read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return math.nan


def soak(steps: int, seed: int = 1) -> None:
    """Long run with defaults: RSS every 10 % of the way (printed as it goes), and the robots
    checked to stay in free space every step."""
    par = two_robot_explore_v0.parallel_env(max_cycles=1000)
    par.reset(seed=seed)
    rng = np.random.default_rng(seed)
    act = {a: np.zeros(2, dtype=np.float32) for a in par.possible_agents}
    outside = 0
    print(f"\n## Soak: {steps:,} steps with defaults (episodes of 1000 steps)")
    print("| steps | RSS (MiB) | peak RSS (MiB) | robot positions outside free space | steps/s |")
    print("|---|---|---|---|---|", flush=True)
    t0 = time.perf_counter()
    for k in range(steps):
        if not par.agents:
            par.reset()
        if k % 10 == 0:
            act = {a: np.array([rng.uniform(0.2, 1), rng.uniform(-1, 1)], dtype=np.float32)
                   for a in par.possible_agents}
        par.step(act)
        poses = np.array([r.true_pose()[:2] for r in par.robots])
        outside += int((~par.world.is_free(poses)).sum())
        if (k + 1) % max(steps // 10, 1) == 0:
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            rate = (k + 1) / (time.perf_counter() - t0)
            print(f"| {k + 1:,} | {_current_rss_mib():,.1f} | {peak:,.1f} | {outside} | "
                  f"{rate:,.0f} |", flush=True)


def seeds_table(steps: int, seeds: tuple[int, ...] = (0, 1, 2, 3, 4)) -> None:
    """Per seed: the env at defaults for ``steps`` steps, then both floors on its world and
    start poses (back to back, so host drift cancels in the ratios); the medians last."""
    print(f"\n## Seeds (defaults, {steps:,} steps each; floors on the same world right after)")
    print("| seed | env steps/s | pymunk-API floor | ratio | floor casting as the env | ratio |")
    print("|---|---|---|---|---|---|")
    ratios = []
    for seed in seeds:
        env_sps, par = run_env(steps, seed)
        public = run_floor(par, steps, seed, public=True)
        floor = run_floor(par, steps, seed)
        ratios.append((env_sps.wall, env_sps.wall / public.wall, env_sps.wall / floor.wall))
        print(f"| {seed} | {env_sps.wall:,.0f} | {public.wall:,.0f} | {ratios[-1][1]:.2f} | "
              f"{floor.wall:,.0f} | {ratios[-1][2]:.2f} |")
    env_med, pub_med, floor_med = (float(np.median(col)) for col in zip(*ratios, strict=True))
    print(f"| **median** | {env_med:,.0f} | | **{pub_med:.2f}** | | {floor_med:.2f} |")


COPY_SETTINGS = {
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


def copy_table(copies: list[int], repeats: int) -> None:
    """The copy table (module docstring, Copies)."""
    _episode({}, 300)  # compiled kernels (those of the grid merges too) load outside the timings
    print("| setting | steps since reset | stepping ms | dumps ms | loads ms (replay) "
          "| deepcopy ms | loads ms / 1000 steps | loads / stepping | pickle bytes |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, kwargs in COPY_SETTINGS.items():
        for steps in copies:
            env, cpu, wall = _episode(kwargs, steps)
            data = pickle.dumps(env)
            dumps = _medians(lambda env=env: pickle.dumps(env), repeats)
            loads = _medians(lambda data=data: pickle.loads(data), repeats)
            deep = _medians(lambda env=env: copy.deepcopy(env), repeats)
            print(f"| {name} | {steps} | {cpu * 1e3:.0f} ({wall * 1e3:.0f}) "
                  f"| {dumps[0] * 1e3:.2f} ({dumps[1] * 1e3:.2f}) "
                  f"| {loads[0] * 1e3:.0f} ({loads[1] * 1e3:.0f}) "
                  f"| {deep[0] * 1e3:.0f} ({deep[1] * 1e3:.0f}) "
                  f"| {loads[0] * 1e6 / steps:.0f} | {loads[0] / cpu:.2f} | {len(data):,} |",
                  flush=True)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000, help="steps per measurement")
    parser.add_argument("--soak", type=int, default=0, help="steps of the memory soak (0: skip)")
    parser.add_argument("--copies", type=int, nargs="*", default=None, metavar="STEPS",
                        help="only the copy table, at these steps since reset "
                             "(default 250 1000 3000)")
    parser.add_argument("--repeats", type=int, default=3, help="restores per copy measurement")
    args = parser.parse_args(argv)
    if args.copies is not None:
        copy_table(args.copies or [250, 1000, 3000], args.repeats)
        return
    print(f"# two_robot_explore_v0 speed ({platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}, single process)\n")

    cfg = MappingConfig()
    print(f"## Defaults (20x20 m procedural, sonar + grid every step, topo every "
          f"{cfg.topo_every}, merge every {cfg.merge_every})")
    run_env(200)  # warm-up (imports, first merge)
    env_sps, par = run_env(args.steps)
    floor = run_floor(par, args.steps)
    public = run_floor(par, args.steps, public=True)
    casts = par.sonars[0].ray_angles.size * 2
    print("| what | steps/s | to the pymunk-API floor (the target's) | to the floor casting "
          "as the env | CPU steps/s | CPU ratio (pymunk-API) |\n|---|---|---|---|---|---|")
    rows = [(f"raw floor: pymunk substeps + {casts} casts through `segment_query_first`", public),
            (f"raw floor: pymunk substeps + {casts} casts as the env (`Sonar._cast`)", floor),
            ("env, defaults", env_sps)]
    for label, kw in (("env, no topo/merge", {"mapping": {"topo_every": 0, "merge_every": 0}}),
                      ("env, no merge", {"mapping": {"merge_every": 0}})):
        rows.append((label, run_env(args.steps, **kw)[0]))
    for label, sps in rows:
        print(f"| {label} | {sps.wall:,.0f} | {sps.wall / public.wall:.2f} | "
              f"{sps.wall / floor.wall:.2f} | {sps.cpu:,.0f} | {sps.cpu / public.cpu:.2f} |")

    seeds_table(args.steps)

    print("\n## Per-stage breakdown (defaults)")
    stages, whole = breakdown(args.steps)
    print("| stage | µs/step | share |\n|---|---|---|")
    for name, sec in sorted(stages.items(), key=lambda kv: -kv[1]):
        print(f"| {name} | {sec / args.steps * 1e6:,.0f} | {sec / whole:.0%} |")
    rest = whole - sum(stages.values())
    print(f"| rest (step glue) | {rest / args.steps * 1e6:,.0f} | {rest / whole:.0%} |")
    print(f"| **whole step** | {whole / args.steps * 1e6:,.0f} | 100% |")

    print("\n## World size")
    print("| world | env steps/s | pymunk-API floor | ratio | CPU ratio | floor casting as the env "
          "| ratio | wall segments |\n|---|---|---|---|---|---|---|---|")
    for side in (20.0, 40.0, 80.0):
        sps, p = run_env(args.steps // 2, world={"size": (side, side)})
        pub = run_floor(p, args.steps // 2, public=True)
        fl = run_floor(p, args.steps // 2)
        print(f"| {side:.0f}x{side:.0f} m | {sps.wall:,.0f} | {pub.wall:,.0f} | "
              f"{sps.wall / pub.wall:.2f} | {sps.cpu / pub.cpu:.2f} | {fl.wall:,.0f} | "
              f"{sps.wall / fl.wall:.2f} | {len(p.world.segments)} |")
    print(f"\npeak RSS so far: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:,.1f} "
          f"MiB")
    if args.soak:
        soak(args.soak)


if __name__ == "__main__":
    main()
