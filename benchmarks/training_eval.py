"""Evaluate trained exploration policies on held-out worlds and print the table and plot of
``benchmarks/RESULTS.md`` (Training): the T85 ratio to ``Frontier`` as an interquartile mean
with a 95 % bootstrap interval, T50/T95 ratios, final coverage, against the scripted explorers
and the goal-level rules.

Usage::

    python benchmarks/training_eval.py runs/goal_s1 runs/goal_s2 ... --worlds 20 \\
        --out out/training_eval

**Worlds.** ``--worlds`` procedural buildings whose sizes (each side 10–20 m) and seeds come
from a fixed ``SeedSequence`` no training run uses (training envs are seeded ``seed + k``,
``train.py``'s periodic evaluation from ``SeedSequence([seed, 0xE7A1])``), plus the real maps
of ``../shared/maps`` (3 ROS maps and DungeonMaps 1; ``--skip-real`` leaves them out). An
episode lasts 150 steps per metre of the longer side (1500–3000) on procedural worlds, 2000 on
real ones; a T never reached counts as that length + 1 (censored).

**Explorers.** Each run (a ``train.py`` folder with ``model.zip`` or ``rllib/``; ``--best``: the
best policy its periodic evaluations saw, ``best_model.zip`` or ``rllib_best/``, chosen on the
run's own evaluation worlds, never these) with the
deterministic policy (``--sample``: sampling its actions, seeded per episode; a discrete
motion-level policy's most likely command can loop) on its own env config (world replaced),
and once per world ``Frontier``,
``RandomWalk`` and the goal-level rules of :class:`agents.goals.SectorRule` (``--rules``; by
default ``ahead``: always the frontier in front), plus ``--baselines``. ``NAME@known`` (a
baseline, or ``--reference``) runs an explorer with the robots' relative start poses known;
``--poses known`` / ``--poses merged`` runs the trained policies with the poses known or found
by merging whatever they were trained with (``train.py --known-poses`` weights in the standard
env: ``--poses merged``).

**Teams.** ``--n-robots N`` (and ``--comm-range R``) evaluates every explorer with N robots
(``multi_robot_explore_v0`` for N > 2) on the same worlds; a run trained with two robots
must be evaluated with two (its ``teammate`` input is not a set), while an SB3 run trained with
a team of 3 or more drives any team of 3 or more (``SB3Explorer.load_policy(n_robots=N)``).

**Statistics** (the practice of ``rliable``, Agarwal et al. 2021): for every explorer and
world, ratio = T / the reference's T on that world (``--reference``, default ``frontier``);
the interquartile mean (IQM, the mean of the middle 50 %: robust to the odd stuck episode,
less noisy than the median) over all
seed × world ratios, with a 95 % percentile interval from a two-level bootstrap (worlds drawn
with replacement, then each world's seeds drawn with replacement), so the interval covers
both which worlds were drawn and which training seeds. Scripted explorers have one run per
world (the world level only).

Every episode is cached in ``OUT/episodes.json`` (atomically, after each one) keyed by the
explorer, the world and the model file, so an interrupted evaluation resumes and adding a run
evaluates only that run. ``--workers`` processes share the episodes (default: one per core).
Outputs ``OUT/summary.md``, ``OUT/summary.json`` and ``OUT/training_eval.png``.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from _maps import MAPS, REAL_MAX_CYCLES, real_worlds
from _poses import POSE_SUFFIXES, split_poses, with_merge_method

from agents.goals import SECTOR_RULES
from topo.fileio import atomic_write_bytes, atomic_write_json

HELDOUT_ENTROPY = 0x4E1D_5EED
"""Root of the held-out worlds' ``SeedSequence`` (no training or ``train.py`` evaluation
world derives from it)."""
SIZE_RANGE = (10.0, 20.0)
STEPS_PER_METRE = 150
CURVE_EVERY = 10
"""Coverage curves are kept every this many steps (for the plot)."""
METRICS = ("T50", "T85", "T95")


@dataclass(frozen=True)
class World:
    """One held-out world: its id, the env config fields that make it, its reset seed."""

    id: str
    config: dict[str, Any]
    seed: int
    max_cycles: int


def heldout_worlds(n: int, real: bool = True, team: dict[str, Any] | None = None
                   ) -> list[World]:
    """``n`` procedural worlds (sides uniform in :data:`SIZE_RANGE`, 0.5 m steps) from
    :data:`HELDOUT_ENTROPY`, then the real maps of ``../shared/maps`` when ``real`` (their
    paths resolved, so that episodes cached from another checkout match). ``team``: env
    config fields of the team (``n_robots``, ``comm``) every world adds (the same worlds)."""
    rng = np.random.default_rng(np.random.SeedSequence(HELDOUT_ENTROPY))
    team = team or {}
    out = []
    for k in range(n):
        size = tuple(float(v) for v in np.round(rng.uniform(*SIZE_RANGE, 2) * 2) / 2)
        seed = int(rng.integers(2**31))
        out.append(World(f"procedural{k}_{size[0]:g}x{size[1]:g}",
                         {"world": {"size": size}, **team}, seed,
                         int(STEPS_PER_METRE * max(size))))
    if real:
        out += [World(world_id, {"world": world, **team}, 0, REAL_MAX_CYCLES)
                for world_id, world in real_worlds()]
    return out


# ------------------------------------------------------------------------------- episodes
POLICY_KINDS = ("run:", "sample:", "best-run:", "best-sample:")
"""Prefixes of a trained policy's explorer name (:func:`_team`)."""


