"""Generate map-pair datasets by running explorers in the env (local processes or Ray).

    python -m agents.dataset generate --explorer frontier --pairs 60 --out data/pairs \\
        [--world procedural|PATH] [--snapshots 3] [--workers 2] [--backend process|ray] \\
        [--address ADDR] [--seed 0] [--robots 2] [--odometry perfect|pioneer3dx|SIGMA]
    python -m agents.dataset info data/pairs

Each **episode** ``e`` of a run is seeded from ``(seed, e)`` alone and yields ``snapshots``
snapshots of a team of ``robots`` robots (``two_robot_explore_v0`` for 2, the default, else
``multi_robot_explore_v0``); each snapshot gives one pair per two robots ``i < j``, ``P = N (N −
1) / 2`` of them, in the order (0, 1), (0, 2), ..., (1, 2), ...: pair ids ``(e · snapshots + k)
· P + p`` (``e · snapshots + k`` with two robots). A pair's map A is robot ``i``'s, map B robot
``j``'s, its transform the true one from ``j``'s frame into ``i``'s (the env's
``true_transform(i, j)``; ``true_merge`` for (0, 1)), its overlap the share of the smaller of
the two robots' true sweeps that the other also swept, and ``extra["robots"]`` is ``[i, j]``
(pairs written before this key existed are (0, 1)). With drifting odometry (``--odometry``)
the pair's transform is still the start-frame truth, and ``extra`` also holds the truth at the
robots' current places (:func:`current_truth`) and both robots' trajectories so far, as mapped
and as driven (``trajectory_a``, ``trajectory_b``: :func:`trajectory_row` from the start, every
:data:`TRAJECTORY_EVERY` steps and at each snapshot; ``fusion.evaluation`` judges a merge by the
ATE of the fused map it makes). Snapshot ``k`` is taken the first time the true coverage reaches
``coverage_levels[k]`` (spread over 15–85 % so that overlaps vary) or, for an explorer too slow
to get there, at step ``(k + 1) / snapshots · max_cycles``, whichever comes first (so the
snapshots of an episode are taken at distinct moments); an episode that terminates early gives
its remaining snapshots at its last step. Episodes are independent tasks, so the pairs are the
same whatever the number of workers or the backend, and an interrupted run resumes with the
same command: episodes whose pairs all exist are skipped, the others are re-run and rewrite
exactly the same pairs. The format is :mod:`fusion.evaluation.pairs`; ``fusion.evaluation.evaluate
DIR`` reads it.

Ray: ``--backend ray`` runs one task per episode on ``ray.init()`` (a local cluster with
``--workers`` CPUs) or on an existing cluster (``--address``); tasks write their pair files into
the output folder, which must then be on storage that every node shares. Workers of either
backend run with one BLAS/OpenMP thread (one episode per CPU). Starting and stopping a local
Ray cluster takes seconds, so on jobs of a few pairs the process backend is faster; on long jobs
the two are alike (``benchmarks/explorers.py --only dataset`` compares them).

Safety: every setting is checked before anything is written (the env is built once and an ``sb3:``
model loaded once, so a bad ``--world-size``, map file or model is refused up front). One writer at
a time: a run holds the lock file ``OUT/.lock`` (the kernel's ``flock``, released when the run
exits, even killed) and a second run on the same ``--out`` stops at once, naming the holder's pid.
Worker processes die with the run that started them and write only while it holds the lock
(:mod:`agents.workers`): a killed run leaves no worker behind. A new dataset whose run fails before
its first pair is written is removed again (``dataset.json`` and the folders the run created), so
the corrected command starts afresh; a run that wrote pairs leaves them, and the same command
resumes. Bad settings, an ``--out`` that is a file or a foreign folder, a dataset made with other
settings and a held lock are one-line errors naming the flag (exit status 2). ``dataset.json``
records how many pairs the dataset holds (the largest ``--pairs`` run on it): a pair file beyond
that count is a stray, refused by name rather than counted. A full disk stops the run with one line
naming the folder (exit status 1): the pairs written are whole, and the same command resumes.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import math
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import tyro
from tqdm.auto import tqdm

from agents.base import run_episode
from agents.cli import one_line_errors
from agents.workers import WORKER_ENV, Owner, check_owner, owner, pool_results, set_owner
from fusion.evaluation.pairs import (
    FORMAT,
    FORMAT_VERSION,
    LOCK_FILE,
    DatasetError,
    GridSnapshot,
    MapPair,
    load_pairs,
    pair_count,
    pair_files,
    read_manifest,
    write_index,
    write_pair,
)
from fusion.rigid import Rigid2D
from topo.fileio import TEMP_PREFIX, LockHeld, atomic_write_json, exclusive_lock
from topo.validation import check_int

BACKENDS = ("process", "ray")


class SettingsError(ValueError):
    """A bad :class:`GenerateArgs` setting, or an ``out`` folder this run cannot write.

    Attributes:
        field: the :class:`GenerateArgs` field at fault (its CLI flag is :attr:`flag`).
    """

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field = field

    @property
    def flag(self) -> str:
        """The command-line flag of :attr:`field` (``world_size`` → ``--world-size``)."""
        return "--" + self.field.replace("_", "-")


@contextlib.contextmanager
def _setting(field: str) -> Iterator[None]:
    """Re-raise a ``ValueError`` of the block as a :class:`SettingsError` of ``field``."""
    try:
        yield
    except SettingsError:
        raise
    except ValueError as exc:
        raise SettingsError(field, str(exc)) from exc


@dataclass(frozen=True)
class GenerateArgs:
    """Generate a map-pair dataset (see ``python -m agents.dataset --help``)."""

    out: Path
    """Output folder (created; an existing dataset with the same settings is resumed)."""
    pairs: int = 60
    """Number of pairs to store."""
    explorer: str = "frontier"
    """Explorer driving every robot: random_walk, wall_follower, frontier,
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
    robots: int = 2
    """Robots in the team (2–8): every two of them make a pair of each snapshot."""
    odometry: str = "perfect"
    """The robots' odometry: 'perfect', 'pioneer3dx' (the Pioneer 3-DX preset of the
    'rot_trans_rot' model) or a relative noise level such as '0.02' (the 'increment' model at
    (0.02, 0.02)). With drift, maps bend and each pair also holds the truth at the robots'
    current places."""
    progress: bool = True
    """Show a progress bar."""

    def __post_init__(self) -> None:
        """Check every setting; a bad one is a :class:`SettingsError` (a ``ValueError``)
        naming it."""
        from envs.explore.config import EnvConfig, WorldConfig

        for name, low in (("pairs", 1), ("snapshots", 1), ("workers", 1), ("seed", 0),
                          ("max_cycles", 10)):
            with _setting(name):
                check_int(getattr(self, name), name, low=low)
        with _setting("robots"):
            EnvConfig(n_robots=self.robots)  # names n_robots and the value
        with _setting("odometry"):
            odometry_kwargs(self.odometry)
        if self.backend not in BACKENDS:
            raise SettingsError("backend", f"backend must be one of {list(BACKENDS)}, got "
                                           f"{self.backend!r}")
        if self.address is not None and self.backend != "ray":
            raise SettingsError("address", f"address is only used with backend='ray', got "
                                           f"backend={self.backend!r}")
        if self.world != "procedural":
            if not Path(self.world).is_file():
                raise SettingsError("world", f"world must be 'procedural' or an existing map "
                                             f"file, got {self.world!r}")
            with _setting("world"):
                WorldConfig(source=self.world)
        else:
            with _setting("world_size"):
                WorldConfig(size=self.world_size)
        if not self.explorer.startswith("sb3:"):
            from agents.registry import EXPLORERS

            if self.explorer not in EXPLORERS:
                raise SettingsError("explorer", f"explorer must be one of {sorted(EXPLORERS)} "
                                                f"or 'sb3:PATH', got {self.explorer!r}")
        elif not Path(self.explorer[4:]).is_file():
            raise SettingsError("explorer", f"explorer {self.explorer!r}: no saved model at "
                                            f"{self.explorer[4:]!r}")

    @property
    def n_episodes(self) -> int:
        return math.ceil(self.pairs / (self.snapshots * len(robot_pairs(self.robots))))

    def settings(self) -> dict[str, Any]:
        """What determines the pairs (stored in ``dataset.json``; a resume must match).
        ``robots`` only for teams of more than two and ``odometry`` only when it drifts, so
        that datasets made before they existed resume."""
        return {"explorer": self.explorer, "world": self.world, "snapshots": self.snapshots,
                "seed": self.seed, "max_cycles": self.max_cycles,
                "world_size": [float(v) for v in self.world_size],
                **({"robots": self.robots} if self.robots != 2 else {}),
                **({"odometry": self.odometry} if self.odometry != "perfect" else {})}


