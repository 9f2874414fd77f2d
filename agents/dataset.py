"""Generate map-pair datasets by running explorers in the env (local processes or Ray).

    python -m agents.dataset generate --explorer frontier --pairs 60 --out data/pairs \\
        [--world procedural|PATH] [--snapshots 3] [--workers 2] [--backend process|ray] \\
        [--address ADDR] [--seed 0]
    python -m agents.dataset info data/pairs

Each **episode** ``e`` of a run is seeded from ``(seed, e)`` alone and yields ``snapshots`` pairs
(ids ``e · snapshots + k``): snapshot ``k`` is taken the first time the true coverage reaches
``coverage_levels[k]`` (spread over 15–85 % so that overlaps vary) or, for an explorer too slow
to get there, at step ``(k + 1) / snapshots · max_cycles``, whichever comes first (so the
snapshots of an episode are taken at distinct moments); an episode that terminates early gives
its remaining snapshots at its last step. Episodes are independent tasks, so the pairs are the
same whatever the number of workers or the backend, and an interrupted run resumes with the
same command: episodes whose pairs all exist are skipped, the others are re-run and rewrite
exactly the same pairs. The format is :mod:`fusion.pairs`; ``fusion.evaluate DIR`` reads it.

Ray: ``--backend ray`` runs one task per episode on ``ray.init()`` (a local cluster with
``--workers`` CPUs) or on an existing cluster (``--address``); tasks write their pair files into
the output folder, which must then be on storage that every node shares. Workers of either
backend run with one BLAS/OpenMP thread (one episode per CPU). Starting and stopping a local
Ray cluster takes about 6 s on a 2-core machine, so on jobs of a few pairs the process backend
is faster; on jobs of a minute or more the two are alike (``benchmarks/explorers.py --only
dataset`` compares them).
"""

from __future__ import annotations

import contextlib
import math
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import tyro
from tqdm.auto import tqdm

from agents.base import run_episode
from fusion.pairs import (
    FORMAT,
    FORMAT_VERSION,
    DatasetError,
    GridSnapshot,
    MapPair,
    atomic_write_json,
    load_pairs,
    pair_files,
    read_manifest,
    write_index,
    write_pair,
)
from fusion.rigid import Rigid2D
from topo._checks import check_int

BACKENDS = ("process", "ray")
_WORKER_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
"""Environment of worker processes (either backend): one BLAS/OpenMP thread per episode."""


@dataclass(frozen=True)
class GenerateArgs:
    """Generate a map-pair dataset (see ``python -m agents.dataset --help``)."""

    out: Path
    """Output folder (created; an existing dataset with the same settings is resumed)."""
    pairs: int = 60
    """Number of pairs to store."""
    explorer: str = "frontier"
    """Explorer driving both robots: random_walk, wall_follower, frontier,
    coordinated_frontier, or sb3:PATH (a saved PPO model)."""
    world: str = "procedural"
    """'procedural' (a new seeded building per episode) or a map file (ROS .yaml, DungeonMaps
    .png, HouseExpo .json)."""
    world_size: tuple[float, float] = (20.0, 20.0)
    """Procedural building size in metres (ignored for map files)."""
    snapshots: int = 3
    """Pairs per episode, taken at increasing coverage."""
    workers: int = 1
    """Parallel episodes (processes, or Ray CPUs for a local Ray cluster)."""
    backend: Literal["process", "ray"] = "process"
    """Where episodes run."""
    address: str | None = None
    """Ray cluster address to join (default: start a local one)."""
    seed: int = 0
    """Seed of the whole run (episode e uses a seed derived from (seed, e))."""
    max_cycles: int = 600
    """Env steps per episode at most."""
    progress: bool = True
    """Show a progress bar."""

    def __post_init__(self) -> None:
        check_int(self.pairs, "pairs", low=1)
        check_int(self.snapshots, "snapshots", low=1)
        check_int(self.workers, "workers", low=1)
        check_int(self.seed, "seed", low=0)
        check_int(self.max_cycles, "max_cycles", low=10)
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {list(BACKENDS)}, got {self.backend!r}")
        if self.address is not None and self.backend != "ray":
            raise ValueError(f"address is only used with backend='ray', got backend="
                             f"{self.backend!r}")
        if self.world != "procedural" and not Path(self.world).is_file():
            raise ValueError(f"world must be 'procedural' or an existing map file, got "
                             f"{self.world!r}")
        if not self.explorer.startswith("sb3:"):
            from agents.scripted import EXPLORERS

            if self.explorer not in EXPLORERS:
                raise ValueError(f"explorer must be one of {sorted(EXPLORERS)} or 'sb3:PATH', "
                                 f"got {self.explorer!r}")
        elif not Path(self.explorer[4:]).is_file():
            raise ValueError(f"explorer {self.explorer!r}: no saved model at "
                             f"{self.explorer[4:]!r}")

    @property
    def n_episodes(self) -> int:
        return math.ceil(self.pairs / self.snapshots)

    def settings(self) -> dict[str, Any]:
        """What determines the pairs (stored in ``dataset.json``; a resume must match)."""
        return {"explorer": self.explorer, "world": self.world, "snapshots": self.snapshots,
                "seed": self.seed, "max_cycles": self.max_cycles,
                "world_size": [float(v) for v in self.world_size]}


