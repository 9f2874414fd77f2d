"""Maps that bend (issue 41): two robots merging through the pose graph
(``mapping.pose_graph=True``) under drifting odometry, against the rigid merges (off).

    python benchmarks/bending_in_loop.py [--worlds 5] [--first-seed 100] [--size 20]
        [--steps 3000] [--explorer frontier] [--odometry-alphas pioneer3dx]
        [--odometry-noise S] [--settings on off] [--oracle [--oracle-at-last]]
        [--anchor-every N] [--window-anchors W] [--window-searches K] [--rows FILE]
        [--out RUN.jsonl] [--from RUN.jsonl ...] [--against RUN.jsonl ...]

For each seed (from 100: worlds the method was not developed on) one episode per setting,
a scripted team (``agents.registry``), ``robot.odometry_model="rot_trans_rot"`` with the
given alphas (or ``--odometry-noise S``: the ``"increment"`` model at ``(S, S)``; ``0``:
perfect); ``--robots N`` (> 2): ``multi_robot_explore_v0``. Every step with a teammate in
robot 0's fused map is checked by the env's infos (``merge_rotation_error_deg``,
``merge_translation_error_m``: the worst teammate, against the drift-aware truth at the
robots' current places, ``envs.explore.drift.drift_aware_error``);
**right** is within 5° and 0.5 m (the issue's target), **wrong** more than 5° or 1 m off.
Per episode: the first merged step, the first right step, merged steps, right and wrong
shares of them, the mean step time (seconds, wall and CPU, the explorers included), the share
of the CPU time spent mapping and merging (the env's ``_sense_and_map`` and ``_fuse``; merging
alone: ``_fuse``), and at the end
``merge_state().bending`` (the fused map's anchor ATE and wall share beside robot 0's own
uncorrected map, links kept and how many of them are wrong at their own anchors) and the
bend floor of window links (:func:`bend_floor`: how often even a perfect window aligner's
link is wrong at its anchors, the windows being bent inside). With
``--oracle`` every window alignment is replaced by the truth wherever the two windows' true
anchor positions come within ``ORACLE_MEET_M`` (and nothing elsewhere): the ceiling of any
window aligner with these anchors, windows and searches (``--oracle-at-last``: the links at
the windows' newest anchors instead of their middle ones). The summary
gives, per setting, the episodes merged, the median first right step (never: ``steps + 1``),
the pooled right share of merged steps, median ATE and wall share, and the mean step time;
then how calibrated the near searches' confidences are (model ``"window_near"``: their mean
against the share right within 5° and 1 m at their anchors, pooled and by confidence bin).
``--rows FILE`` writes every near search's row (features, confidence, errors at its anchors;
split ``dev`` for seeds below 100, else ``test``) as JSON lines: what ``python -m
fusion.calibration fit --model window_near --rows FILE --split dev`` fits on.

**Judging a change** (the explorers follow the straightened maps, so any change sends some
episodes down other paths and five seeds move by chance as much as most changes do): run about
a hundred episodes of each version with ``--out`` (one file per version of the code; rewritten
after each episode; run again with the same options, it resumes where it stopped), then
``--from NEW.jsonl ... --against OLD.jsonl ...`` prints the summary of the new rows and, over
the episodes both runs hold, the paired table: per metric the mean difference and its standard
error, the episodes better and worse (:data:`BETTER_ATE_M`, :data:`BETTER_WALL`), the gain over
the robot's map as scanned (fused minus own, per episode: steadier than the raw values, since
the map as scanned moves by chance too), the folded fused maps (:data:`FOLD_M`), links and loop
closures kept wrong, and the first right merge of the episodes both merged right. A difference
of two standard errors on one set of seeds has failed to repeat on the next hundred: confirm on
fresh seeds.
"""

from __future__ import annotations

import argparse
import itertools
import math
import statistics
import time

import numpy as np
import torch
from _timing import StageClock