def robot_pairs(robots: int) -> np.ndarray:
    """``(P, 2)`` robot indices ``i < j`` of a team of ``robots``, (0, 1) first: the pairs of
    every snapshot, in pair-id order."""
    return np.argwhere(np.triu(np.ones((robots, robots), dtype=bool), k=1))


def episode_seed(seed: int, episode: int) -> int:
    """The env/explorer seed of episode ``episode`` of a run seeded ``seed``."""
    return int(np.random.SeedSequence([seed, episode]).generate_state(1)[0])


def coverage_levels(snapshots: int) -> np.ndarray:
    """True-coverage thresholds of the snapshots, evenly spread over 15–85 %."""
    return 0.15 + 0.70 * (np.arange(snapshots) + 0.5) / snapshots


def odometry_kwargs(odometry: str) -> dict[str, Any]:
    """The env's ``robot`` settings of ``--odometry`` (:class:`GenerateArgs`): ``{}`` for
    ``"perfect"``, the ``"rot_trans_rot"`` model with the ``"pioneer3dx"`` preset, or the
    ``"increment"`` model at ``(σ, σ)`` for a number ``σ``.

    Raises:
        ValueError: anything else, or a noise level the env refuses (named)."""
    from envs.explore.config import RobotConfig

    if odometry == "perfect":
        return {}
    if odometry == "pioneer3dx":
        kwargs: dict[str, Any] = {"odometry_model": "rot_trans_rot",
                                  "odometry_alphas": "pioneer3dx"}
    else:
        try:
            sigma = float(odometry)
        except (TypeError, ValueError):
            raise ValueError(f"odometry must be 'perfect', 'pioneer3dx' or a noise level such "
                             f"as '0.02', got {odometry!r}") from None
        kwargs = {"odometry_noise": (sigma, sigma)}
    RobotConfig(**kwargs)  # the env's own check of the level
    return kwargs


