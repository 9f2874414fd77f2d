"""``make demo``: two scripted wanderers explore one episode of ``two_robot_explore_v0``.

Prints the coverage and how good the map merge was, writes the last frame to ``out/demo.png``
and a short GIF (every 20th step) to ``out/demo.gif``.

The wanderer is deliberately simple (the agents package has frontier explorers): drive ahead,
drift in a random direction that changes now and then, and turn away — towards the side with
more room — when the front sonars see something close.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from envs import two_robot_explore_v0  # noqa: E402


class Wanderer:
    """A reactive sonar wanderer for the Pioneer front ring (-90 … 90°)."""

    def __init__(self, rng: np.random.Generator, max_range: float) -> None:
        self.rng = rng
        self.max_range = max_range
        self.drift = 0.0
        self.turn_steps = 0
        self.turn_dir = 1.0

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """``(v, ω)`` in ``[-1, 1]`` from the latest sonar readings."""
        r = obs["sonar"] * self.max_range
        front = min(r[3], r[4])
        right, left = float(np.mean(r[:3])), float(np.mean(r[5:]))
        if self.turn_steps:
            if front > 0.9:
                self.turn_steps -= 1
            return np.array([0.0, self.turn_dir], dtype=np.float32)
        if front < 0.6 or min(r[2], r[5]) < 0.4:
            self.turn_dir = 1.0 if left >= right else -1.0
            self.turn_steps = int(self.rng.integers(3, 10))
            return np.array([0.0, self.turn_dir], dtype=np.float32)
        if self.rng.random() < 0.05:
            self.drift = float(self.rng.uniform(-0.4, 0.4))
        steer = 0.6 * (min(r[5], r[6]) - min(r[1], r[2])) / self.max_range
        return np.array([1.0, np.clip(self.drift + steer, -1, 1)], dtype=np.float32)


def _write_atomic(path: Path, write) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=path.suffix)
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=1000, help="max_cycles of the episode")
    parser.add_argument("--out", type=Path, default=Path("out"))
    parser.add_argument("--no-gif", action="store_true")
    args = parser.parse_args()
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    import imageio.v3 as iio

    env = two_robot_explore_v0.parallel_env(max_cycles=args.steps, render_mode="rgb_array")
    obs, infos = env.reset(seed=args.seed)
    rng = np.random.default_rng(args.seed)
    max_range = env.config.sonar.max_range
    bots = {a: Wanderer(np.random.default_rng(rng.integers(2**32)), max_range)
            for a in env.possible_agents}
    frames = []
    total = 0.0
    steps = 0
    while env.agents:
        actions = {a: bots[a].act(obs[a]) for a in env.agents}
        obs, rewards, _, _, infos = env.step(actions)
        total += rewards["robot_0"]
        steps += 1
        if not args.no_gif and steps % 20 == 0:
            frames.append(env.render()[::2, ::2])
    frame = env.render()
    info = infos["robot_0"]
    print(f"two_robot_explore_v0, seed {args.seed}: {env.world.name}, {steps} steps")
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
    _write_atomic(png, lambda p: iio.imwrite(p, frame))
    print(f"  wrote {png}")
    if frames:
        gif = args.out / "demo.gif"
        _write_atomic(gif, lambda p: iio.imwrite(p, np.stack(frames), duration=100, loop=0))
        print(f"  wrote {gif} ({len(frames)} frames)")
    env.close()


if __name__ == "__main__":
    main()
