"""Exploration metrics of one episode, recorded step by step from the env's ``infos``.

* ``T50``/``T85``/``T95``: first step at which the **true** coverage (the env's
  ``info["true_coverage"]``: known fraction of the reachable free area, all robots, world
  frame) reaches 50/85/95 %. An episode that never gets there is *censored* at its length + 1
  (``reached_*`` says which), so averages stay comparable and penalise not finishing.
* ``overlap``: final fraction of the smaller robot's explored area also explored by the other
  (``info["overlap"]``; in a team of more than two, the cells swept again by another robot over
  the most that could be); duplicated effort.
* ``path_length_m`` per robot (true poses), ``collisions`` (sum of the robots' contacts).
* ``merge_first_accept_step``, ``merge_accept_fraction`` (steps with a transform in use),
  final ``merge_rotation_error_deg``/``merge_translation_error_m`` (NaN without a transform
  in use at the end: the infos' ``merge_errors_valid``).
* ``coverage``: the whole true-coverage curve, for plots.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

LEVELS = (0.50, 0.85, 0.95)

EPISODE_INFO_KEYS = ("true_coverage", "shared_coverage", "overlap", "merges", "contacts",
                     "fused_robots", "fused_ate_m", "fused_wall_share")
"""Robot 0's infos that training logs at episode ends under ``explore/`` (both backends), those
the env has: ``contacts`` and ``fused_robots`` only a team of more than two robots
(``multi_robot_explore_v0``: robots in contact with it, robots in its fused map), the fused
map's ATE and wall share only ``mapping.pose_graph``."""


@dataclass
class EpisodeRecorder:
    """Callback for :func:`agents.base.run_episode` collecting the metrics above.

    Use: ``rec = EpisodeRecorder(); run_episode(env, team, seed, callback=rec)``, then
    ``rec.summary()``.
    """

    coverage: list[float] = field(default_factory=list)
    accepted: list[bool] = field(default_factory=list)
    _last_pose: dict[str, np.ndarray] = field(default_factory=dict)
    _path: dict[str, float] = field(default_factory=dict)
    _last_info: dict[str, Any] = field(default_factory=dict)
    _collisions: dict[str, int] = field(default_factory=dict)

    def __call__(self, step: int, observations: dict, rewards: dict, infos: dict) -> None:
        if not infos:
            return
        first = next(iter(infos.values()))
        self.coverage.append(float(first["true_coverage"]))
        self.accepted.append(bool(first["merge_accepted"]))
        for agent, info in infos.items():
            pose = np.asarray(info["pose"], dtype=np.float64)[:2]
            if agent in self._last_pose:
                self._path[agent] = self._path.get(agent, 0.0) + float(
                    np.linalg.norm(pose - self._last_pose[agent]))
            self._last_pose[agent] = pose
            self._collisions[agent] = int(info["collisions"])
        self._last_info = first

    def summary(self) -> dict[str, Any]:
        """The episode's metrics (module docstring)."""
        cov = np.asarray(self.coverage)
        n = len(cov)
        out: dict[str, Any] = {"steps": n}
        for level in LEVELS:
            key = f"T{round(level * 100)}"
            hit = np.flatnonzero(cov >= level)
            out[f"reached_{key}"] = bool(len(hit))
            out[key] = int(hit[0] + 1) if len(hit) else n + 1
        info = self._last_info
        out["final_coverage"] = float(cov[-1]) if n else 0.0
        out["overlap"] = float(info.get("overlap", math.nan))
        out["path_length_m"] = {a: round(v, 3) for a, v in sorted(self._path.items())}
        out["collisions"] = int(sum(self._collisions.values()))
        acc = np.asarray(self.accepted)
        first = np.flatnonzero(acc)
        out["merge_first_accept_step"] = int(first[0] + 1) if len(first) else None
        out["merge_accept_fraction"] = float(acc.mean()) if n else 0.0
        for key in ("merge_rotation_error_deg", "merge_translation_error_m"):
            out[key] = float(info[key]) if info.get("merge_errors_valid") else math.nan
        out["coverage"] = cov
        return out
