"""Fingerprint of ``two_robot_explore_v0``'s output, step by step: for checking that a speed
change leaves the env bit-identical.

Runs seeds 0, 1, 2 and 4 for ``--steps`` steps each under a fixed action sequence (a new random
command every 10 steps) and prints two running SHA-256 digests every 100 steps: ``obs``, of
observations, rewards, terminations, truncations and both robots' topological maps (positions,
kinds, paths, lengths, polylines), and ``infos``, of the infos (their scalars, and the array
ones' bytes) — so a change of the infos alone (a new key, say) shows in the second column
only. Seeds 0–2 accept no merge within 1000 steps; seed 4 merges from step 399, so the code
that runs once the maps are fused (the warped shared map, the teammate observation,
``local_map`` from both grids) is covered too. Run it on two checkouts and diff::

    python benchmarks/env_hash.py > /tmp/before.txt      # on main
    python benchmarks/env_hash.py > /tmp/after.txt       # on your branch
    diff /tmp/before.txt /tmp/after.txt                  # nothing printed = identical

The first differing line bounds the first differing step (to within 100 steps).
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from envs import two_robot_explore_v0  # noqa: E402

SCALARS = (int, float, bool, str)


def episode(seed: int, steps: int):
    """Run one episode of at most ``steps`` steps under the fixed actions (a new random command
    every 10 steps from ``default_rng(seed)``); yield ``(env, step index, step outputs)``."""
    par = two_robot_explore_v0.parallel_env(max_cycles=steps)
    par.reset(seed=seed)
    rng = np.random.default_rng(seed)
    acts = {}
    for k in range(steps):
        if k % 10 == 0:
            acts = {a: np.array([rng.uniform(0.2, 1.0), rng.uniform(-1, 1)], dtype=np.float32)
                    for a in par.agents}
        yield par, k, par.step(acts)
        if not par.agents:
            break


def fingerprint(seed: int, steps: int, every: int = 100):
    """Yield ``(step, obs digest, infos digest)`` of the running hashes (module docstring)
    every ``every`` steps of one episode."""
    h = hashlib.sha256()
    hi = hashlib.sha256()
    for par, k, (obs, rew, term, trunc, info) in episode(seed, steps):
        for a in sorted(obs):
            for key in sorted(obs[a]):
                h.update(np.ascontiguousarray(obs[a][key]).tobytes())
            h.update(repr((rew[a], term[a], trunc[a])).encode())
            inf = info[a]
            hi.update(repr([(key, inf[key]) for key in sorted(inf)
                            if isinstance(inf[key], SCALARS)]).encode())
            for key in sorted(inf):
                if isinstance(inf[key], np.ndarray):
                    hi.update(np.ascontiguousarray(inf[key]).tobytes())
        for m in par.maps:
            tm = m.topomap
            for arr in (tm.xy, tm.kinds, tm.edges, tm.lengths, *(tm.paths or ())):
                h.update(np.ascontiguousarray(arr).tobytes())
        if (k + 1) % every == 0:
            yield k + 1, h.hexdigest()[:16], hi.hexdigest()[:16]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000, help="steps per seed")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 4])
    args = parser.parse_args()
    for seed in args.seeds:
        for step, obs_digest, infos_digest in fingerprint(seed, args.steps):
            print(seed, step, "obs", obs_digest, "infos", infos_digest, flush=True)


if __name__ == "__main__":
    main()
