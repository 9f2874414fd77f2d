"""The env's infos (manual, Infos) and the merge errors they report.

Infos are small, numeric and comparable: no NaN, no wall clock, no live objects, so that equal
episodes give equal infos and infos are cheap to send. The merge errors are measured against
ground truth for metrics; explorers must not use them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from envs.explore.comm import TeamViews
from envs.explore.drift import drift_aware_error
from envs.explore.mapping import OracleCoverage, RobotMap, SharedMap
from envs.explore.merging import MERGE_METHODS, MERGE_SOURCES, TeamMerging
from envs.explore.robot import Robot
from fusion.rigid import Rigid2D


def merge_errors(members: Mapping[int, tuple[Rigid2D, Rigid2D]], robots: Sequence[Robot],
                 truths: Sequence[Rigid2D], merging: TeamMerging, views: TeamViews,
                 drifts: bool) -> tuple[float, float]:
    """Rotation error (degrees) and translation error (metres, at the centroid of the
    teammate's map) of the merge transforms in use in robot 0's fused map against ground truth,
    the largest over its teammates; ``(nan, nan)`` when it has none.

    Args:
        members: robot 0's fused teammates, ``{j: (to_0, from_0)}`` (``SharedMap.members``).
        robots: every robot, in index order.
        truths: ``truths[j]``: the true transform from robot ``j``'s map frame into robot 0's
            (their start poses).
        merging: the episode's merging (it keeps the last answer per teammate,
            :meth:`TeamMerging.errors`).
        views: what robot 0 holds of each teammate's map (the centroid is that map's).
        drifts: the odometry is noisy: the truth is then drift-aware
            (:func:`envs.explore.drift.drift_aware_error`: the transform that is
            right at the robots' current places, errors measured there) and ``truths`` is not
            read.
    """
    worst = (math.nan, math.nan)
    for j, (to_0, _) in sorted(members.items()):
        if drifts:
            rot, trans = drift_aware_error(to_0, robots[0], robots[j])
        else:
            rot, trans = merging.errors(j, to_0, views.view(0, j).topomap, truths[j],
                                        robots[j].odometry[:2])
        worst = (rot, trans) if math.isnan(worst[0]) else (max(worst[0], rot),
                                                           max(worst[1], trans))
    return worst


def step_infos(agents: Sequence[str], possible_agents: Sequence[str], robots: Sequence[Robot],
               maps: Sequence[RobotMap], oracle: OracleCoverage, shared: SharedMap,
               world_area: float, merging: TeamMerging, views: TeamViews,
               errors: tuple[float, float], team: bool,
               fused_truth: tuple[float, float] | None = None) -> dict[str, dict[str, Any]]:
    """One step's infos (manual, Infos): ``{agent: {key: value}}`` for each live agent.

    Args:
        agents, possible_agents: the live agents and all of them (index order).
        robots, maps: every robot's, in index order.
        oracle, shared: the true coverage and robot 0's fused map.
        world_area: the reachable free area, m² (``shared_coverage``'s denominator).
        merging, views: the episode's merging and contacts.
        errors: :func:`merge_errors` while robot 0's fused map has teammates (not read
            otherwise: the infos then say 0.0 and ``merge_errors_valid`` False).
        team: the ``multi_robot_explore_v0`` layout (adds ``contacts`` and
            ``fused_robots``).
        fused_truth: with ``mapping.pose_graph``, robot 0's fused map's anchor ATE (m) and
            wall share as of the last merge step (adds ``fused_ate_m`` and
            ``fused_wall_share``); ``None`` otherwise.
    """
    in_use = bool(shared.members)
    rot_err, trans_err = errors if in_use else (0.0, 0.0)
    common = {
        "true_coverage": oracle.fraction,
        "true_area_m2": oracle.area,
        "shared_area_m2": shared.area,
        "shared_coverage": shared.area / world_area,
        "overlap": oracle.overlap,
        "merge_accepted": in_use,
        "merge_method": MERGE_METHODS.index(merging.pair01.method),
        "merge_source": MERGE_SOURCES.index(merging.pair01.source),
        "merge_errors_valid": in_use,
        "merge_rotation_error_deg": rot_err,
        "merge_translation_error_m": trans_err,
        "merges": merging.calls,
        "merge_drops": merging.drops,
    }
    if fused_truth is not None:
        common["fused_ate_m"], common["fused_wall_share"] = fused_truth
    out = {}
    for i, a in enumerate(possible_agents):
        if a not in agents:
            continue
        rmap = maps[i]
        robot = robots[i]
        out[a] = {
            **common,
            "own_area_m2": rmap.n_ever * rmap.geometry.resolution ** 2,
            "collisions": robot.collisions,
            "pose": robot.true_pose(),
            "odometry": robot.odometry.copy(),
        }
        if team:
            out[a]["contacts"] = len(views.contacts(i))
            out[a]["fused_robots"] = len(merging.frames[i])
    return out