from agents.base import run_episode
from agents.registry import EXPLORERS, make_team
from envs import multi_robot_explore_v0, two_robot_explore_v0
from envs.explore.graph_merging import GraphMerging
from fusion import Rigid2D
from topo.fileio import atomic_write_json_lines, read_json_lines

RIGHT_DEG, RIGHT_M = 5.0, 0.5
WRONG_DEG, WRONG_M = 5.0, 1.0
BETTER_ATE_M, BETTER_WALL = 0.03, 0.02
"""A paired episode counts as better or worse (``--against``) when its fused ATE moved by
more than this (m), or its wall share."""
FOLD_M = 0.3
"""A fused map counts as folded (``--against``) when its ATE is this much (m) worse than the
robot's map as scanned."""
ORACLE_MEET_M = 3.0
ORACLE_AT_LAST = False


def oracle_align(self, i: int, ei: int, j: int, ej: int) -> bool:
    """``GraphMerging._align`` with the truth for an aligner (``--oracle``): the windows'
    middle anchors' true relative pose, whenever the two windows' true anchor positions come
    within :data:`ORACLE_MEET_M`; no link otherwise."""
    w = self.config.window_anchors
    ti = np.array(self.submaps[i].truths[ei - w + 1:ei + 1])[:, :2]
    tj = np.array(self.submaps[j].truths[ej - w + 1:ej + 1])[:, :2]
    self.searches += 1
    if np.min(np.linalg.norm(ti[:, None] - tj[None], axis=2)) > ORACLE_MEET_M:
        return False
    half = 0 if ORACLE_AT_LAST else w // 2
    a, b = ei - half, ej - half
    ta = Rigid2D.from_pose(self.submaps[i].truths[a])
    tb = Rigid2D.from_pose(self.submaps[j].truths[b])
    return self.add_alignment(i, a, j, b, ta.inverse() @ tb, 1.0)