def _policy_path(run: str | Path, best: bool) -> Path:
    """A run's final policy (``model.zip`` or ``rllib/``), or with ``best`` the best one its
    evaluations saw (``agents.training.BEST_SB3`` / ``BEST_RLLIB``); raises SystemExit if
    missing."""
    from agents.training import BEST_RLLIB, BEST_SB3

    names = (BEST_SB3, BEST_RLLIB) if best else ("model.zip", "rllib")
    for name in names:
        if (Path(run) / name).exists():
            return Path(run) / name
    raise SystemExit(f"{run}: no {' or '.join(names)} (not a finished train.py run"
                     f"{' with periodic evaluations' if best else ''})")


@functools.lru_cache(maxsize=8)
def _policy(run: str, best: bool = False, n: int | None = None) -> tuple[Any, dict[str, Any]]:
    """A run's policy (:func:`_policy_path`), for a team of ``n`` when that is not the run's
    own, and its env config (loaded once per process)."""
    import train

    run_dir = Path(run)
    saved = json.loads((run_dir / "args.json").read_text())
    known = {f for f in train.Args.__dataclass_fields__}
    kwargs = {k: v for k, v in saved.items() if k in known and k not in ("resume", "runs_dir")}
    for key in ("world_size", "eval_baselines"):
        kwargs[key] = tuple(kwargs[key])
    args = train.Args(**kwargs)
    path = _policy_path(run_dir, best)
    if path.is_file():
        from agents.sb3_explorer import SB3Explorer

        policy = SB3Explorer.load_policy(path, n_robots=n)
    else:
        from agents.rllib import RLlibPolicy

        policy = RLlibPolicy.load(path)
    return policy, args.env_config()


def _team(explorer: str, n: int = 2) -> tuple[dict[str, Any], dict[str, Any]]:
    """The team of ``n`` robots of ``explorer`` (``run:PATH``, ``sample:PATH`` — the same
    policy sampling its actions —, ``best-run:PATH`` / ``best-sample:PATH`` — the run's best
    policy —, ``rule:NAME`` or a scripted name; any of them with ``@known`` or ``@merged``
    appended runs with the robots' relative start poses known or found by merging whatever
    it was trained with, :mod:`_poses`) and the env config it runs with (before the world is
    set)."""
    from agents.goals import SectorRule
    from agents.registry import make_team
    from agents.sb3_explorer import sb3_team
    from agents.scripted import Blackboard

    base, merge_method = split_poses(explorer)
    if merge_method is not None:
        team, config = _team(base, n)
        return team, with_merge_method(config, merge_method)
    if explorer.startswith(POLICY_KINDS):
        kind, _, run = explorer.partition(":")
        policy, config = _policy(run, kind.startswith("best-"), n)
        return sb3_team(policy, deterministic=kind.endswith("run"), n_robots=n), config
    if explorer.startswith("rule:"):
        board = Blackboard()
        return {f"robot_{i}": SectorRule(explorer[5:], blackboard=board) for i in range(n)}, {}
    return make_team(explorer, n_robots=n), {}