def env_kwargs(settings: dict[str, Any]) -> dict[str, Any]:
    """The ``parallel_env`` arguments of a run's ``settings``."""
    world: dict[str, Any] = {"source": settings["world"]}
    if settings["world"] == "procedural":
        world["size"] = tuple(settings["world_size"])
    robots = settings.get("robots", 2)
    robot = odometry_kwargs(settings.get("odometry", "perfect"))
    return {"max_cycles": settings["max_cycles"], "world": world,
            **({"n_robots": robots} if robots != 2 else {}),
            **({"robot": robot} if robot else {})}


def pair_overlap(swept_a: np.ndarray, swept_b: np.ndarray) -> float:
    """The share of the smaller of two true sweeps (world-cell masks) the other also swept:
    the env's ``overlap`` info for two robots."""
    small = min(int(np.count_nonzero(swept_a)), int(np.count_nonzero(swept_b)))
    return int(np.count_nonzero(swept_a & swept_b)) / small if small else 0.0


def _snapshot(env: Any, infos: dict, first_id: int, episode: int, k: int, seed: int,
              step: int, settings: dict[str, Any],
              trails: list[list[list[float]]] | None = None) -> list[MapPair]:
    """Every robot pair of one snapshot (module docstring), ids from ``first_id`` on;
    ``trails``: each robot's :func:`trajectory_row` so far (drifting odometry)."""
    raw = env.unwrapped
    a = infos["robot_0"]
    snaps = [raw.robot_map(agent) for agent in raw.possible_agents]

    def grid(snap: Any) -> GridSnapshot:
        g = snap.grid
        return GridSnapshot(np.asarray(g.states(), dtype=np.int8).copy(), float(g.resolution),
                            tuple(float(v) for v in g.origin))

    grids = [grid(snap) for snap in snaps]
    world = settings["world"]
    world_id = f"procedural:{seed}" if world == "procedural" else Path(world).name
    out = []
    drifts = settings.get("odometry", "perfect") != "perfect"
    for p, (i, j) in enumerate(robot_pairs(len(snaps)).tolist()):
        truth: Rigid2D = raw.true_transform(i, j)
        extra: dict[str, Any] = {"true_coverage": float(a["true_coverage"]), "robots": [i, j]}
        if drifts:
            extra.update(current_truth(raw.robots[i], raw.robots[j]))
            if trails is not None:
                extra["trajectory_a"] = [list(r) for r in trails[i]]
                extra["trajectory_b"] = [list(r) for r in trails[j]]
        out.append(MapPair(
            pair_id=first_id + p, map_a=snaps[i].topomap, map_b=snaps[j].topomap,
            grid_a=grids[i], grid_b=grids[j], transform=truth,
            overlap=pair_overlap(raw.oracle.swept[i], raw.oracle.swept[j]), world_id=world_id,
            seed=seed, explorer=settings["explorer"], step=step, episode=episode, snapshot=k,
            extra=extra,
        ))
    return out


