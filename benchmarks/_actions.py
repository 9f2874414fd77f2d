"""The fixed action sequence of the env benchmarks (``tests/envs/test_env_hash.py`` pins the
env's output under it): for each robot a new random command every 10 steps from
``default_rng(seed)``, mostly forward."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

AGENTS = ("robot_0", "robot_1")


def fixed_actions(steps: int, seed: int) -> list[dict[str, np.ndarray]]:
    """The commands of ``steps`` steps (each dict shared by the 10 steps it holds for)."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(steps):
        if k % 10 == 0:
            cmd = {a: np.array([rng.uniform(0.2, 1.0), rng.uniform(-1, 1)], dtype=np.float32)
                   for a in AGENTS}
        out.append(cmd)
    return out


def episode(seed: int, steps: int) -> Iterator[tuple[Any, int, tuple]]:
    """One episode of ``two_robot_explore_v0`` (defaults, ``max_cycles=steps``, reset with
    ``seed``) under :func:`fixed_actions`; yields ``(env, step index, step outputs)``."""
    from envs import two_robot_explore_v0

    par = two_robot_explore_v0.parallel_env(max_cycles=steps)
    par.reset(seed=seed)
    for k, acts in enumerate(fixed_actions(steps, seed)):
        yield par, k, par.step(acts)
        if not par.agents:
            break
