"""A team of sonar robots explores an unknown building and merges its maps.

The manual of ``multi_robot_explore_v0`` (teams of ``n_robots`` = 2–8, range-limited
communication) and ``two_robot_explore_v0`` (two robots, its original layout: one ``teammate``
row, no ``contacts``/``fused_robots`` infos). How sensing, drift, merging, the known-poses
baseline, the state and copies work, at length: ``docs/env_explore.md``.

## Description

Pioneer3-DX-like robots (``robot_0 … robot_{N-1}``) start at random poses, unknown to each
other, in a 2-D indoor world simulated with pymunk. Each drives by a velocity command, senses
with a ring of sonars and builds an occupancy grid and a topological map **in its own odometry
frame**. Every ``merge_every`` steps robots in contact align their maps; an accepted merge adds
a teammate's map to a robot's **fused map**. The team is rewarded for growing robot 0's fused
map (the **shared map**), so a wrong merge costs reward. A cooperative PettingZoo
``ParallelEnv``; ``env()`` is its AEC version; after ``import envs``,
``gymnasium.make("topomerge/TwoRobotExplore-v0")`` (or ``"topomerge/MultiRobotExplore-v0"``,
``n_robots=N``) is the team as one Gymnasium agent (:mod:`envs.explore.centralised`).

## Action Space

``Box(-1, 1, (2,), float32)`` per robot (``action_type="continuous"``):

| index | meaning                  | unit              | min | max |
|-------|--------------------------|-------------------|-----|-----|
| 0     | forward speed ``v``      | × ``robot.max_speed`` (0.7 m/s)     | -1 | 1 |
| 1     | turn rate ``ω`` (CCW)    | × ``robot.max_turn_rate`` (100°/s)  | -1 | 1 |

Finite values outside ``[-1, 1]`` are clipped; NaN, inf or a wrong shape is a ``ValueError``.
With ``action_type="discrete"``, ``Discrete(5)``: 0 stop, 1 forward, 2 turn left in place,
3 turn right in place, 4 backward (full speed/turn rate).

## Observation Space

A ``Dict`` per robot (``R`` = the world's diagonal plus the sonar range; ``N`` =
``mapping.max_nodes``, ``L`` = ``mapping.local_map_size``):

| key | shape, dtype | meaning | min | max |
|---|---|---|---|---|
| ``sonar`` | (8,) f32 | range / ``max_range`` per sonar (1 = no echo) | 0 | 1 |
| ``odometry`` | (4,) f32 | ``x, y`` (m, own start frame), ``cos θ, sin θ`` | -R, -1 | R, 1 |
| ``graph_nodes`` | (N, 9) f32 | per node, nearest first (a) | -2R, 0 | 2R, 16 |
| ``graph_mask`` | (N,) f32 | 1 for a real node, 0 for padding | 0 | 1 |
| ``graph_adjacency`` | (N, N) f32 | 1 where a path joins two listed nodes | 0 | 1 |
| ``local_map`` | (1, L, L) u8 | heading-up crop of the robot's fused map (b) | 0 | 255 |
| ``teammate`` | (5,) f32 | teammate's estimated pose (c; two robots) | -2R, -1, 0 | 2R, 1, 1 |
| ``teammates`` | (N−1, 7) f32 | per teammate (h; teams) | -2R, -1, 0 | 2R, 1, 1 |

(a) of the robot's own topological map: ``x, y`` relative to the robot (m, robot frame: x
ahead, y left), kind one-hot (junction, dead end, corner, gateway), degree (0–16), clearance
(m, 0–10), frontier flag (1: the node touches the unknown).
(b) robot at the centre facing up, its left on the image's left,
``mapping.local_map_resolution`` m/pixel; 0 occupied, 128 unknown, 255 free; only its own map
before a merge.
(c) ``x, y`` (m, robot frame), ``cos, sin`` of its relative heading, valid flag (1 once a merge
is accepted; all 0 before).
(h) one row per teammate in index order, skipping the robot itself: the five entries of (c)
(valid: it is in this robot's fused map; its pose at their last contact when out of contact),
then ``in_contact`` (0/1) and ``age``: steps since their last contact / ``max_cycles`` (0 in
contact, 1 if never; clipped to 1).

## Sensors

A ring of sonars on each robot's rim (``sonar.angles``: the Pioneer front ring). A sonar is a
cone of ``sonar.rays`` rays cast against the walls and the teammates' discs — the very shapes
the robots collide with — and reads its nearest echo plus Gaussian noise; an echo meeting a
wall more than ``dropout_incidence`` off its normal is lost with probability ``dropout_prob``
(specular reflection); ``max_range`` means no echo. Odometry is exact by default;
``robot.odometry_noise`` or ``robot.odometry_model="rot_trans_rot"`` make it drift, and the
maps then bend (Drift in ``docs/env_explore.md``).

## Maps

``world.source="procedural"`` (default) is a new ``world.size`` building of rooms, corridors,
doors, loops and furniture every reset; or a ROS ``map_server`` YAML, DungeonMaps PNG or
HouseExpo JSON file. Each robot folds its scans into an occupancy grid (half-side ``R`` around
its start; readings beyond ``mapping.usable_range`` only free) and every ``mapping.topo_every``
steps, once the map has grown by ``mapping.topo_growth``, re-extracts its topological map
(``topo.extract_topomap``): **places**, **gateways** (doorways), **dead ends** and the paths
between them; nodes touching the unknown are flagged ``frontier`` and left out of merges.

Merging (``mapping.merge_method``): ``"hybrid"`` (default) runs the structural merge of the
topological maps every ``merge_every`` steps and the occupancy-grid alignment every
``grid_merge_every`` steps. A result is accepted when its **confidence** (calibrated
probability that the transform is right: rotation < 2°, translation < 0.3 m) is at least
``mapping.accept_threshold``: lower it to merge sooner, at the price of wrong merges. The grids
keep checking an accepted transform and may replace or drop it (``merge_drops``). ``"auto"``,
``"paper_icp"``, ``"exhaustive"``, ``"multistart_icp"``: one ``fusion.merge_maps`` method with
its own accept rule; ``"none"`` never merges; ``"known"`` uses the true start-frame transforms
from the first step (the known-poses baseline).

## Communication

Robots at most ``comm.range`` metres apart (``None``: always; with ``comm.line_of_sight``, no
wall between) are in range; robots joined by a chain of in-range robots are **in contact**.
Pairs merge only in contact (at most ``max(1, N // 2)`` per merge step); out of contact a robot
keeps a teammate's map as it was at their last contact (``env.teammate_map(agent, teammate)``).
With three or more robots ``mapping.cycle_check`` leaves out merges that break triangles
A→B→C, and a merge no triangle confirms needs ``mapping.team_accept_threshold``.
``merge_state()`` reports every pair, fused map and contact.

## Rewards

Team reward (every robot gets it), every step:

    coverage_reward · (new shared-map area, m²) − collision_penalty · (new contacts of any
    robot) − time_penalty

A teammate's cells count once it is in robot 0's fused map; when a merge changes or drops a
transform the shared map is rebuilt and the change of its area (negative for a wrong merge or
a dropped one) enters the reward. ``reward_mode="oracle"`` uses the true newly swept area
instead (ablations); ``"individual"`` gives each robot its own new area and its own contacts.
Shaping for learning velocity commands lives outside the env (``agents.motion.MotionEnv``).

Worked example (defaults: ``coverage_reward = 0.1``, ``collision_penalty = 0.5``,
``time_penalty = 0.01``): in one step robot 0 uncovers 120 new cells and robot 1 (already
merged) 80 cells, 30 of which robot 0 had already seen, at 0.1 m: the shared map grows by
(120 + 50) · 0.01 = 1.7 m²; robot 1 also bumps a wall: reward = 0.1 · 1.7 − 0.5 · 1 − 0.01 =
−0.34 for both robots.

## Starting State

``N`` random drivable cells (two for ``two_robot_explore_v0``) at least
``world.start_clearance`` (0.45 m) from any wall and ``world.min_start_separation`` (2 m)
apart, in one connected region, random headings; each robot's odometry starts at ``(0, 0, 0)``.
Where a building has no such cells the draw retries from the same generator (other cells, then
the most spread-out cells, then another building), so every seed starts; settings no building
can hold (too many robots for the world, a world or map too large to allocate) are refused
when the env is made, naming the setting and the limit (``envs.explore.feasibility``).
A fresh ``pymunk.Space`` every reset; the first scan is taken at reset. A ``reset`` that raises
(a ``seed`` that is not ``None`` or an integer ≥ 0, bad ``options`` or ``start_poses``) leaves
no episode (``agents`` empty): ``step()`` raises until a ``reset`` succeeds.

## Episode End

* Termination: the true covered fraction of the reachable free area (``info["true_coverage"]``)
  reaches ``target_coverage`` (0.95) — all robots terminate.
* Truncation: ``max_cycles`` steps (1000) — all robots truncate.

After that ``agents`` is empty and ``step()`` raises until ``reset()``.

## Infos

Small, numeric and comparable (no NaN, no wall clock, no live objects). Per robot:

| key | type | meaning |
|---|---|---|
| ``true_coverage`` / ``true_area_m2`` | float | share of the reachable area / m² truly swept (d) |
| ``shared_area_m2`` / ``shared_coverage`` | float | shared map's known m² / over reachable m² |
| ``own_area_m2`` | float | known area of the robot's own map, m² |
| ``overlap`` | float | fraction of the smaller robot's true sweep the other also swept |
| ``collisions`` | int | contacts of this robot so far |
| ``merge_accepted`` | bool | a merge transform is in use |
| ``merge_method`` / ``merge_source`` | int | code of the merge in use's method / source (g) |
| ``merge_errors_valid`` | bool | the two errors below are measured (a transform is in use) |
| ``merge_rotation_error_deg`` | float | rotation error of the transform in use, ° (f) |
| ``merge_translation_error_m`` | float | its translation error at robot 1's map centroid, m (f) |
| ``merges`` / ``merge_drops`` | int | merge calls so far / transforms the grids refuted (Maps) |
| ``pose`` / ``odometry`` | (3,) f64 | true world ``x, y, θ`` (metrics only) / own-frame odometry |
| ``contacts`` / ``fused_robots`` | int | teammates in contact / robots in its fused map (teams) |
| ``fused_ate_m`` / ``fused_wall_share`` | float | robot 0's fused map: ATE, m / wall share (h) |

(d) from true poses and ranges: dropped echoes and drift do not count. (f) against ground
truth, drift-aware with odometry noise; 0.0 when not valid; in a team, the largest over robot
0's fused teammates. (g) ``MERGE_METHODS[code]`` (0: none) and ``MERGE_SOURCES[code]`` (1
structural, 2 grid, 3 known), constants of this module; in a team, pair (robot_0, robot_1)'s.
(h) only with ``mapping.pose_graph``, for metrics: against the truth as of the last merge
step (``fusion.evaluation.bending``): the RMS error of its anchors after one best rigid fit, and
the share of its occupied cells within 0.2 m of a true wall (0.0 before any is mapped);
``merge_state().bending`` has more.
Maps are read through the env: ``env.unwrapped.robot_map(agent)`` and ``fused_map(agent)``
(read-only snapshots of its own and its fused map; ``scanned_map(agent)``: its own as scanned,
which differs from its own map only with ``mapping.pose_graph``) and ``merge_state()``
(:class:`MergeState`).

## State

``state()`` (``state_space``; the AEC ``env()`` forwards both) is a global view for centralised
critics: float32, ``4N + 4 + 3 · 32²`` values in the world frame — each robot's true pose,
``true_coverage``, ``overlap``, the share of teammates in robot 0's fused map, steps /
``max_cycles``, then 32 × 32 maps of the world truly swept, in the shared map, and reachable
(index table: State in ``docs/env_explore.md``).

## Copies

The env pickles and deep-copies before and after ``reset``, and a copy continues exactly as the
original would. A copy replays the episode since ``reset``, so restoring takes about as long as
those steps took; a replay that does not reproduce the original raises ``RuntimeError``.

## Arguments

``parallel_env(config=None, *, render_mode=None, **kwargs)``; ``kwargs`` are
:class:`~envs.explore.config.EnvConfig` fields, groups as dicts, e.g.
``parallel_env(max_cycles=500, sonar={"rays": 1}, world={"size": (40, 40)})``. Unknown keys
are a ``ValueError``.

| parameter | type | default | meaning |
|---|---|---|---|
| ``world.source`` | str | ``"procedural"`` | procedural building or a map file path (Maps) |
| ``world.size`` / ``room_size`` | (float, float) | (20, 20) / (3, 6) | building, room sides, m |
| ``world.resolution`` / ``png_resolution`` | float | 0.1 / 0.1 | world grid m/cell, PNG m/pixel |
| ``world.corridor_prob`` / ``loop_prob`` | float | 0.25 / 0.3 | corridor rows, extra doors |
| ``world.door_width`` / ``wall_thickness`` | float | 1 / 0.2 | m |
| ``world.obstacle_density`` | float | 0.5 | furniture boxes per 10 m² |
| ``world.start_clearance`` / ``min_start_separation`` | float | 0.45 / 2 | m (Starting State) |
| ``n_robots`` | int | 2 | robots in the team, 2–8 (``two_robot_explore_v0``: 2) |
| ``comm.range`` / ``line_of_sight`` | float or None / bool | None / False | see Communication |
| ``robot.radius`` | float | 0.25 | disc radius, m |
| ``robot.max_speed`` / ``max_turn_rate`` | float | 0.7 / 100 | m/s, °/s at action 1 |
| ``robot.dt`` / ``substeps`` | float / int | 0.1 / 4 | seconds per step, physics substeps |
| ``robot.odometry_model`` | str | ``"increment"`` | or ``"rot_trans_rot"`` (Thrun's α1–α4 model) |
| ``robot.odometry_noise`` | (float, float) | (0, 0) | relative σ of ``"increment"`` odometry |
| ``robot.odometry_alphas`` | 4 floats or str | 0s | α1–α4, or ``"pioneer3dx"`` |
| ``robot.drift_correction`` | bool | False | experimental odometry correction (noisy only) |
| ``robot.drift_correction_every`` / ``_window`` / ``_age`` | int | 25 / 150 / 300 | steps |
| ``robot.drift_correction_sigma`` | float | 3 | m per echo of the match's information |
| ``sonar.angles`` | floats | Pioneer ring | directions, ° CCW from the heading |
| ``sonar.rays`` / ``cone`` | int / float | 3 / 15 | rays per cone, cone width (°) |
| ``sonar.min_range`` / ``max_range`` / ``noise_std`` | float | 0.15 / 5 / 0.01 | m |
| ``sonar.dropout_incidence`` / ``dropout_prob`` | float | 60 / 0.5 | specular dropout: °, chance |
| ``sonar.measure_every`` | float or None | None | scan every this many metres travelled |
| ``mapping.grid_resolution`` | float | 0.1 | m/cell |
| ``mapping.usable_range`` | float or None | 2.5 | m; longer readings only free (Maps) |
| ``mapping.topo_every`` / ``merge_every`` | int | 25 / 25 | steps (0 = never) |
| ``mapping.grid_merge_every`` | int | 100 | steps between grid alignments |
| ``mapping.topo_growth`` / ``grid_merge_growth`` | float | 0.02 / 0.2 | growth before a rerun |
| ``mapping.topo`` | dict or ``ExtractConfig`` | defaults | ``topo.ExtractConfig`` fields |
| ``mapping.merge_method`` | str | ``"hybrid"`` | see Maps |
| ``mapping.accept_threshold`` | float | 0.9 | least merge confidence accepted (Maps) |
| ``mapping.first_merge_check`` | bool | True | a pair's first merge needs the grids too |
| ``mapping.pose_graph`` | bool | False | experimental: maps that bend (docs/env_explore.md) |
| ``mapping.cycle_check`` | bool | True | cycle consistency (Communication) |
| ``mapping.team_accept_threshold`` | float | 0.97 | merges no triangle confirms (likewise) |
| ``mapping.local_map_size`` / ``_resolution`` | int / float | 64 / 0.15 | pixels, m/pixel |
| ``mapping.max_nodes`` | int | 32 | graph nodes observed |
| ``max_cycles`` / ``target_coverage`` | int / float | 1000 / 0.95 | truncation, termination |
| ``reward_mode`` | str | ``"shared"`` | ``"shared"``, ``"oracle"``, ``"individual"`` |
| ``coverage_reward`` / ``collision_penalty`` | float | 0.1 / 0.5 | per new m², per new contact |
| ``time_penalty`` | float | 0.01 | per step |
| ``action_type`` | str | ``"continuous"`` | or ``"discrete"`` |
| ``render_mode`` | str or None | None | ``"human"`` (pygame-ce window) or ``"rgb_array"`` |

Reset options: ``{"start_poses": [[x, y, θ], ...]}`` (one row per robot, world frame,
radians) places the robots; other keys are ignored with a warning.

## Version History

* multi_robot_explore_v0: initial release (teams of 2–8, communication, the N-way merge; at
  ``n_robots = 2``, ``comm.range = None`` the same episodes as two_robot_explore_v0 but for
  the ``teammates`` layout and the two infos).
* v0: initial release. (Unreleased changes within v0, dynamics unchanged: small numeric
  infos, maps read through ``robot_map``/``fused_map``/``merge_state``, ``state()``, exact
  copies by replay, the sonar cast by the env's own ray caster with the same readings; the
  topological maps re-extracted (places, gateways, dead ends, clearance and frontier flags), so
  ``graph_nodes`` has 9 features and merges, hence rewards, differ; sonar readings beyond
  ``mapping.usable_range`` no longer draw walls or free space past it, so maps, coverage and
  rewards differ; a pair's first structural merge needs the grids to agree, so some merges
  come later; a start draw that finds no cells retries instead of raising, so seeds that
  failed to reset now start — every seed that started before starts the same.)
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec

from envs.explore.actions import DISCRETE_ACTIONS, parse_actions
from envs.explore.config import EnvConfig
from envs.explore.copies import ReplayCopies
from envs.explore.episode import EpisodeHooks, agent_names
from envs.explore.global_state import (
    STATE_MAP_SIZE,
    STATE_SAMPLES,
    STATE_SCALARS,
    state_scalars,
)
from envs.explore.infos import merge_errors
from envs.explore.mapping import FusedMapSnapshot, RobotMapSnapshot
from envs.explore.merging import (
    MERGE_METHODS,
    MERGE_SOURCES,
    MergeState,
    PairState,
)
from envs.explore.observations import (
    MAX_CLEARANCE,
    MAX_DEGREE,
    N_NODE_FEATURES,
    TEAMMATE_FEATURES,
)
from envs.explore.starts import check_seed, parse_reset_options
from envs.explore.worlds import World
from fusion.rigid import Rigid2D

AGENTS = ("robot_0", "robot_1")
"""The two-robot env's agents (``agent_names(2)``)."""