def episode(explorer: str, world: World) -> dict[str, Any]:
    """One episode of ``explorer`` on ``world``: T50/T85/T95, reached flags, final coverage,
    overlap, collisions and the coverage curve every :data:`CURVE_EVERY` steps."""
    import torch

    torch.set_num_threads(1)
    from agents.base import run_episode
    from agents.metrics import EpisodeRecorder
    from envs import parallel_env_for

    team, config = _team(explorer, world.config.get("n_robots", 2))
    config = {**config, **world.config, "max_cycles": world.max_cycles}
    env = parallel_env_for(config)
    rec = EpisodeRecorder()
    try:
        run_episode(env, team, seed=world.seed, callback=rec)
    finally:
        env.close()
    s = rec.summary()
    curve = np.asarray(s.pop("coverage"), dtype=float)[CURVE_EVERY - 1::CURVE_EVERY]
    keep = {k: s[k] for k in (*METRICS, *(f"reached_{m}" for m in METRICS),
                              "final_coverage", "overlap", "collisions")}
    return {**{k: (bool(v) if k.startswith("reached") else float(v)) for k, v in keep.items()},
            "curve": np.round(curve, 4).tolist(), "max_cycles": world.max_cycles}


def _key(explorer: str, world: World) -> str:
    """Cache key: the explorer (a run with its model file's size and mtime) and the world."""
    tag = explorer
    if explorer.startswith(POLICY_KINDS):
        kind, _, run = split_poses(explorer)[0].partition(":")
        st = _policy_path(run, kind.startswith("best-")).stat()
        tag = f"{explorer}@{st.st_size}:{st.st_mtime_ns}"
    return json.dumps([tag, world.id, world.config, world.seed, world.max_cycles],
                      sort_keys=True)


def run_all(explorers: list[str], worlds: list[World], cache_path: Path,
            workers: int) -> dict[tuple[str, str], dict[str, Any]]:
    """Every (explorer, world) episode, from the cache or run now (saved after each)."""
    cache = json.loads(cache_path.read_text()) if cache_path.exists() else {}
    todo = [(e, w) for e in explorers for w in worlds if _key(e, w) not in cache]
    print(f"{len(explorers) * len(worlds) - len(todo)} episodes cached, {len(todo)} to run "
          f"with {workers} worker(s)", flush=True)
    if todo:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(episode, e, w): (e, w) for e, w in todo}
            for i, fut in enumerate(as_completed(futures), 1):
                e, w = futures[fut]
                cache[_key(e, w)] = fut.result()
                atomic_write_json(cache_path, cache)
                print(f"[{i}/{len(todo)}] {e} on {w.id}: T85 {cache[_key(e, w)]['T85']:.0f}",
                      flush=True)
    return {(e, w.id): cache[_key(e, w)] for e in explorers for w in worlds}


# ------------------------------------------------------------------------------- statistics
def iqm(values: np.ndarray) -> float:
    """Interquartile mean: the mean of the middle 50 % (``scipy.stats.trim_mean``, 0.25)."""
    from scipy.stats import trim_mean

    return float(trim_mean(np.asarray(values, dtype=float).ravel(), 0.25))


def bootstrap_iqm(ratios: np.ndarray, rng: np.random.Generator, reps: int = 2000,
                  level: float = 0.95) -> tuple[float, float, float]:
    """IQM of ``ratios`` (``(worlds, seeds)``) and its percentile interval from a two-level
    bootstrap: worlds with replacement, then each drawn world's seeds with replacement."""
    ratios = np.asarray(ratios, dtype=float)
    n_w, n_s = ratios.shape
    stats = np.empty(reps)
    for b in range(reps):
        w = rng.integers(n_w, size=n_w)
        s = rng.integers(n_s, size=(n_w, n_s))
        stats[b] = iqm(ratios[w[:, None], s])
    lo, hi = np.quantile(stats, [(1 - level) / 2, (1 + level) / 2])
    return iqm(ratios), float(lo), float(hi)


def summarise(groups: dict[str, list[str]], worlds: list[World],
              episodes: dict[tuple[str, str], dict[str, Any]], seed: int = 0,
              reference: str = "frontier") -> list[dict[str, Any]]:
    """One row per explorer group (a name → its explorers, one per training seed): the IQM
    ratios to ``reference`` with intervals, final coverage and the share of episodes reaching
    85 %."""
    rng = np.random.default_rng(seed)
    rows = []
    for name, members in groups.items():
        row: dict[str, Any] = {"explorer": name, "seeds": len(members), "worlds": len(worlds)}
        for m in METRICS:
            ratios = np.array([[episodes[(e, w.id)][m] / episodes[(reference, w.id)][m]
                                for e in members] for w in worlds])
            row[f"{m}_ratio"] = bootstrap_iqm(ratios, rng)
            if m == "T85":
                row["per_seed_T85_ratio"] = [iqm(ratios[:, j]) for j in range(len(members))]
        eps = [episodes[(e, w.id)] for e in members for w in worlds]
        row["final_coverage"] = float(np.mean([e["final_coverage"] for e in eps]))
        row["reached_T85"] = float(np.mean([e["reached_T85"] for e in eps]))
        row["overlap"] = float(np.mean([e["overlap"] for e in eps]))
        rows.append(row)
    return rows


