"""``make demo``, maps that bend: two Frontier explorers with drifting Pioneer 3-DX odometry
explore a 20 m building of ``two_robot_explore_v0`` and merge through the pose graph
(``mapping.pose_graph=True``, needs the ``slam`` extra: GTSAM).

Each robot's map as scanned (``env.scanned_map``) bends with its odometry; the pose graph
straightens it into the robot's working map (``env.robot_map``: its submaps at their
corrections, right where the robot is) and robot 0's fused map (``env.fused_map("robot_0")``)
is its own and robot 1's submaps, each moved by its anchor's correction. Prints when the pair
merged and how far each map is from the truth (``merge_state().bending``: the anchors' ATE
after one best rigid fit, the share of occupied cells within 0.2 m of a true wall), and writes
the maps as scanned beside robot 0's working and fused maps to ``out/bending.png`` (true walls
drawn from each robot's start, where its frame begins; on the working map from where the
robot is now).

    python examples/bending.py [--out out] [--seed 102] [--steps 2000]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agents.base import run_episode  # noqa: E402
from agents.registry import make_team  # noqa: E402
from envs import two_robot_explore_v0  # noqa: E402
from topo.plotting import save_figure  # noqa: E402

PIONEER = {"odometry_model": "rot_trans_rot", "odometry_alphas": "pioneer3dx"}
"""The Pioneer 3-DX odometry preset: the maps bend."""

STATE_COLOURS = ListedColormap(["0.72", "white", "black"])
"""Unknown, free, occupied (``topo.grid.CellState`` codes 0, 1, 2)."""


def draw(ax, states: np.ndarray, origin: tuple[float, float], resolution: float,
         walls: np.ndarray, title: str) -> None:
    """One map's cell states, cropped to its known cells, with the true walls ``walls``
    (``(M, 4)`` segments in the map's frame) in red."""
    rows, cols = np.nonzero(states)
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    extent = (origin[0] + c0 * resolution, origin[0] + c1 * resolution,
              origin[1] + r0 * resolution, origin[1] + r1 * resolution)
    ax.imshow(states[r0:r1, c0:c1], cmap=STATE_COLOURS, vmin=0, vmax=2, origin="lower",
              extent=extent, interpolation="nearest")
    for x0, y0, x1, y1 in walls:
        ax.plot([x0, x1], [y0, y1], color="tab:red", lw=0.8, alpha=0.75)
    pad = 1.0
    ax.set_xlim(extent[0] - pad, extent[1] + pad)
    ax.set_ylim(extent[2] - pad, extent[3] + pad)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=102,
                        help="a held-out world where the pair merges early (102)")
    parser.add_argument("--steps", type=int, default=2000, help="max_cycles of the episode")
    parser.add_argument("--out", type=Path, default=Path("out"))
    args = parser.parse_args(argv)
    env = two_robot_explore_v0.parallel_env(robot=PIONEER, mapping={"pose_graph": True},
                                            world={"size": (20.0, 20.0)},
                                            max_cycles=args.steps)
    merged_at = []

    def watch(step, _obs, _rewards, infos):
        if not merged_at and infos and infos["robot_0"]["merge_accepted"]:
            merged_at.append(step)

    out = run_episode(env, make_team("frontier"), seed=args.seed, callback=watch)
    bend = env.merge_state().bending
    fused = env.fused_map("robot_0")
    when = f"fused from step {merged_at[0]}" if merged_at else "never merged"
    print(f"maps that bend, seed {args.seed}: {env.world.name}, {out['steps']} steps, "
          f"Pioneer 3-DX odometry; robots {list(fused.robots)} {when}")
    lines = {"own": "robot 0's map as scanned", "working": "its working map",
             "fused": "its fused map"}
    for key, name in lines.items():
        print(f"  {name:25s} ATE {bend[key + '_ate_m']:.2f} m, walls within 0.2 m of true "
              f"walls {bend[key + '_wall_share']:.0%}")
    print(f"  ({bend['links_kept']:.0f} links kept, {bend['links_kept_wrong']:.0f} of them off "
          f"at their anchors)")

    fig, axes = plt.subplots(2, 2, figsize=(13, 12), layout="constrained")
    for i, ax in enumerate(axes[0]):
        snap = env.scanned_map(f"robot_{i}")
        title = f"robot_{i}'s map as scanned (bent by its odometry)"
        if i == 0:
            title += (f"\nATE {bend['own_ate_m']:.2f} m, walls within 0.2 m of true walls "
                      f"{bend['own_wall_share']:.0%}")
        draw(ax, snap.states, snap.origin, snap.resolution, _walls_in(env, i), title)
    work = env.robot_map("robot_0").grid
    draw(axes[1, 0], work.states(), work.origin, work.resolution, _walls_here(env, 0),
         f"robot_0's working map (straightened by the graph)\nATE "
         f"{bend['working_ate_m']:.2f} m, walls within 0.2 m of true walls "
         f"{bend['working_wall_share']:.0%}")
    draw(axes[1, 1], fused.states, fused.origin, fused.resolution, _walls_in(env, 0),
         f"robot_0's fused map (robots {', '.join(map(str, fused.robots))})\n"
         f"ATE {bend['fused_ate_m']:.2f} m, walls within 0.2 m of true walls "
         f"{bend['fused_wall_share']:.0%}")
    fig.suptitle(f"Maps that bend (pose graph, Pioneer 3-DX odometry): seed {args.seed}, "
                 f"step {fused.step}, {when}; red: the true walls", fontsize=11)
    png = save_figure(fig, args.out / "bending.png")
    plt.close(fig)
    print(f"  wrote {png}")
    env.close()


def _walls_here(env, i: int) -> np.ndarray:
    """The world's walls in robot ``i``'s odometry frame as it is where the robot is now
    (its true pose against its odometry): where its working map is right."""
    to_map = env.robots[i].odometry_frame().inverse()
    seg = env.world.segments
    return np.hstack([to_map.apply(seg[:, :2]), to_map.apply(seg[:, 2:])])


def _walls_in(env, i: int) -> np.ndarray:
    """The world's walls in robot ``i``'s map frame (its true start pose: no drift)."""
    to_map = env.frames[i].inverse()
    seg = env.world.segments
    return np.hstack([to_map.apply(seg[:, :2]), to_map.apply(seg[:, 2:])])


if __name__ == "__main__":
    main()