def current_truth(robot_a: Any, robot_b: Any) -> dict[str, list]:
    """A drifting pair's truth at the robots' current places (``extra`` keys): the transform
    from B's map frame onto A's that is right where the robots are now
    (``envs.explore.drift.drift_aware_truth``, ``[theta, tx, ty]``) and the robots' current
    odometry positions (A's in A's frame, B's in B's; ``[[x, y], [x, y]]``: where the env's
    ``envs.explore.drift.drift_aware_error`` measures a merge's translation error).
    ``fusion.evaluation --truth current`` judges merges against the transform. Why: a bent
    map has no one rigid truth; the start-frame one misjudges merges that are right where the
    team is."""
    from envs.explore.drift import drift_aware_truth

    t = drift_aware_truth(robot_a, robot_b)
    return {"current_transform": [t.theta, float(t.T[0]), float(t.T[1])],
            "current_places": [[float(v) for v in robot_a.odometry[:2]],
                               [float(v) for v in robot_b.odometry[:2]]]}


TRAJECTORY_EVERY = 25
"""With drifting odometry, each robot's pose is kept every this many steps (and at each
snapshot) for its pairs' ``extra["trajectory_a"]`` / ``["trajectory_b"]``
(:func:`trajectory_row`): a 3000-step episode's trajectory is 120 rows."""


def trajectory_row(robot: Any) -> list[float]:
    """A robot's pose now, ``[x, y, θ, true x, true y, true θ]``: its odometry (the frame its
    map is drawn in) and its true pose in its start frame (where that map would be without
    drift). Why: a dataset pair's two trajectories judge a rigid merge of bent maps by the
    fused map's ATE (``fusion.evaluation.bending.PairTrajectories``)."""
    from envs.explore.robot import start_frame_pose

    truth = start_frame_pose(robot.start, robot.true_pose())
    return [float(v) for v in (*robot.odometry, *truth)]


