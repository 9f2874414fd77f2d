"""``make demo``: two scripted explorers run one episode of ``two_robot_explore_v0``, then a
team of ``--team`` (4) Frontier explorers one episode of ``multi_robot_explore_v0`` with an 8 m
communication range.

Prints the coverage and how good the map merges were, writes the last frames to
``out/demo.png`` and ``out/team.png`` and a short GIF (every 20th step) to ``out/demo.gif``.
The two-robot explorers are ``agents.scripted`` ones (``--explorer``, default
``coordinated_frontier``).

    python examples/demo.py [--out out] [--seed 0] [--explorer NAME] [--team N]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agents.registry import make_team  # noqa: E402
from agents.scripted import Frontier  # noqa: E402
from envs import multi_robot_explore_v0, two_robot_explore_v0  # noqa: E402
from topo.fileio import atomic_write  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=1000, help="max_cycles of the episode")
    parser.add_argument("--out", type=Path, default=Path("out"))
    parser.add_argument("--no-gif", action="store_true")
    parser.add_argument("--explorer", default="coordinated_frontier",
                        help="agents.registry.EXPLORERS name of the explorer driving both robots")
    parser.add_argument("--team", type=int, default=4,
                        help="robots of the multi-robot episode (2-8; 0 skips it)")
    args = parser.parse_args()
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    import imageio.v3 as iio

    env = two_robot_explore_v0.parallel_env(max_cycles=args.steps, render_mode="rgb_array")
    obs, infos = env.reset(seed=args.seed)
    team = make_team(args.explorer, env=env)
    for explorer, s in zip(team.values(), np.random.SeedSequence(args.seed).spawn(2), strict=True):
        explorer.reset(int(s.generate_state(1)[0]))
    frames = []
    total = 0.0
    steps = 0
    while env.agents:
        actions = {a: team[a].act(obs[a], infos[a]) for a in env.agents}
        obs, rewards, _, _, infos = env.step(actions)
        total += rewards["robot_0"]
        steps += 1
        if not args.no_gif and steps % 20 == 0:
            frames.append(env.render()[::2, ::2])
    frame = env.render()
    info = infos["robot_0"]
    print(f"two_robot_explore_v0, seed {args.seed}: {env.world.name}, {steps} steps, "
          f"explorer {args.explorer}")
    print(f"  true coverage      {info['true_coverage']:.1%} of {env.world.reachable_area:.0f} m²")
    print(f"  shared map         {info['shared_area_m2']:.1f} m² (robot 0 alone "
          f"{info['own_area_m2']:.1f} m²)")
    print(f"  team return        {total:.2f}")
    print(f"  contacts           {infos['robot_0']['collisions']} + "
          f"{infos['robot_1']['collisions']}")
    print(f"  merges             {info['merges']} attempted, transform in use: "
          f"{info['merge_accepted']}")
    if info["merge_accepted"]:
        print(f"  merge accuracy     rotation error {info['merge_rotation_error_deg']:.2f}°, "
              f"translation error {info['merge_translation_error_m']:.3f} m")
    else:
        print("  merge accuracy     no merge accepted in this episode")
    png = args.out / "demo.png"
    atomic_write(png, lambda fh: iio.imwrite(fh, frame, extension=".png"))
    print(f"  wrote {png}")
    if frames:
        gif = args.out / "demo.gif"
        atomic_write(gif, lambda fh: iio.imwrite(fh, np.stack(frames), extension=".gif",
                                                 duration=100, loop=0))
        print(f"  wrote {gif} ({len(frames)} frames)")
    env.close()
    if args.team:
        team_episode(args.team, args.seed, args.steps, args.out)


def team_episode(n: int, seed: int, steps: int, out: Path) -> None:
    """One episode of ``n`` Frontier explorers with an 8 m communication range; prints who
    merged with whom and writes the last frame to ``out/team.png``."""
    import imageio.v3 as iio

    env = multi_robot_explore_v0.parallel_env(n_robots=n, comm={"range": 8.0},
                                              max_cycles=steps, render_mode="rgb_array")
    obs, infos = env.reset(seed=seed)
    team = {a: Frontier() for a in env.possible_agents}
    for (agent, explorer), s in zip(team.items(), np.random.SeedSequence(seed).spawn(n),
                                    strict=True):
        explorer.reset(int(s.generate_state(1)[0]))
        explorer.bind(env, agent)
    k = 0
    while env.agents:
        obs, _, _, _, infos = env.step({a: team[a].act(obs[a], infos[a]) for a in env.agents})
        k += 1
    state = env.merge_state()
    info = infos["robot_0"]
    print(f"multi_robot_explore_v0, {n} robots, 8 m range, seed {seed}: {k} steps")
    print(f"  true coverage      {info['true_coverage']:.1%}; robot 0's fused map "
          f"{info['shared_area_m2']:.1f} m² of robots {list(state.fused[0])}")
    for (i, j), pair in sorted(state.pairs.items()):
        if pair.transform is not None:
            err = math.degrees(pair.transform.rotation_error(env.true_transform(i, j)))
            print(f"  pair ({i}, {j})        merged, rotation error {err:.2f}°, kept by the "
                  f"cycle check: {pair.kept}")
    png = out / "team.png"
    atomic_write(png, lambda fh: iio.imwrite(fh, env.render(), extension=".png"))
    print(f"  wrote {png}")
    env.close()


if __name__ == "__main__":
    main()