def episode_seed(seed: int, episode: int) -> int:
    """The env/explorer seed of episode ``episode`` of a run seeded ``seed``."""
    return int(np.random.SeedSequence([seed, episode]).generate_state(1)[0])


def coverage_levels(snapshots: int) -> np.ndarray:
    """True-coverage thresholds of the snapshots, evenly spread over 15–85 %."""
    return 0.15 + 0.70 * (np.arange(snapshots) + 0.5) / snapshots


def _snapshot(env: Any, infos: dict, pair_id: int, episode: int, k: int, seed: int,
              step: int, settings: dict[str, Any]) -> MapPair:
    raw = env.unwrapped
    a = infos["robot_0"]
    snap_a, snap_b = raw.robot_map("robot_0"), raw.robot_map("robot_1")

    def grid(snap: Any) -> GridSnapshot:
        g = snap.grid
        return GridSnapshot(np.asarray(g.states(), dtype=np.int8).copy(), float(g.resolution),
                            tuple(float(v) for v in g.origin))

    world = settings["world"]
    world_id = f"procedural:{seed}" if world == "procedural" else Path(world).name
    truth: Rigid2D = raw.true_merge
    return MapPair(
        pair_id=pair_id, map_a=snap_a.topomap, map_b=snap_b.topomap, grid_a=grid(snap_a),
        grid_b=grid(snap_b), transform=truth, overlap=float(a["overlap"]), world_id=world_id,
        seed=seed, explorer=settings["explorer"], step=step, episode=episode, snapshot=k,
        extra={"true_coverage": float(a["true_coverage"])},
    )


def generate_episode(root: str, episode: int, n_pairs: int, settings: dict[str, Any]) -> int:
    """Run episode ``episode`` and write its pairs (ids ``episode · snapshots + k`` below
    ``n_pairs``) into dataset ``root``. Returns how many pairs it wrote. Top-level and
    argument-only so that process pools and Ray can ship it."""
    from agents.scripted import make_team
    from envs.two_robot_explore_v0 import parallel_env

    snapshots = settings["snapshots"]
    ids = [episode * snapshots + k for k in range(snapshots)]
    ids = [i for i in ids if i < n_pairs]
    seed = episode_seed(settings["seed"], episode)
    world: dict[str, Any] = {"source": settings["world"]}
    if settings["world"] == "procedural":
        world["size"] = tuple(settings["world_size"])
    env = parallel_env(max_cycles=settings["max_cycles"], world=world)
    team = make_team(settings["explorer"])
    levels = coverage_levels(snapshots)[: len(ids)]
    deadlines = [math.ceil((k + 1) / snapshots * settings["max_cycles"]) for k in range(len(ids))]
    taken: list[MapPair] = []
    state = {"infos": None, "step": 0}

    def callback(step: int, _obs: dict, _rew: dict, infos: dict) -> None:
        if len(infos) < 2:
            return
        state["infos"], state["step"] = infos, step
        cov = float(infos["robot_0"]["true_coverage"])
        while len(taken) < len(ids) and (cov >= levels[len(taken)]
                                         or step >= deadlines[len(taken)]):
            k = len(taken)
            taken.append(_snapshot(env, infos, ids[k], episode, k, seed, step, settings))

    try:
        run_episode(env, team, seed=seed, callback=callback)
        while len(taken) < len(ids) and state["infos"] is not None:
            k = len(taken)
            taken.append(_snapshot(env, state["infos"], ids[k], episode, k, seed,
                                   state["step"], settings))
    finally:
        env.close()
    for pair in taken:
        write_pair(root, pair)
    return len(taken)


Runner = Callable[[list[int]], Iterator[int]]


@contextlib.contextmanager
def _worker_env() -> Iterator[None]:
    """Set :data:`_WORKER_ENV` while worker processes start (they inherit it), then restore."""
    saved = {k: os.environ.get(k) for k in _WORKER_ENV}
    os.environ.update(_WORKER_ENV)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _process_runner(args: GenerateArgs, root: str, settings: dict) -> Runner:
    def run(episodes: list[int]) -> Iterator[int]:
        if args.workers == 1:
            for e in episodes:
                yield generate_episode(root, e, args.pairs, settings)
            return
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = mp.get_context("forkserver" if "forkserver" in mp.get_all_start_methods()
                             else "spawn")
        with _worker_env(), ProcessPoolExecutor(max_workers=args.workers,
                                                 mp_context=ctx) as pool:
            futures = [pool.submit(generate_episode, root, e, args.pairs, settings)
                       for e in episodes]
            for fut in as_completed(futures):
                yield fut.result()
    return run