def table(rows: list[dict[str, Any]], reference: str = "Frontier") -> str:
    """The Markdown table of :func:`summarise`'s rows (ratios to ``reference``)."""
    def cell(v: tuple[float, float, float]) -> str:
        return f"{v[0]:.2f} [{v[1]:.2f}, {v[2]:.2f}]"

    ref = reference
    lines = [f"| explorer | seeds × worlds | T85 / {ref}, IQM [95 % CI] | T50 / {ref} | "
             f"T95 / {ref} | final coverage | reached 85 % | overlap | per-seed T85 IQM |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        per_seed = ", ".join(f"{v:.2f}" for v in r["per_seed_T85_ratio"]) if r["seeds"] > 1 \
            else ""
        lines.append(f"| {r['explorer']} | {r['seeds']} × {r['worlds']} | "
                     f"{cell(r['T85_ratio'])} | {cell(r['T50_ratio'])} | {cell(r['T95_ratio'])} "
                     f"| {r['final_coverage']:.2f} | {r['reached_T85']:.0%} | "
                     f"{r['overlap']:.2f} | {per_seed} |")
    return "\n".join(lines) + "\n"


def plot(rows: list[dict[str, Any]], groups: dict[str, list[str]], worlds: list[World],
         episodes: dict[tuple[str, str], dict[str, Any]], path: Path,
         reference: str = "frontier") -> None:
    """Left: every seed × world T85 ratio to ``reference`` with the IQM and its interval, per
    explorer; right: mean coverage against the share of the episode elapsed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from topo.plotting import save_figure

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.8))
    for i, r in enumerate(rows):
        vals = [episodes[(e, w.id)]["T85"] / episodes[(reference, w.id)]["T85"]
                for e in groups[r["explorer"]] for w in worlds]
        jitter = np.random.default_rng(i).uniform(-0.15, 0.15, len(vals))
        ax.scatter(i + jitter, vals, s=8, alpha=0.35)
        mid, lo, hi = r["T85_ratio"]
        ax.errorbar(i, mid, yerr=[[mid - lo], [hi - mid]], fmt="D", color="k", capsize=5)
    ax.axhline(1.0, color="0.5", lw=0.8)
    ax.set_xticks(range(len(rows)), [r["explorer"] for r in rows], rotation=30, ha="right")
    ax.set_yscale("log")
    ax.set_ylabel(f"T85 / {reference}'s T85 (per world; IQM ± 95 % CI)")
    grid = np.linspace(0, 1, 101)
    for r in rows:
        curves = []
        for e in groups[r["explorer"]]:
            for w in worlds:
                c = np.asarray(episodes[(e, w.id)]["curve"])
                x = (np.arange(1, len(c) + 1) * CURVE_EVERY) / w.max_cycles
                curves.append(np.interp(grid, x, c, left=0.0))
        bx.plot(grid, np.mean(curves, axis=0), label=r["explorer"])
    for level in (0.5, 0.85, 0.95):
        bx.axhline(level, color="0.7", lw=0.8, ls="--")
    bx.set_xlabel("share of the episode (1500–3000 steps procedural, 2000 real)")
    bx.set_ylabel("true coverage (mean over seeds × worlds)")
    bx.set_ylim(0, 1)
    bx.legend()
    bx.grid(alpha=0.3)
    save_figure(fig, path)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="*", type=Path, help="train.py run folders")
    parser.add_argument("--label", action="append", default=[],
                        help="NAME=GLOB: group the run folders GLOB matches under NAME (default: "
                             "one group 'ppo' of all runs); repeat for ablations, e.g. "
                             "--label masked='runs/m*'")
    parser.add_argument("--sample", action="store_true",
                        help="the runs' policies sample their actions (seeded per episode) "
                             "instead of taking the most likely one")
    parser.add_argument("--best", action="store_true",
                        help="each run's best evaluated policy (best_model.zip / rllib_best/, "
                             "chosen on the run's own evaluation worlds) instead of its final one")
    parser.add_argument("--worlds", type=int, default=20, help="procedural held-out worlds")
    parser.add_argument("--skip-real", action="store_true", help="procedural worlds only")
    parser.add_argument("--rules", nargs="*", default=["ahead"], choices=SECTOR_RULES)
    parser.add_argument("--baselines", nargs="*", default=["random_walk"],
                        help="scripted explorers besides frontier; NAME@known: with the "
                             "robots' relative start poses known")
    parser.add_argument("--poses", choices=[k.lstrip("@") for k in POSE_SUFFIXES],
                        default=None,
                        help="run the trained policies with the robots' relative start poses "
                             "known or found by merging, whatever they were trained with "
                             "(default: as trained)")
    parser.add_argument("--reference", default="frontier",
                        help="scripted explorer the T ratios are taken to (it is evaluated too)")
    parser.add_argument("--n-robots", type=int, default=2,
                        help="robots per team (2-8); runs must have been trained with as many")
    parser.add_argument("--comm-range", type=float, default=None,
                        help="communication range of the team, m (default: unlimited)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--out", type=Path, default=Path("out/training_eval"))
    opts = parser.parse_args()
    if opts.worlds < 1:
        parser.error(f"--worlds must be >= 1, got {opts.worlds}")
    if opts.workers < 1:
        parser.error(f"--workers must be >= 1, got {opts.workers}")
    if not 2 <= opts.n_robots <= 8:
        parser.error(f"--n-robots must be between 2 and 8, got {opts.n_robots}")
    if opts.comm_range is not None and opts.comm_range <= 0:
        parser.error(f"--comm-range must be > 0, got {opts.comm_range}")
    team: dict[str, Any] = {}
    if opts.n_robots != 2:
        team["n_robots"] = opts.n_robots
    if opts.comm_range is not None:
        team["comm"] = {"range": opts.comm_range}
    groups: dict[str, list[str]] = {}
    kind = ("best-" if opts.best else "") + ("sample" if opts.sample else "run")
    if opts.label:
        import glob

        for spec in opts.label:
            name, sep, pattern = spec.partition("=")
            paths = sorted(p for p in glob.glob(pattern) if Path(p).is_dir())
            if not sep or not name or not paths:
                parser.error(f"--label must be NAME=GLOB matching run folders, got {spec!r}")
            groups[name] = [f"{kind}:{p}" for p in paths]
    elif opts.runs:
        groups["ppo"] = [f"{kind}:{p}" for p in opts.runs]
    for members in groups.values():
        for m in members:
            run = Path(m.partition(":")[2])
            if not (run / "args.json").is_file():
                parser.error(f"{run}: not a train.py run folder (no args.json)")
            trained = json.loads((run / "args.json").read_text()).get("n_robots", 2)
            if trained != opts.n_robots and (min(trained, opts.n_robots) == 2
                                              or not (run / "model.zip").is_file()):
                parser.error(f"{run} was trained with {trained} robots, --n-robots is "
                             f"{opts.n_robots}: only an SB3 team policy (3 or more robots) "
                             f"drives a team of another size (3 or more)")
            try:
                _policy_path(run, opts.best)
            except SystemExit as missing:
                parser.error(str(missing))
    if opts.poses is not None:
        groups = {name: [f"{m}@{opts.poses}" for m in members]
                  for name, members in groups.items()}
    ref = opts.reference
    scripted = list(dict.fromkeys(["frontier", ref, *opts.baselines,
                                   *(f"rule:{r}" for r in opts.rules)]))
    groups = {**groups, **{s: [s] for s in scripted if s != ref}, ref: [ref]}
    if not opts.skip_real and not MAPS.is_dir():
        parser.error(f"the real maps are not at {MAPS} (shared/ beside the repository); "
                     "pass --skip-real to evaluate on procedural worlds only")
    worlds = heldout_worlds(opts.worlds, real=not opts.skip_real, team=team)
    opts.out.mkdir(parents=True, exist_ok=True)
    explorers = list(dict.fromkeys([ref, *(m for ms in groups.values() for m in ms)]))
    episodes = run_all(explorers, worlds, opts.out / "episodes.json", opts.workers)
    rows = summarise(groups, worlds, episodes, reference=ref)
    text = table(rows, "Frontier" if ref == "frontier" else ref)
    print("\n" + text)
    atomic_write_bytes(opts.out / "summary.md", text.encode())
    atomic_write_json(opts.out / "summary.json", {"rows": rows,
                                                  "worlds": [w.id for w in worlds],
                                                  "groups": groups})
    plot(rows, groups, worlds, episodes, opts.out / "training_eval.png", reference=ref)
    print(f"wrote {opts.out / 'summary.md'} and {opts.out / 'training_eval.png'}")


if __name__ == "__main__":
    main()