def generate_episode(root: str, episode: int, n_pairs: int, settings: dict[str, Any]) -> int:
    """Run episode ``episode`` and write its pairs (ids ``episode · snapshots + k`` below
    ``n_pairs``) into dataset ``root``. Returns how many pairs it wrote. Top-level and
    argument-only so that process pools and Ray can ship it."""
    from agents.registry import make_team
    from envs import parallel_env_for

    snapshots = settings["snapshots"]
    per = len(robot_pairs(settings.get("robots", 2)))
    # snapshot k's pairs are ids[k], ids[k] + 1, ... (those below n_pairs are written)
    ids = [(episode * snapshots + k) * per for k in range(snapshots)]
    ids = [i for i in ids if i < n_pairs]
    seed = episode_seed(settings["seed"], episode)
    env = parallel_env_for(env_kwargs(settings))
    team = make_team(settings["explorer"], env=env)
    n_agents = len(env.possible_agents)
    levels = coverage_levels(snapshots)[: len(ids)]
    deadlines = [math.ceil((k + 1) / snapshots * settings["max_cycles"]) for k in range(len(ids))]
    taken: list[list[MapPair]] = []
    state = {"infos": None, "step": 0}
    drifts = settings.get("odometry", "perfect") != "perfect"
    # every robot starts at the origin of its map frame and of its start frame
    trails: list[list[list[float]]] = [[[0.0] * 6] for _ in range(n_agents)]
    sampled = [0]  # the last step the trails were sampled at

    def sample(step: int) -> None:  # each robot's pose now, as mapped and as it truly is
        if drifts and sampled[0] != step:
            sampled[0] = step
            for trail, robot in zip(trails, env.unwrapped.robots, strict=True):
                trail.append(trajectory_row(robot))

    def callback(step: int, _obs: dict, _rew: dict, infos: dict) -> None:
        if len(infos) < n_agents:
            return
        state["infos"], state["step"] = infos, step
        if step % TRAJECTORY_EVERY == 0:
            sample(step)
        cov = float(infos["robot_0"]["true_coverage"])
        while len(taken) < len(ids) and (cov >= levels[len(taken)]
                                         or step >= deadlines[len(taken)]):
            k = len(taken)
            sample(step)
            taken.append(_snapshot(env, infos, ids[k], episode, k, seed, step, settings,
                                   trails))

    try:
        run_episode(env, team, seed=seed, callback=callback)
        while len(taken) < len(ids) and state["infos"] is not None:
            k = len(taken)
            sample(state["step"])
            taken.append(_snapshot(env, state["infos"], ids[k], episode, k, seed,
                                   state["step"], settings, trails))
    finally:
        env.close()
    pairs = [pair for snapshot in taken for pair in snapshot if pair.pair_id < n_pairs]
    for pair in pairs:
        check_owner()
        write_pair(root, pair)
    return len(pairs)


def _ray_episode(run: Owner, root: str, episode: int, n_pairs: int,
                 settings: dict[str, Any]) -> int:
    """:func:`generate_episode` in a Ray worker, writing only while ``run`` holds the lock
    (a task that outlives a killed driver writes nothing)."""
    set_owner(run)
    return generate_episode(root, episode, n_pairs, settings)


Runner = Callable[[list[int]], Iterator[int]]


def _process_runner(args: GenerateArgs, root: str, settings: dict) -> Runner:
    def run(episodes: list[int]) -> Iterator[int]:
        calls = [(root, e, args.pairs, settings) for e in episodes]
        if args.workers == 1:
            return (generate_episode(*call) for call in calls)
        return pool_results(generate_episode, calls, args.workers, Path(root) / LOCK_FILE)
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
                      "runtime_env": {"env_vars": dict(WORKER_ENV)}}
            if args.address is None:
                ray.init(num_cpus=args.workers, include_dashboard=False, **common)
            else:
                ray.init(address=args.address, **common)
        try:
            task = ray.remote(num_cpus=1)(_ray_episode)
            run = owner(Path(root) / LOCK_FILE)
            pending = [task.remote(run, root, e, args.pairs, settings) for e in episodes]
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                yield ray.get(done[0])
        finally:
            if started_here:
                ray.shutdown()
    return run


def _preflight(args: GenerateArgs) -> None:
    """Build once what every episode builds — the env (a map file is loaded and checked) and
    an ``sb3:`` explorer's model — so that a bad setting stops the run before it writes."""
    from envs import parallel_env_for

    with _setting("world"):
        env = parallel_env_for(env_kwargs(args.settings()))
        env.close()
    if args.explorer.startswith("sb3:"):
        from agents.registry import make_team

        try:
            make_team(args.explorer, env=env)
        except Exception as exc:  # whatever SB3/torch raise on a file that is not a model
            raise SettingsError("explorer", f"explorer {args.explorer!r}: cannot load the "
                                            f"model ({type(exc).__name__}: {exc})") from exc