def _ray_runner(args: GenerateArgs, root: str, settings: dict) -> Runner:
    try:
        import ray
    except ImportError as exc:
        raise ImportError("the ray backend needs the `ray` extra: "
                          "pip install -e '.[ray]'") from exc

    def run(episodes: list[int]) -> Iterator[int]:
        started_here = not ray.is_initialized()
        if started_here:
            # one thread per task, as the process backend's workers on a CPU each
            common = {"log_to_driver": False, "configure_logging": False,
                      "runtime_env": {"env_vars": dict(_WORKER_ENV)}}
            if args.address is None:
                ray.init(num_cpus=args.workers, include_dashboard=False, **common)
            else:
                ray.init(address=args.address, **common)
        try:
            task = ray.remote(num_cpus=1)(generate_episode)
            pending = [task.remote(root, e, args.pairs, settings) for e in episodes]
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                yield ray.get(done[0])
        finally:
            if started_here:
                ray.shutdown()
    return run


def generate(args: GenerateArgs) -> dict[str, Any]:
    """Generate (or resume) the dataset described by ``args``; returns a summary with the
    pairs written now, the pairs already there, the time and pairs/s."""
    root = Path(args.out)
    settings = args.settings()
    manifest_path = root / "dataset.json"
    if manifest_path.exists():
        manifest = read_manifest(root)
        if manifest.get("settings") != settings:
            raise DatasetError(
                f"{manifest_path}: was generated with settings {manifest.get('settings')}, "
                f"not {settings}; use another --out to start a new dataset")
    else:
        root.mkdir(parents=True, exist_ok=True)
        atomic_write_json(manifest_path, {"format": FORMAT, "version": FORMAT_VERSION,
                                          "settings": settings})
    existing = pair_files(root, clean_temp=True)
    todo = [e for e in range(args.n_episodes)
            if any(i not in existing and i < args.pairs
                   for i in range(e * args.snapshots, (e + 1) * args.snapshots))]
    before = sum(1 for i in existing if i < args.pairs)
    runner = (_ray_runner if args.backend == "ray" else _process_runner)(args, str(root),
                                                                        settings)
    t0 = time.perf_counter()
    written = 0
    with tqdm(total=args.pairs, initial=before, unit="pair", disable=not args.progress,
              desc=f"pairs -> {root}") as bar:
        for n in runner(todo):
            written += n
            bar.update(n)
    elapsed = time.perf_counter() - t0
    write_index(root)
    return {"written": written, "already_there": before, "seconds": elapsed,
            "pairs_per_s": written / elapsed if elapsed > 0 else math.inf}


def info(root: Path) -> str:
    """A printable summary of dataset ``root``."""
    manifest = read_manifest(root)
    pairs = load_pairs(root)
    lines = [f"{root}: {len(pairs)} pairs ({FORMAT} v{FORMAT_VERSION})",
             f"settings: {manifest.get('settings')}"]
    if pairs:
        overlap = np.array([p.overlap for p in pairs])
        nodes = np.array([[p.map_a.n_nodes, p.map_b.n_nodes] for p in pairs])
        lines += [
            f"worlds: {len({p.world_id for p in pairs})}, episodes: "
            f"{len({p.episode for p in pairs})}, explorers: "
            f"{sorted({p.explorer for p in pairs})}",
            f"overlap: min {overlap.min():.2f}, median {np.median(overlap):.2f}, "
            f"max {overlap.max():.2f}",
            f"nodes per map: median {np.median(nodes):.0f}, range {nodes.min()}–{nodes.max()}",
        ]
    return "\n".join(lines)


@dataclass(frozen=True)
class InfoArgs:
    """Print a summary of a map-pair dataset."""

    root: Annotated[Path, tyro.conf.Positional]
    """Dataset folder."""


def main(argv: list[str] | None = None) -> None:
    """CLI entry point: ``generate`` or ``info`` (tyro subcommands)."""
    cmd = tyro.extras.subcommand_cli_from_dict(
        {"generate": GenerateArgs, "info": InfoArgs}, args=argv)
    if isinstance(cmd, InfoArgs):
        print(info(cmd.root))
        return
    summary = generate(cmd)
    print(f"wrote {summary['written']} pairs ({summary['already_there']} already there) in "
          f"{summary['seconds']:.1f} s: {summary['pairs_per_s'] * 60:.1f} pairs/min")


if __name__ == "__main__":
    main()