def bend_floor(graph: GraphMerging, meet_m: float = ORACLE_MEET_M) -> dict[str, float]:
    """The bend floor of window links (what even a perfect window aligner inherits): every
    pair of closed windows (two robots', or one robot's that do not overlap) whose true
    anchors come within ``meet_m``, each window put in the world by its best rigid fit (its
    anchors' odometry headings and positions onto their true ones: the circular mean of the
    heading differences, then the mean position), the link this implies checked against the
    truth at the windows' middle anchors (where links are made) and at their newest ones.
    Returns the pairs and the shares of them more than 5° or 1 m off at each."""
    w = graph.config.window_anchors
    odo, true = [], []
    for sub in graph.submaps:
        k = len(sub.patches)
        odo.append(np.array([[p.T[0], p.T[1], p.theta] for p in sub.poses[:k]]).reshape(-1, 3))
        true.append(np.array(sub.truths[:k]).reshape(-1, 3))

    def fit(r: int, end: int) -> Rigid2D:
        o, t = odo[r][end - w + 1:end + 1], true[r][end - w + 1:end + 1]
        d = t[:, 2] - o[:, 2]
        turn = Rigid2D(float(np.arctan2(np.sin(d).mean(), np.cos(d).mean())))
        shift = t[:, :2].mean(axis=0) - turn.apply(o[:, :2]).mean(axis=0)
        return Rigid2D(turn.theta, (float(shift[0]), float(shift[1])))

    wrong = {"mid": 0, "last": 0}
    pairs = 0
    n = len(graph.submaps)
    for i in range(n):
        for j in range(i, n):
            for ei in range(w - 1, len(odo[i])):
                for ej in range(w - 1, len(odo[j]) if j != i else ei - w + 1):
                    ti, tj = true[i][ei - w + 1:ei + 1, :2], true[j][ej - w + 1:ej + 1, :2]
                    if np.min(np.linalg.norm(ti[:, None] - tj[None], axis=2)) > meet_m:
                        continue
                    pairs += 1
                    fi, fj = fit(i, ei), fit(j, ej)
                    for where, (a, b) in (("mid", (ei - w // 2, ej - w // 2)),
                                          ("last", (ei, ej))):
                        ideal = ((fi @ Rigid2D.from_pose(odo[i][a])).inverse()
                                 @ fj @ Rigid2D.from_pose(odo[j][b]))
                        err = (Rigid2D.from_pose(true[i][a]).inverse()
                               @ Rigid2D.from_pose(true[j][b])).inverse() @ ideal
                        wrong[where] += bool(abs(np.degrees(err.theta)) > WRONG_DEG
                                             or float(np.hypot(*err.T)) > WRONG_M)
    return {"floor_pairs": float(pairs),
            "floor_mid_wrong": wrong["mid"] / pairs if pairs else float("nan"),
            "floor_last_wrong": wrong["last"] / pairs if pairs else float("nan")}


def episode(seed: int, explorer: str, steps: int, size: float, robot: dict,
            pose_graph: bool, mapping: dict | None = None, robots: int = 2) -> dict:
    """One episode's row (module docstring)."""
    kwargs = dict(max_cycles=steps, world={"size": (size, size)},
                  mapping={"pose_graph": pose_graph, **(mapping or {})}, robot=robot)
    env = (two_robot_explore_v0.parallel_env(**kwargs) if robots == 2
           else multi_robot_explore_v0.parallel_env(n_robots=robots, **kwargs))
    row = {"seed": seed, "graph": pose_graph, "first": None, "first_right": None,
           "merged": 0, "right": 0, "wrong": 0}

    def watch(k, _obs, _rewards, infos):
        info = infos.get("robot_0")
        if not info or not info["merge_errors_valid"]:
            return
        row["merged"] += 1
        row["first"] = row["first"] or k
        rot, trans = info["merge_rotation_error_deg"], info["merge_translation_error_m"]
        if rot <= RIGHT_DEG and trans <= RIGHT_M:
            row["right"] += 1
            row["first_right"] = row["first_right"] or k
        elif rot > WRONG_DEG or trans > WRONG_M:
            row["wrong"] += 1

    clock = StageClock(env.unwrapped, ("_sense_and_map", "_fuse"))
    t0, cpu = time.perf_counter(), time.process_time()
    out = run_episode(env, make_team(explorer, env=env), seed=seed, callback=watch)
    cpu = time.process_time() - cpu
    row["steps"] = out["steps"]
    row["step_s"] = (time.perf_counter() - t0) / max(out["steps"], 1)
    row["cpu_step_s"] = cpu / max(out["steps"], 1)
    row["mapping_share"] = sum(clock.seconds.values()) / cpu if cpu else float("nan")
    row["merging_share"] = clock.seconds["_fuse"] / cpu if cpu else float("nan")
    if pose_graph:
        row.update(env.unwrapped.merge_state().bending)
        row.update(bend_floor(env.unwrapped._graph))
        odometry = (f"sigma{robot['odometry_noise'][0]:g}" if "odometry_noise" in robot
                    else robot.get("odometry_alphas", "perfect"))
        row["near_rows"] = near_rows(env.unwrapped._graph, seed, f"bending/{odometry}/{robots}")
    return row


def near_rows(graph: GraphMerging, seed: int, name: str) -> list[dict]:
    """Every near search the graph recorded (``LinkRecord.features`` set) as a calibration row
    of model ``"window_near"``: its features and confidence, its errors at its own anchors, and
    ``right`` (within 5° and 1 m there); ``set`` ``name``, ``world`` the seed, split ``dev``
    below seed 100."""
    out = []
    for rec, (rot, trans) in zip(graph.records, graph.link_errors(), strict=True):
        if rec.features is None:
            continue
        out.append({"set": name, "world": f"bending:{seed}", "seed": seed,
                    "split": "dev" if seed < 100 else "test", "way": "ab", "overlap": 1.0,
                    "loop": rec.i == rec.j, "features": rec.features,
                    "confidence": rec.confidence, "rot_err_deg": rot, "trans_err_m": trans,
                    "right": bool(rot <= WRONG_DEG and trans <= WRONG_M)})
    return out


def calibration_lines(rows: list[dict]) -> list[str]:
    """How calibrated the near rows' confidences are: pooled and per bin, mean confidence
    against the share right."""
    if not rows:
        return ["near searches: none"]
    p = np.array([r["confidence"] for r in rows])
    y = np.array([r["right"] for r in rows], dtype=float)
    out = [f"near searches: {len(rows)}, mean confidence {p.mean():.3f}, right {y.mean():.3f}",
           "confidence | near searches | mean confidence | right"]
    edges = (0.0, 0.7, 0.8, 0.85, 0.9, 0.95, 1.0 + 1e-9)
    for lo, hi in itertools.pairwise(edges):
        m = (p >= lo) & (p < hi)
        if m.any():
            out.append(f"{lo:.2f}–{min(hi, 1.0):.2f} | {int(m.sum())} | {p[m].mean():.3f} | "
                       f"{y[m].mean():.3f}")
    return out


def _mean_se(values: list[float]) -> tuple[float, float]:
    values = [v for v in values if not math.isnan(v)]
    if not values:
        return math.nan, math.nan
    se = statistics.stdev(values) / math.sqrt(len(values)) if len(values) > 1 else math.nan
    return statistics.mean(values), se


def paired_lines(old: list[dict], new: list[dict]) -> list[str]:
    """The paired comparison (module docstring, ``--against``) of the pose-graph episodes
    (``graph`` true) that both ``old`` and ``new`` hold, matched by seed."""
    before = {r["seed"]: r for r in old if r["graph"]}
    after = {r["seed"]: r for r in new if r["graph"]}
    seeds = sorted(set(before) & set(after))
    if not seeds:
        return ["paired: no pose-graph episode in both runs"]
    out = [f"paired: {len(seeds)} episodes (new minus old)",
           "metric | old mean | new mean | mean difference (se) | better / worse episodes"]
    metrics = (("fused ATE m", lambda r: r["fused_ate_m"], -BETTER_ATE_M),
               ("fused wall share", lambda r: r["fused_wall_share"], BETTER_WALL),
               ("ATE gain over own map m", lambda r: r["fused_ate_m"] - r["own_ate_m"],
                -BETTER_ATE_M),
               ("wall-share gain over own map",
                lambda r: r["fused_wall_share"] - r["own_wall_share"], BETTER_WALL))
    for name, get, better in metrics:
        diff = [get(after[s]) - get(before[s]) for s in seeds]
        mean, se = _mean_se(diff)
        up = sum(d * math.copysign(1, better) > abs(better) for d in diff)
        down = sum(d * math.copysign(1, better) < -abs(better) for d in diff)
        old_mean, new_mean = (_mean_se([get(r[s]) for s in seeds])[0] for r in (before, after))
        out.append(f"{name} | {old_mean:.3f} | {new_mean:.3f} | {mean:+.3f} ({se:.3f}) | "
                   f"{up} / {down}")
    for name, rows in (("old", before), ("new", after)):
        folds = [s for s in seeds if rows[s]["fused_ate_m"] - rows[s]["own_ate_m"] > FOLD_M]
        kept = ", ".join(
            f"{k.replace('_', ' ')} wrong {sum(rows[s][k + '_wrong'] for s in seeds):.0f} / "
            f"{sum(rows[s][k] for s in seeds):.0f}" for k in ("links_kept", "loops_kept"))
        merged = sum(rows[s]["merged"] > 0 for s in seeds)
        out.append(f"{name}: merged {merged}, {kept}; folded (fused ATE > own + {FOLD_M} m) "
                   f"{len(folds)}: {folds}")
    both = [s for s in seeds if before[s]["first_right"] and after[s]["first_right"]]
    if both:
        mean, se = _mean_se([after[s]["first_right"] - before[s]["first_right"] for s in both])
        out.append(f"first right, the {len(both)} episodes both merged right: mean difference "
                   f"{mean:+.0f} steps ({se:.0f})")
    else:
        out.append("first right: no episode merged right in both runs")
    return out


def _run_options(args: argparse.Namespace) -> dict:
    """What a run's rows depend on besides the seed (``--out`` resumes only the same)."""
    keys = ("size", "steps", "explorer", "odometry_alphas", "odometry_noise", "oracle",
            "oracle_at_last", "robots", "window_searches", "window_anchors", "anchor_every")
    return {k: getattr(args, k) for k in keys}


def _jsonable(row: dict) -> dict:
    return {k: (v if isinstance(v, (str, bool, type(None), list, dict)) else
                int(v) if isinstance(v, (int, np.integer)) else float(v))
            for k, v in row.items()}


ROW_KEYS = ("seed", "graph", "first", "first_right", "merged", "right", "wrong", "step_s",
            "fused_ate_m", "own_ate_m", "working_ate_m", "fused_wall_share", "own_wall_share",
            "working_wall_share", "links_kept", "links_kept_wrong", "loops_kept",
            "loops_kept_wrong", "window_searches", "floor_pairs", "floor_mid_wrong",
            "floor_last_wrong")
"""The columns of an episode's printed row."""


def _row_line(row: dict) -> str:
    return " | ".join(_fmt(row.get(k)) for k in ROW_KEYS)


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--worlds", type=int, default=5)
    parser.add_argument("--first-seed", type=int, default=100)
    parser.add_argument("--size", type=float, default=20.0)
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--explorer", choices=sorted(EXPLORERS), default="frontier")
    parser.add_argument("--odometry-alphas", default="pioneer3dx")
    parser.add_argument("--odometry-noise", type=float, default=None,
                        help="use the increment model at (S, S) instead of the alphas")
    parser.add_argument("--settings", nargs="+", choices=("on", "off"), default=["on", "off"])
    parser.add_argument("--oracle", action="store_true",
                        help="window alignments from the truth (the ceiling of any aligner)")
    parser.add_argument("--oracle-at-last", action="store_true",
                        help="oracle links at the windows' newest anchors, not their middle")
    parser.add_argument("--robots", type=int, default=2,
                        help="team size (more than 2: multi_robot_explore_v0)")
    parser.add_argument("--window-searches", type=int, default=None)
    parser.add_argument("--window-anchors", type=int, default=None)
    parser.add_argument("--anchor-every", type=int, default=None)
    parser.add_argument("--rows", default=None,
                        help="write the near searches' calibration rows (JSON lines) here")
    parser.add_argument("--out", default=None,
                        help="write every episode's row here (JSON lines); resumes a run")
    parser.add_argument("--from", dest="from_", nargs="+", default=None, metavar="RUN",
                        help="summarise these runs' rows (--out files) instead of running")
    parser.add_argument("--against", nargs="+", default=None, metavar="RUN",
                        help="compare with these runs' rows (--out files), paired by seed")
    args = parser.parse_args(argv)
    if args.from_ and args.out:
        parser.error("--from summarises runs already made: it takes no --out")
    if args.oracle:
        GraphMerging._align = oracle_align
    if args.oracle_at_last:
        global ORACLE_AT_LAST
        ORACLE_AT_LAST = True
    mapping = {k: v for k, v in (("window_searches", args.window_searches),
                                 ("window_anchors", args.window_anchors),
                                 ("anchor_every", args.anchor_every)) if v is not None}
    torch.set_num_threads(1)
    if args.odometry_noise is not None:
        robot = {"odometry_noise": (args.odometry_noise, args.odometry_noise)}
    else:
        robot = {"odometry_model": "rot_trans_rot", "odometry_alphas": args.odometry_alphas}
    options = _run_options(args)
    done: dict[tuple[int, bool], dict] = {}
    if args.out:
        for r in read_json_lines(args.out):
            if r.get("options") != options:
                raise ValueError(f"--out {args.out} holds a run with other options "
                                 f"({r.get('options')}, not {options}): resume it with "
                                 f"those or write to another file")
            done[(r["seed"], r["graph"])] = r
    rows = []
    print(" | ".join(ROW_KEYS), flush=True)
    seeds = range(args.first_seed, args.first_seed + args.worlds)
    if args.from_:
        rows = [r for path in args.from_ for r in _read_run(path)]
        args.steps = rows[0]["options"]["steps"]  # "never merged right" counts as steps + 1
        args.settings = [s for s in ("on", "off") if any(r["graph"] == (s == "on")
                                                          for r in rows)]
        seeds = ()
        for row in rows:
            print(_row_line(row))
    for seed in seeds:
        for setting in args.settings:
            row = done.get((seed, setting == "on"))
            if row is None:
                row = _jsonable(episode(seed, args.explorer, args.steps, args.size, robot,
                                        setting == "on", mapping, args.robots))
                row["options"] = options
                done[(seed, setting == "on")] = row
            rows.append(row)
            print(_row_line(row), flush=True)
            # rewritten whole after each episode: a crash keeps those done
            if args.out:
                atomic_write_json_lines(args.out, done.values())
            if args.rows:
                atomic_write_json_lines(args.rows, [n for r in rows
                                                    for n in r.get("near_rows", ())])
    print()
    print("setting | merged episodes | median first right | right / merged steps | "
          "wrong / merged steps | median fused ATE (own; working) m | "
          "median wall share fused (own; working) | "
          "links kept wrong | loops kept wrong | "
          "bend floor: ideal window links wrong (middle / newest anchors) | "
          "step ms | mapping + merging, merging alone: share of a step")
    for setting in args.settings:
        sel = [r for r in rows if r["graph"] == (setting == "on")]
        merged = sum(r["merged"] > 0 for r in sel)
        first = statistics.median(r["first_right"] or args.steps + 1 for r in sel)
        msteps = sum(r["merged"] for r in sel)
        right = sum(r["right"] for r in sel) / msteps if msteps else float("nan")
        wrong = sum(r["wrong"] for r in sel) / msteps if msteps else float("nan")
        ms = 1000 * statistics.mean(r["step_s"] for r in sel)
        if setting == "on":
            ate, wall = (f"{statistics.median(r['fused_' + k] for r in sel):.2f} "
                         f"({statistics.median(r['own_' + k] for r in sel):.2f}; "
                         f"{statistics.median(r['working_' + k] for r in sel):.2f})"
                         for k in ("ate_m", "wall_share"))
            kept = " | ".join(f"{sum(r[k + '_wrong'] for r in sel):.0f} / "
                              f"{sum(r[k] for r in sel):.0f}" for k in ("links_kept", "loops_kept"))
            pairs = sum(r["floor_pairs"] for r in sel)
            floor = " / ".join(
                f"{sum(r[k] * r['floor_pairs'] for r in sel if r['floor_pairs']) / pairs:.3f}"
                if pairs else "-" for k in ("floor_mid_wrong", "floor_last_wrong"))
        else:
            ate = wall = floor = "-"
            kept = "- | -"
        cpu = [r["cpu_step_s"] * r["steps"] for r in sel]
        share = " ".join(f"{sum(r[k] * c for r, c in zip(sel, cpu, strict=True)) / sum(cpu):.0%}"
                         for k in ("mapping_share", "merging_share"))
        print(f"{setting} | {merged}/{len(sel)} | {first} | {right:.2f} | {wrong:.2f} | {ate} | "
              f"{wall} | {kept} | {floor} | {ms:.1f} | {share}")
    near = [n for r in rows for n in r.get("near_rows", ())]
    if "on" in args.settings:
        print()
        print("\n".join(calibration_lines(near)))
    if args.rows:
        print(f"wrote {len(near)} rows to {args.rows}")
    if args.against:
        print()
        print("\n".join(paired_lines([r for path in args.against for r in _read_run(path)],
                                      rows)))


def _read_run(path: str) -> list[dict]:
    """The episode rows of an ``--out`` file.

    Raises:
        FileNotFoundError: ``path`` does not exist or holds no rows.
    """
    rows = read_json_lines(path)
    if not rows:
        raise FileNotFoundError(f"{path}: no run rows (write them with --out)")
    return rows


if __name__ == "__main__":
    main()