def _cli_value(value: Any) -> str:
    """A setting as it is typed on the command line (lists space-separated)."""
    return " ".join(map(str, value)) if isinstance(value, list) else str(value)


def _open_manifest(root: Path, settings: dict[str, Any], pairs: int) -> bool:
    """Check ``root/dataset.json`` against ``settings`` and its pair files against its pair
    count (a stray is an error), raising that count to ``pairs``; or write it in a folder
    that holds nothing else. Returns whether it was written now. Called under the lock."""
    path = root / "dataset.json"
    if path.exists():
        manifest = read_manifest(root)
        stored = manifest.get("settings") or {}
        if stored != settings:
            diff = "; ".join(
                f"--{k.replace('_', '-')} {_cli_value(stored.get(k, '(unset)'))} (this run: "
                f"{_cli_value(settings.get(k, '(unset)'))})"
                for k in sorted(set(stored) | set(settings)) if stored.get(k) != settings.get(k))
            raise SettingsError("out", f"{root} holds a dataset made with other settings: "
                                       f"{diff}; run with its settings to resume it, or give "
                                       f"another --out for a new dataset")
        count = pair_count(manifest)
        found = pair_files(root, count=count)  # before the count grows: strays are refused
        grown = max(pairs, max(found, default=-1) + 1 if count is None else count)
        if grown != count:
            atomic_write_json(path, {**manifest, "pairs": grown})
        return False
    others = sorted(p.name for p in root.iterdir()
                    if p.name != LOCK_FILE and not p.name.startswith(TEMP_PREFIX))
    if others:
        raise SettingsError("out", f"{root} is a folder that is not a map-pair dataset (no "
                                   f"dataset.json; it holds {others[:3]}"
                                   f"{'...' if len(others) > 3 else ''}): give a new or empty "
                                   f"folder")
    atomic_write_json(path, {"format": FORMAT, "version": FORMAT_VERSION, "settings": settings,
                             "pairs": pairs})
    return True


def _forget_empty_dataset(root: Path) -> None:
    """After a failed run that started dataset ``root``: if no pair was written, remove
    ``dataset.json`` and ``pairs/`` so that the folder is as it was."""
    try:
        if pair_files(root, clean_temp=True):
            return  # pairs were written: the same command resumes
    except DatasetError:
        return
    (root / "dataset.json").unlink(missing_ok=True)
    with contextlib.suppress(OSError):
        (root / "pairs").rmdir()


@contextlib.contextmanager
def _dataset_lock(root: Path) -> Iterator[None]:
    try:
        with exclusive_lock(root / LOCK_FILE):
            yield
    except LockHeld as exc:
        h = exc.holder
        who = (f"pid {h.get('pid')} on {h.get('host')}, since {h.get('since')}" if h
               else "a process starting just now")
        raise SettingsError("out", f"{root} is being written by another run ({who}): wait for "
                                   f"it to end or stop it; its lock {exc.path} goes with that "
                                   f"process (delete the file only if no such process runs)"
                            ) from exc


def generate(args: GenerateArgs) -> dict[str, Any]:
    """Generate (or resume) the dataset described by ``args``; returns a summary with the
    pairs written now, the pairs already there, the time and pairs/s.

    Raises:
        SettingsError: a setting the env or the explorer refuses; ``out`` is a file, a folder
            that is not a dataset, a dataset made with other settings, or being written by
            another run (its lock is held).
        fusion.evaluation.pairs.DatasetError: a corrupt ``dataset.json``, a foreign or stray file
            in ``pairs/``.
    """
    root = Path(args.out)
    settings = args.settings()
    if root.exists() and not root.is_dir():
        raise SettingsError("out", f"{root} is a file, not a folder: give a new folder, or a "
                                   f"dataset folder to resume")
    _preflight(args)
    made = [p for p in (root, *root.parents) if not p.exists()]  # deepest first
    with _setting("out"):
        try:
            root.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ValueError(f"cannot create {root}: {exc.strerror}") from exc
    try:
        with _dataset_lock(root):
            fresh = _open_manifest(root, settings, args.pairs)
            try:
                return _run(args, root, settings)
            except BaseException:
                if fresh:
                    _forget_empty_dataset(root)
                raise
    finally:
        for folder in made:  # the folders this run created, if it left them empty
            try:
                folder.rmdir()
            except OSError:
                break