__all__ = ["AGENTS", "DISCRETE_ACTIONS", "MAX_CLEARANCE", "MAX_DEGREE", "MERGE_METHODS",
           "MERGE_SOURCES", "N_NODE_FEATURES", "STATE_MAP_SIZE", "STATE_SAMPLES",
           "STATE_SCALARS", "TEAMMATE_FEATURES", "MergeState", "MultiRobotExploreEnv",
           "PairState", "TwoRobotExploreEnv", "agent_names", "env", "multi_env",
           "multi_parallel_env", "parallel_env", "raw_env", "state_scalars"]


class MultiRobotExploreEnv(EpisodeHooks, ReplayCopies, ParallelEnv):
    """The sonar exploration env for a team of ``n_robots``; the module docstring is its
    manual.

    Snapshots for explorers and datasets: :meth:`robot_map`, :meth:`fused_map`,
    :meth:`scanned_map`, :meth:`teammate_map`, :meth:`merge_state`; ground truth:
    :meth:`true_transform`; the global state for centralised critics: :meth:`state`,
    :attr:`state_space`.

    Live internals for metrics, tests and rendering (valid after ``reset``, changed in place by
    every step; read, never modify): ``world``
    (:class:`~envs.explore.worlds.World`), ``robots``, ``sonars``, ``maps``
    (per-robot :class:`~envs.explore.mapping.RobotMap`), ``shared`` (robot 0's
    fused map, :class:`~envs.explore.mapping.SharedMap`), ``views`` (who is in
    contact and what each robot holds of the others' maps,
    :class:`~envs.explore.comm.TeamViews`), ``oracle``
    (:class:`~envs.explore.mapping.OracleCoverage`), ``frames`` (each robot's map
    frame → world, ``fusion.Rigid2D``), ``true_merge`` (the true robot-1 → robot-0 frame
    transform), ``merge`` (the last ``MergeResult``), ``steps``, ``n_robots``.

    The env pickles and deep-copies, before and after ``reset``; a copy continues exactly as
    the original would. A copy replays the episode since ``reset`` (manual, Copies), so
    restoring one takes about as long as those steps took.
    """

    metadata = {
        "name": "multi_robot_explore_v0",
        "render_modes": ["human", "rgb_array"],
        "render_fps": 10,
        "is_parallelizable": True,
    }

    two_robot = False
    """The ``two_robot_explore_v0`` layout: one ``teammate`` observation (5,) instead of
    ``teammates`` (N − 1, 7), and no ``contacts``/``fused_robots`` infos."""

    def __init__(self, config: EnvConfig | None = None, *, render_mode: str | None = None,
                 **kwargs: Any) -> None:
        if config is not None and not isinstance(config, EnvConfig):
            raise TypeError(f"config must be an EnvConfig or None, got {type(config).__name__}")
        if config is None:
            config = EnvConfig.from_kwargs(**kwargs)
        elif kwargs:
            config = config.replace(**kwargs)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']} or None, "
                f"got {render_mode!r}"
            )
        self._setup(config, render_mode, None)

    # ------------------------------------------------------------------ spaces
    def observation_space(self, agent: str) -> spaces.Space:
        """The observation space of ``agent`` (the same object every call)."""
        try:
            return self._observation_spaces[agent]
        except KeyError:
            raise ValueError(f"agent must be one of {self.possible_agents}, got "
                             f"{agent!r}") from None

    def action_space(self, agent: str) -> spaces.Space:
        """The action space of ``agent`` (the same object every call)."""
        try:
            return self._action_spaces[agent]
        except KeyError:
            raise ValueError(f"agent must be one of {self.possible_agents}, got "
                             f"{agent!r}") from None

    @property
    def max_cycles(self) -> int:
        """Truncation step count (settable, as PettingZoo's test suite does)."""
        return self._max_cycles

    @max_cycles.setter
    def max_cycles(self, value: int) -> None:
        self.config = self.config.replace(max_cycles=value)
        self._max_cycles = self.config.max_cycles
        if self._history is not None:  # replayed by copies at this step
            self._history.max_cycles_changes.append((self.steps, self._max_cycles))

    @property
    def merge(self) -> Any:
        """The last merge call's result (``None`` before the first; :meth:`merge_state`)."""
        self._require_reset()
        return self._merging.result

    @property
    def world(self) -> World:
        """The current episode's world (after ``reset``)."""
        self._require_reset()
        return self._world

    # ------------------------------------------------------------------ reset
    def reset(self, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict, dict]:
        """Start an episode; ``seed`` re-creates the env's one ``numpy.random.Generator``.

        Raises:
            TypeError, ValueError: a ``seed`` that is not ``None`` or an integer ``>= 0``, bad
                ``options`` or start poses; the env is then left with no episode.
        """
        self._ready = False  # a reset that raises leaves no episode (manual, Starting State)
        self.agents = []
        self._history = None
        seed = check_seed(seed)
        starts = parse_reset_options(options, self.n_robots, self.metadata["name"])
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        self._begin(starts)
        if self.render_mode == "human":
            self.render()
        return self._observe(), self._infos()

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Advance every robot one step (``robot.dt`` seconds); see the manual."""
        self._require_reset()
        if not self.agents:
            raise RuntimeError(
                "step() called after the episode ended (all agents terminated or truncated); "
                "call reset() to start a new episode")
        self._advance(parse_actions(actions, self.agents, self.possible_agents,
                                    self.config.action_type))
        rewards = self._rewards()
        terminations = self._terminations()
        truncations = self._truncations()
        observations = self._observe()
        infos = self._infos()
        if any(terminations.values()) or any(truncations.values()):
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def _require_reset(self) -> None:
        if not self._ready:
            raise RuntimeError("call reset() before step(), render() or world")

    # ------------------------------------------------------------------ infos
    def true_transform(self, i: int, j: int) -> Rigid2D:
        """The true transform from robot ``j``'s map frame into robot ``i``'s (their start
        poses; the same object for the whole episode)."""
        return self._truths[i][j]

    def merge_errors(self) -> tuple[float, float]:
        """Rotation error (degrees) and translation error (metres, at the centroid of the
        teammate's map) of the merge transforms in use in robot 0's fused map against ground
        truth, the largest over its teammates; NaN when it has none; drift-aware with odometry
        noise (:func:`envs.explore.infos.merge_errors`)."""
        return merge_errors(self.shared.members, self.robots, self._truths[0], self._merging,
                            self.views, self._merging.noise > 0.0 or self._graph is not None)

    # ------------------------------------------------------------------ snapshots, state
    def robot_map(self, agent: str) -> RobotMapSnapshot:
        """``agent``'s own maps now: a read-only
        :class:`~envs.explore.mapping.RobotMapSnapshot` (a copy of its occupancy
        grid, its topological map, odometry) that later steps never change. With
        ``mapping.pose_graph`` the grid is its working map: its submaps at the graph's
        corrections, pinned at its newest anchor (:meth:`scanned_map`: as scanned).

        What map-planning explorers read (manual, Infos); the copy is taken on the first call
        of a step and shared by that step's later calls.
        """
        self._require_reset()
        i = self._index(agent, "agent")
        snap = self._snapshots[i]
        if snap is None:
            snap = RobotMapSnapshot.of(self.maps[i], self.robots[i].odometry, self.steps)
            self._snapshots[i] = snap
        return snap

    def fused_map(self, agent: str) -> FusedMapSnapshot:
        """``agent``'s fused map now, in its own odometry frame: a read-only
        :class:`~envs.explore.mapping.FusedMapSnapshot` (cell states, resolution, origin, the
        robots it holds, the step) that later steps never change.

        Its own grid with the maps of its fused teammates moved in by the rigid transforms in
        use (``merge_state().frames``), or with ``mapping.pose_graph`` its component's submaps
        composed at their corrections (maps that bend). What a robot believes the building is,
        to plan on or to judge merges by; taken on the first call of a step and shared by
        that step's later calls, and reading it changes nothing in the env.

        Raises:
            ValueError: ``agent`` is not one of ``possible_agents``.
        """
        self._require_reset()
        i = self._index(agent, "agent")
        snap = self._fused_snapshots[i]
        if snap is None:
            snap = FusedMapSnapshot.of(self._fused_states(i), self.maps[i].geometry,
                                       sorted(self._merging.frames[i]), self.steps)
            self._fused_snapshots[i] = snap
        return snap

    def scanned_map(self, agent: str) -> FusedMapSnapshot:
        """``agent``'s map as its scans made it, at its odometry, uncorrected: a read-only
        :class:`~envs.explore.mapping.FusedMapSnapshot` holding only itself. With
        ``mapping.pose_graph`` its submaps added up without the graph's corrections — under
        drift the bent map its working map (:meth:`robot_map`) is straightened from; without,
        its own map. For comparison and figures; reading it changes nothing.

        Raises:
            ValueError: ``agent`` is not one of ``possible_agents``.
        """
        self._require_reset()
        i = self._index(agent, "agent")
        own = self.maps[i]
        states = (own.states.copy() if self._graph is None else
                  own.grid.model.classify(self._graph.scanned_log_odds(i, self.maps)))
        return FusedMapSnapshot.of(states, own.geometry, [i], self.steps)

    def _index(self, agent: str, name: str) -> int:
        try:
            return self.possible_agents.index(agent)
        except ValueError:
            raise ValueError(f"{name} must be one of {self.possible_agents}, got "
                             f"{agent!r}") from None

    def teammate_map(self, agent: str, teammate: str) -> RobotMapSnapshot | None:
        """``teammate``'s map as ``agent`` knows it (manual, Communication): a read-only
        :class:`~envs.explore.mapping.RobotMapSnapshot` of its live map while the
        two are in contact, of the copy from their last contact after that (``step`` says
        when), ``None`` if they never were in contact. ``teammate == agent``: its own map."""
        self._require_reset()
        i, j = self._index(agent, "agent"), self._index(teammate, "teammate")
        if self.views.in_contact(i, j):
            return self.robot_map(teammate)
        view = self.views.view(i, j)
        if view is None:
            return None
        return RobotMapSnapshot.of(view, self.views.odometry(i, j, []), int(self.views.seen[i, j]))

    def merge_state(self) -> MergeState:
        """The merge state now (:class:`MergeState`: the robot-1 → robot-0 transform in use,
        what supplied it, the last merge result, counts, the last merge call's wall time; each
        pair's state, each robot's fused map and frames, the contacts; with
        ``mapping.pose_graph`` its ``bending`` measures against the truth)."""
        self._require_reset()
        state = self._merging.state(self.views, self.shared.transform)
        if self._graph is not None:
            state = dataclasses.replace(state, bending=self._graph.bending(
                self.maps, self._walls, self.views))
        return state

    def state(self) -> np.ndarray:
        """The global state for centralised critics: a ``(state_scalars(N) + 3 ·
        STATE_MAP_SIZE²,)`` float32 vector in :attr:`state_space` (manual, State)."""
        self._require_reset()
        return self._state.vector([r._pose() for r in self.robots], self.oracle, self.shared,
                                  self.steps, self._max_cycles)

    # ------------------------------------------------------------------ render, close
    def render(self) -> np.ndarray | None:
        """``"rgb_array"``: an ``(H, W, 3)`` uint8 image; ``"human"``: draw to a window."""
        if self.render_mode is None:
            gymnasium.logger.warn(
                "You are calling render method without specifying any render mode. "
                "Pass render_mode='rgb_array' or 'human' to the env.")
            return None
        self._require_reset()
        if self._renderer is None:
            from envs.explore.render import Renderer

            self._renderer = Renderer(self.render_mode, self.metadata["render_fps"])
        return self._renderer.draw(self)

    def close(self) -> None:
        """Close the render window, if any."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


class TwoRobotExploreEnv(MultiRobotExploreEnv):
    """``two_robot_explore_v0``: the team of two (``n_robots`` must be 2) with the layout its
    users rely on — one ``teammate`` observation (5,) and no ``contacts``/``fused_robots``
    infos; everything else is :class:`MultiRobotExploreEnv` (the manual)."""

    metadata = {**MultiRobotExploreEnv.metadata, "name": "two_robot_explore_v0"}
    two_robot = True


def parallel_env(config: EnvConfig | None = None, *, render_mode: str | None = None,
                 **kwargs: Any) -> TwoRobotExploreEnv:
    """The native ``ParallelEnv`` of ``two_robot_explore_v0`` (arguments: see the manual's
    Arguments table)."""
    return TwoRobotExploreEnv(config, render_mode=render_mode, **kwargs)


raw_env = TwoRobotExploreEnv
"""The unwrapped two-robot env class (native parallel; there is no separate AEC
implementation)."""


def env(config: EnvConfig | None = None, *, render_mode: str | None = None,
        **kwargs: Any) -> AECEnv:
    """The AEC version: PettingZoo's ``parallel_to_aec`` (order-enforcing) around
    :func:`parallel_env`."""
    return parallel_to_aec(parallel_env(config, render_mode=render_mode, **kwargs))


def multi_parallel_env(config: EnvConfig | None = None, *, render_mode: str | None = None,
                       **kwargs: Any) -> MultiRobotExploreEnv:
    """The native ``ParallelEnv`` of ``multi_robot_explore_v0`` (``n_robots`` 2–8; arguments:
    see the manual's Arguments table)."""
    return MultiRobotExploreEnv(config, render_mode=render_mode, **kwargs)


def multi_env(config: EnvConfig | None = None, *, render_mode: str | None = None,
              **kwargs: Any) -> AECEnv:
    """The AEC version of :func:`multi_parallel_env`."""
    return parallel_to_aec(multi_parallel_env(config, render_mode=render_mode, **kwargs))