def _run(args: GenerateArgs, root: Path, settings: dict[str, Any]) -> dict[str, Any]:
    existing = pair_files(root, clean_temp=True, count=pair_count(read_manifest(root)))
    per_episode = args.snapshots * len(robot_pairs(args.robots))
    todo = [e for e in range(args.n_episodes)
            if any(i not in existing and i < args.pairs
                   for i in range(e * per_episode, (e + 1) * per_episode))]
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
            "robot pairs (i, j): " + ", ".join(
                f"({i}, {j}) {n}" for (i, j), n in sorted(Counter(
                    tuple(p.extra.get("robots", (0, 1))) for p in pairs).items())),
        ]
    return "\n".join(lines)


@dataclass(frozen=True)
class InfoArgs:
    """Print a summary of a map-pair dataset."""

    root: Annotated[Path, tyro.conf.Positional]
    """Dataset folder."""


@dataclass(frozen=True)
class _GenerateFlags(GenerateArgs):
    __doc__ = GenerateArgs.__doc__

    def __post_init__(self) -> None:
        """Nothing: :func:`main` builds the checked :class:`GenerateArgs` itself, so that a bad
        setting is its one-line error rather than tyro's box."""


PROG = "python -m agents.dataset"


def _fail(command: str, message: str, status: int = 2) -> None:
    print(f"{PROG} {command}: error: {' '.join(message.split())}", file=sys.stderr)
    raise SystemExit(status)


def main(argv: list[str] | None = None) -> None:
    """CLI entry point: ``generate`` or ``info`` (tyro subcommands).

    A bad setting, an unusable ``--out`` (a file, a foreign folder, a dataset made with other
    settings, another run's lock) or an unreadable dataset prints one line naming the flag on
    stderr and exits with status 2 (``SystemExit(2)``); a full disk one line naming the folder,
    status 1. tyro's own errors (an unknown flag, a value of the wrong type) are one line
    too."""
    argv = sys.argv[1:] if argv is None else list(argv)
    commands = {"generate": _GenerateFlags, "info": InfoArgs}
    cmd = one_line_errors(lambda: tyro.extras.subcommand_cli_from_dict(
        commands, args=argv, prog=PROG), " ".join([PROG, *argv[:1]] if argv[:1] and argv[0]
                                                  in commands else [PROG]))
    if isinstance(cmd, InfoArgs):
        try:
            print(info(cmd.root))
        except DatasetError as exc:
            _fail("info", f"ROOT: {exc}")
        return
    try:
        summary = generate(GenerateArgs(**{f.name: getattr(cmd, f.name)
                                           for f in dataclasses.fields(GenerateArgs)}))
    except SettingsError as exc:
        _fail("generate", f"{exc.flag}: {exc}")
    except DatasetError as exc:
        _fail("generate", f"--out: {exc}")
    except OSError as exc:
        if exc.errno not in (errno.ENOSPC, errno.EDQUOT):
            raise
        _fail("generate", f"{cmd.out}: no space left ({exc.strerror}) writing "
                          f"{exc.filename or 'a pair'}: the pairs written are whole; free space "
                          f"and rerun the same command to resume", status=1)
    print(f"wrote {summary['written']} pairs ({summary['already_there']} already there) in "
          f"{summary['seconds']:.1f} s: {summary['pairs_per_s'] * 60:.1f} pairs/min")


if __name__ == "__main__":
    main()

