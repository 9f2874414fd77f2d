"""Typed, frozen, validated configuration of ``two_robot_explore`` (STYLE.md §8).

Four groups — :class:`WorldConfig`, :class:`RobotConfig`, :class:`SonarConfig`,
:class:`MappingConfig` — and the top-level :class:`EnvConfig` that holds them with the reward
and episode settings. Every field is checked in ``__post_init__``; every error names the field
(``sonar.max_range``), the bad value and what is allowed. :meth:`EnvConfig.from_kwargs` builds a
config from keyword arguments (nested groups as dicts) and refuses unknown keys.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fusion.decision import DEFAULT_ACCEPT_THRESHOLD, TEAM_ACCEPT_THRESHOLD
from topo.grid import SensorModel
from topo.validation import check_int, check_real, config_from

REWARD_MODES = ("shared", "oracle", "individual")
"""``EnvConfig.reward_mode`` values (see the env manual, section Rewards)."""

ACTION_TYPES = ("continuous", "discrete")
"""``EnvConfig.action_type`` values."""

MERGE_METHODS = ("hybrid", "auto", "paper_icp", "exhaustive", "multistart_icp", "known", "none")
"""``MappingConfig.merge_method`` values: ``"hybrid"`` (``fusion.hybrid.hybrid_merge``: the
structural merge, then the occupancy-grid alignment), a ``fusion.merge_maps`` method,
``"known"`` (the robots know their relative start poses: no merging, the true transforms) or
``"none"`` (never merges: each robot alone)."""


def _check_choice(value: object, name: str, allowed: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in allowed:
        raise ValueError(f"{name} must be one of {list(allowed)}, got {value!r}")
    return value


def _check_pair(value: object, name: str, *, low: float,
                low_inclusive: bool = False) -> tuple[float, float]:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise TypeError(f"{name} must be a pair of numbers, got {value!r}")
    a = check_real(value[0], f"{name}[0]", low=low, low_inclusive=low_inclusive)
    b = check_real(value[1], f"{name}[1]", low=low, low_inclusive=low_inclusive)
    return (a, b)


def _check_optional_real(value: object, name: str, **bounds: Any) -> float | None:
    return None if value is None else check_real(value, name, **bounds)


def _check_bool(value: object, name: str) -> bool:
    if not isinstance(value, bool):
        raise TypeError(f"{name} must be True or False, got {value!r}")
    return value


def _set(obj: object, name: str, value: object) -> None:
    object.__setattr__(obj, name, value)


def _extract_config(value: object) -> Any:
    """``mapping.topo`` as a ``topo.ExtractConfig``: ``None`` (the defaults), a config, or a
    dict of its fields (errors name ``mapping.topo``)."""
    from topo.extract import ExtractConfig

    try:
        return config_from(ExtractConfig, value, "mapping.topo")
    except ValueError as exc:
        if str(exc).startswith("mapping.topo"):
            raise
        # a bad field value: ExtractConfig names the field, not where it was given
        raise ValueError(f"mapping.topo: {exc}") from exc


@dataclass(frozen=True, slots=True)
class WorldConfig:
    """Where the robots are: a seeded procedural building or a real map file.

    Attributes:
        source: ``"procedural"`` or a path to a map file: ROS map ``.yaml`` (+ PGM), DungeonMaps
            ``.png`` (scale from ``png_resolution``), HouseExpo-style ``.json``
            (``{"verts": [[x, y], ...]}`` in metres).
        size: procedural building width and height in metres, each ``>= 6``.
        resolution: cell size of the world grid in metres (procedural and JSON worlds).
        png_resolution: metres per pixel of PNG maps (DungeonMaps give none; 0.05–0.1 is typical),
            at most 0.5 (as ``resolution``).
        room_size: procedural ``(min, max)`` room side in metres.
        corridor_prob: chance that a procedural row/column of rooms is a corridor (1.4–2 m wide).
        door_width: procedural door width in metres (must let a robot through).
        loop_prob: chance of an extra door between rooms already connected (makes loops).
        obstacle_density: procedural furniture boxes per 10 m² of room floor.
        wall_thickness: procedural wall thickness in metres.
        start_clearance: minimum free distance around a start position, metres, ``>=`` the robot
            radius.
        min_start_separation: minimum distance between two start positions, metres, ``>=``
            twice the robot radius (the env refuses teams that cannot start this far apart:
            ``envs.explore.feasibility``).
    """

    source: str = "procedural"
    size: tuple[float, float] = (20.0, 20.0)
    resolution: float = 0.1
    png_resolution: float = 0.1
    room_size: tuple[float, float] = (3.0, 6.0)
    corridor_prob: float = 0.25
    door_width: float = 1.0
    loop_prob: float = 0.3
    obstacle_density: float = 0.5
    wall_thickness: float = 0.2
    start_clearance: float = 0.45
    min_start_separation: float = 2.0

    def __post_init__(self) -> None:
        if isinstance(self.source, Path):
            _set(self, "source", str(self.source))
        if not isinstance(self.source, str) or not self.source:
            raise TypeError(
                f"world.source must be 'procedural' or a map file path, got {self.source!r}"
            )
        if self.source != "procedural":
            suffix = Path(self.source).suffix.lower()
            if suffix not in (".yaml", ".yml", ".png", ".json"):
                raise ValueError(
                    f"world.source must be 'procedural' or a .yaml/.png/.json map file, "
                    f"got {self.source!r}"
                )
        _set(self, "size", _check_pair(self.size, "world.size", low=6.0, low_inclusive=True))
        _set(self, "resolution", check_real(self.resolution, "world.resolution", low=0.01,
                                            low_inclusive=True, high=0.5))
        _set(self, "png_resolution", check_real(self.png_resolution, "world.png_resolution",
                                                low=0.0, high=0.5))
        rs = _check_pair(self.room_size, "world.room_size", low=0.0)
        if not 2.0 <= rs[0] <= rs[1]:
            raise ValueError(f"world.room_size must satisfy 2 <= min <= max, got {rs}")
        _set(self, "room_size", rs)
        for name in ("corridor_prob", "loop_prob"):
            _set(self, name, check_real(getattr(self, name), f"world.{name}", low=0.0,
                                        low_inclusive=True, high=1.0))
        _set(self, "door_width", check_real(self.door_width, "world.door_width", low=0.0))
        _set(self, "obstacle_density", check_real(self.obstacle_density,
                                                  "world.obstacle_density", low=0.0,
                                                  low_inclusive=True, high=2.0))
        _set(self, "wall_thickness", check_real(self.wall_thickness, "world.wall_thickness",
                                                low=0.0))
        _set(self, "start_clearance", check_real(self.start_clearance, "world.start_clearance",
                                                 low=0.0))
        _set(self, "min_start_separation", check_real(self.min_start_separation,
                                                      "world.min_start_separation",
                                                      low=0.0, low_inclusive=True))


ODOMETRY_MODELS = ("increment", "rot_trans_rot")
"""``RobotConfig.odometry_model`` values."""

ODOMETRY_PRESETS = {"pioneer3dx": (0.05 ** 2, 0.01 ** 2, 0.03 ** 2, 0.01 ** 2)}
"""Named ``RobotConfig.odometry_alphas``. ``"pioneer3dx"``: Stage's default odometry error for
its differential-drive ("like a Pioneer") position model, ``odom_error [0.03 0.03 0.00 0.05]``
(Stage 3.1 manual, Position model: proportions of error in x, y, z and heading), as the
rot1-trans-rot2 model's variances — a 5 % standard deviation of each rotation (α1 = 0.05²) and
3 % of each translation (α3 = 0.03²) — plus the cross terms Stage lacks, 0.01 rad per metre
driven and 0.01 m per radian turned (α2 = α4 = 0.01²)."""


def _check_alphas(value: object) -> tuple[float, float, float, float]:
    """``robot.odometry_alphas``: four numbers ``>= 0`` or a preset name."""
    if isinstance(value, str):
        if value not in ODOMETRY_PRESETS:
            raise ValueError(f"robot.odometry_alphas must be four numbers >= 0 or one of "
                             f"{sorted(ODOMETRY_PRESETS)}, got {value!r}")
        return ODOMETRY_PRESETS[value]
    if isinstance(value, bytes) or not hasattr(value, "__len__") or len(value) != 4:
        raise TypeError(f"robot.odometry_alphas must be four numbers >= 0 or one of "
                        f"{sorted(ODOMETRY_PRESETS)}, got {value!r}")
    return tuple(check_real(a, f"robot.odometry_alphas[{i}]", low=0.0, low_inclusive=True,
                            high=1.0)
                 for i, a in enumerate(value))


@dataclass(frozen=True, slots=True)
class RobotConfig:
    """A Pioneer3-DX-like differential-drive disc.

    Attributes:
        radius: disc radius, metres.
        max_speed: forward speed at action ``v = 1``, m/s.
        max_turn_rate: turn rate at action ``ω = 1``, degrees per second.
        dt: seconds of simulated time per env step.
        substeps: physics substeps per env step (fixed).
        odometry_model: how odometry errs (:data:`ODOMETRY_MODELS`): ``"increment"``, Gaussian
            noise on each step's increment scaled by ``odometry_noise``; ``"rot_trans_rot"``,
            the rot1-trans-rot2 model of Thrun et al., *Probabilistic Robotics* (2005),
            table 5.6 (``sample_motion_model_odometry``), scaled by ``odometry_alphas``
            (``envs.explore.robot.sample_odometry``).
        odometry_noise: ``(translation, rotation)`` relative standard deviations of the
            ``"increment"`` model (``0`` = perfect odometry).
        odometry_alphas: ``(α1, α2, α3, α4)`` of the ``"rot_trans_rot"`` model, each ``>= 0``
            (variances: rotation from rotation, rotation from translation, translation from
            translation, translation from rotation), or the name of a preset of
            :data:`ODOMETRY_PRESETS` (``"pioneer3dx"``), stored as its four numbers.
        drift_correction: correct the odometry against the robot's own map by scan-to-map
            matching (``envs.explore.localize``); only with noisy odometry.
            Experimental, off: it did not reduce these robots' drift (``docs/notes/drift.md``).
        drift_correction_every: steps between two matches.
        drift_correction_window: steps of sonar echoes in a match's submap.
        drift_correction_age: the match's reference is the walls occupied this many steps ago.
        drift_correction_sigma: metres; the match's information is ``JᵀJ / sigma²``.
    """

    radius: float = 0.25
    max_speed: float = 0.7
    max_turn_rate: float = 100.0
    dt: float = 0.1
    substeps: int = 4
    odometry_model: str = "increment"
    odometry_noise: tuple[float, float] = (0.0, 0.0)
    odometry_alphas: tuple[float, float, float, float] | str = (0.0, 0.0, 0.0, 0.0)
    drift_correction: bool = False
    drift_correction_every: int = 25
    drift_correction_window: int = 150
    drift_correction_age: int = 300
    drift_correction_sigma: float = 3.0

    def __post_init__(self) -> None:
        _set(self, "radius", check_real(self.radius, "robot.radius", low=0.0, high=2.0))
        _set(self, "max_speed", check_real(self.max_speed, "robot.max_speed", low=0.0,
                                           high=10.0))
        _set(self, "max_turn_rate", check_real(self.max_turn_rate, "robot.max_turn_rate",
                                               low=0.0, high=1000.0))
        _set(self, "dt", check_real(self.dt, "robot.dt", low=0.0, high=1.0))
        _set(self, "substeps", check_int(self.substeps, "robot.substeps", low=1))
        _set(self, "odometry_model", _check_choice(self.odometry_model, "robot.odometry_model",
                                                   ODOMETRY_MODELS))
        _set(self, "odometry_noise", _check_pair(self.odometry_noise, "robot.odometry_noise",
                                                 low=0.0, low_inclusive=True))
        _set(self, "odometry_alphas", _check_alphas(self.odometry_alphas))
        if self.odometry_model == "increment" and any(self.odometry_alphas):
            raise ValueError(
                f"robot.odometry_alphas apply to robot.odometry_model 'rot_trans_rot' only, got "
                f"{self.odometry_alphas} with odometry_model 'increment'"
            )
        if self.odometry_model == "rot_trans_rot" and any(self.odometry_noise):
            raise ValueError(
                f"robot.odometry_noise applies to robot.odometry_model 'increment' only, got "
                f"{self.odometry_noise} with odometry_model 'rot_trans_rot' (use "
                f"robot.odometry_alphas)"
            )
        _check_bool(self.drift_correction, "robot.drift_correction")
        for name in ("every", "window", "age"):
            key = f"drift_correction_{name}"
            _set(self, key, check_int(getattr(self, key), f"robot.{key}", low=1))
        _set(self, "drift_correction_sigma", check_real(
            self.drift_correction_sigma, "robot.drift_correction_sigma", low=0.0))
        step = self.max_speed * self.dt / self.substeps
        if step > self.radius:
            raise ValueError(
                f"robot.substeps must keep a substep's travel ({step:.3f} m) below "
                f"robot.radius ({self.radius} m) so the robot cannot tunnel through walls"
            )


PIONEER_SONAR_DEG = (-90.0, -50.0, -30.0, -10.0, 10.0, 30.0, 50.0, 90.0)
"""The Pioneer 3 front sonar ring, degrees CCW from the heading."""


@dataclass(frozen=True, slots=True)
class SonarConfig:
    """The sonar ring (see the manual, section Sensors).

    Attributes:
        angles: sensor directions, degrees CCW from the heading (the Pioneer front ring).
        cone: full cone width, degrees.
        rays: rays per cone (evenly spread across it; ``1`` = a single central ray).
        min_range: shortest range reported, metres (closer echoes read as this).
        max_range: longest range, metres; a reading ``>= max_range`` means "no echo".
        noise_std: standard deviation of the Gaussian range noise, metres.
        dropout_incidence: incidence angle (degrees from the wall normal) beyond which an echo
            may be lost to specular reflection.
        dropout_prob: probability of losing such a steep echo.
        measure_every: ``None`` measures every step; a distance in metres measures only after the
            robot has travelled that far (the paper's robots used 0.10 m).
    """

    angles: tuple[float, ...] = PIONEER_SONAR_DEG
    cone: float = 15.0
    rays: int = 3
    min_range: float = 0.15
    max_range: float = 5.0
    noise_std: float = 0.01
    dropout_incidence: float = 60.0
    dropout_prob: float = 0.5
    measure_every: float | None = None

    def __post_init__(self) -> None:
        if isinstance(self.angles, (str, bytes)) or not hasattr(self.angles, "__len__"):
            raise TypeError(f"sonar.angles must be a sequence of degrees, got {self.angles!r}")
        if not 1 <= len(self.angles) <= 32:
            raise ValueError(
                f"sonar.angles must hold 1 to 32 directions, got {len(self.angles)}"
            )
        _set(self, "angles", tuple(check_real(a, f"sonar.angles[{i}]", low=-360.0,
                                              low_inclusive=True, high=360.0)
                                   for i, a in enumerate(self.angles)))
        _set(self, "cone", check_real(self.cone, "sonar.cone", low=0.0, low_inclusive=True,
                                      high=90.0))
        _set(self, "rays", check_int(self.rays, "sonar.rays", low=1))
        if self.rays > 16:
            raise ValueError(f"sonar.rays must be <= 16, got {self.rays}")
        _set(self, "min_range", check_real(self.min_range, "sonar.min_range", low=0.0,
                                           low_inclusive=True))
        _set(self, "max_range", check_real(self.max_range, "sonar.max_range", low=0.0,
                                           high=50.0))
        if self.min_range >= self.max_range:
            raise ValueError(
                f"sonar.min_range must be < sonar.max_range ({self.max_range}), "
                f"got {self.min_range}"
            )
        _set(self, "noise_std", check_real(self.noise_std, "sonar.noise_std", low=0.0,
                                           low_inclusive=True))
        _set(self, "dropout_incidence", check_real(self.dropout_incidence,
                                                   "sonar.dropout_incidence", low=0.0,
                                                   low_inclusive=True, high=90.0))
        _set(self, "dropout_prob", check_real(self.dropout_prob, "sonar.dropout_prob", low=0.0,
                                              low_inclusive=True, high=1.0))
        _set(self, "measure_every", _check_optional_real(self.measure_every,
                                                         "sonar.measure_every", low=0.0))


@dataclass(frozen=True, slots=True)
class MappingConfig:
    """Mapping and fusion in the loop.

    Attributes:
        grid_resolution: cell size of each robot's occupancy grid, metres.
        usable_range: sonar readings longer than this (metres, from the robot's centre) only
            free the cone up to it and mark no wall (``topo.SensorModel.usable_range``;
            ``None`` uses every reading in full). Far readings are where a lost echo reads
            through a wall and a wide arc closes a doorway (the choice of 2.5 m:
            ``docs/notes/fusion.md``).
        topo_every: re-extract each robot's topological map every this many steps (``0`` never).
        topo: settings of the extraction (``topo.ExtractConfig``, or a dict of its fields;
            ``None`` for its defaults).
        merge_every: merge the two topological maps every this many steps (``0`` never).
        merge_method: ``"hybrid"`` (default), a ``fusion.merge_maps`` method, ``"known"``
            (every pair's true start-frame transform from the first step: the known-poses
            baseline) or ``"none"`` (:data:`MERGE_METHODS`).
        grid_merge_every: with ``"hybrid"``, the (slower) occupancy-grid alignment
            runs on merge steps that are multiples of this: to find a merge, and once one is in
            use to re-examine it (replace or drop it, see the env's manual); ``0`` never. A
            multiple of ``merge_every`` (unused when ``merge_every`` is 0 and with
            ``pose_graph``).
        topo_growth: an extraction due waits until the robot's map knows this fraction more
            cells than at its last extraction (the same map gives the same graph; a structural
            merge of two unchanged graphs is skipped likewise). ``0`` extracts on schedule.
        grid_merge_growth: after a grid alignment, the next one waits (beyond
            ``grid_merge_every``) until the two robots' maps together know this fraction more
            cells: the same maps would only give the same answer. ``0`` runs on schedule.
        accept_threshold: with ``"hybrid"``, a merge is accepted only when its calibrated
            confidence (probability that the transform is right) reaches this, in ``[0, 1]``;
            default ``fusion.decision.DEFAULT_ACCEPT_THRESHOLD`` (0.9).
        local_map_size: side of the egocentric ``local_map`` observation, cells (``>= 64``).
        local_map_resolution: metres per ``local_map`` cell.
        max_nodes: graph nodes in the observation (nearest first; padded with a mask).
        cycle_check: with three or more robots, keep only pairwise merges that the cycles
            they close agree with (``fusion.team.consistent_edges``); ``False`` uses the
            pairwise decisions alone (for ablations). No effect with two robots.
        team_accept_threshold: with three or more robots and ``cycle_check``, a pairwise
            merge that no consistent triangle confirms is used only at this confidence or more
            (a team has many pairs, so many chances of one confident look-alike), in
            ``[0, 1]``. No effect with two robots.
        first_merge_check: with ``"hybrid"``, a pair's first merge (no transform in use, also
            after a drop) from the structural merge also needs the grids' own alignment to be
            the same one at ``accept_threshold`` (``fusion.hybrid.hybrid_merge``'s ``vouch``):
            early maps that share no place let a room row fit its twin. ``False`` merges
            sooner in large buildings, with look-alikes (``docs/notes/fusion.md``).
        pose_graph: experimental (issue 41), ``False`` changes nothing: each robot's map is
            a chain of anchored submaps in a ``fusion.PoseGraph`` (GTSAM, the ``slam``
            extra), robots' local windows are aligned into inter-robot links and loop
            closures, and each fused map (the coverage reward's) is its robots' submaps
            rendered at their optimised poses (:mod:`envs.explore.graph_merging`). The
            rigid pair merges (``merge_method``) then do not run.
        anchor_every: with ``pose_graph``, a robot starts a new anchor (submap) every this
            many steps: a few metres of travel, short enough that a submap is rigid.
        window_anchors: with ``pose_graph``, how many consecutive anchors make a local
            window that is aligned as one rigid grid.
        window_searches: with ``pose_graph``, window alignments each robot tries per merge
            step (each a ``fusion.grid_merge.merge_grids`` or a search near the graph's
            estimate): a budget per robot, so the pairs still to join do not starve a
            robot's loop closures. Two: the graph averages its alignments' noise, so with
            drifting odometry two a step make straighter fused maps than one (about 12 % more
            time a step); perfect odometry merges the same. A robot has at most one
            candidate of each kind a merge step — each teammate it has still to join, its
            nearest older window for a loop closure, the nearest window of each joined
            teammate — so in a team of two, more than 2 changes nothing.
    """

    grid_resolution: float = 0.1
    usable_range: float | None = 2.5
    topo_every: int = 25
    topo_growth: float = 0.02
    topo: Any = None
    merge_every: int = 25
    merge_method: str = "hybrid"
    grid_merge_every: int = 100
    grid_merge_growth: float = 0.2
    accept_threshold: float = DEFAULT_ACCEPT_THRESHOLD
    local_map_size: int = 64
    local_map_resolution: float = 0.15
    max_nodes: int = 32
    cycle_check: bool = True
    team_accept_threshold: float = TEAM_ACCEPT_THRESHOLD
    first_merge_check: bool = True
    pose_graph: bool = False
    anchor_every: int = 100
    window_anchors: int = 4
    window_searches: int = 2

    def __post_init__(self) -> None:
        _set(self, "grid_resolution", check_real(self.grid_resolution,
                                                 "mapping.grid_resolution", low=0.02,
                                                 low_inclusive=True, high=0.5))
        if self.usable_range is not None:
            _set(self, "usable_range", check_real(self.usable_range, "mapping.usable_range",
                                                  low=0.0))
        _set(self, "topo_every", check_int(self.topo_every, "mapping.topo_every", low=0))
        _set(self, "topo", _extract_config(self.topo))
        _set(self, "merge_every", check_int(self.merge_every, "mapping.merge_every", low=0))
        _check_choice(self.merge_method, "mapping.merge_method", MERGE_METHODS)
        _set(self, "grid_merge_every", check_int(self.grid_merge_every,
                                                 "mapping.grid_merge_every", low=0))
        if self.grid_merge_every and self.merge_every and not self.pose_graph and (
                self.grid_merge_every % self.merge_every):  # the pose graph aligns no grids
            raise ValueError(f"mapping.grid_merge_every must be 0 or a multiple of "
                             f"mapping.merge_every ({self.merge_every}), got "
                             f"{self.grid_merge_every}")
        _set(self, "topo_growth", check_real(self.topo_growth, "mapping.topo_growth", low=0.0,
                                             low_inclusive=True, high=10.0))
        _set(self, "grid_merge_growth", check_real(self.grid_merge_growth,
                                                   "mapping.grid_merge_growth", low=0.0,
                                                   low_inclusive=True, high=10.0))
        _set(self, "accept_threshold", check_real(self.accept_threshold,
                                                  "mapping.accept_threshold", low=0.0,
                                                  low_inclusive=True, high=1.0))
        _set(self, "local_map_size", check_int(self.local_map_size, "mapping.local_map_size",
                                               low=64))
        if self.local_map_size > 512:
            raise ValueError(f"mapping.local_map_size must be <= 512, got {self.local_map_size}")
        _set(self, "local_map_resolution", check_real(self.local_map_resolution,
                                                      "mapping.local_map_resolution", low=0.0,
                                                      high=1.0))
        _set(self, "max_nodes", check_int(self.max_nodes, "mapping.max_nodes", low=1))
        if self.max_nodes > 256:
            raise ValueError(f"mapping.max_nodes must be <= 256, got {self.max_nodes}")
        _check_bool(self.cycle_check, "mapping.cycle_check")
        _check_bool(self.first_merge_check, "mapping.first_merge_check")
        _check_bool(self.pose_graph, "mapping.pose_graph")
        if self.pose_graph and not self.merge_every:
            raise ValueError("mapping.pose_graph needs merge steps: mapping.merge_every must be "
                             "> 0 with it, got 0")
        _set(self, "anchor_every", check_int(self.anchor_every, "mapping.anchor_every",
                                             low=10))
        _set(self, "window_anchors", check_int(self.window_anchors, "mapping.window_anchors",
                                               low=2))
        _set(self, "window_searches", check_int(self.window_searches,
                                                "mapping.window_searches", low=1))
        _set(self, "team_accept_threshold", check_real(
            self.team_accept_threshold, "mapping.team_accept_threshold", low=0.0,
            low_inclusive=True, high=1.0))

    @property
    def sensor_model(self) -> SensorModel:
        """The robots' inverse sensor model: ``topo.SensorModel`` with :attr:`usable_range`."""
        return SensorModel(usable_range=self.usable_range)


@dataclass(frozen=True, slots=True)
class CommConfig:
    """Communication between robots (the env's manual, Communication).

    Attributes:
        range: two robots closer than this (metres, centre to centre) are in contact and
            exchange their maps; robots in contact with a common teammate are in contact too
            (multi-hop: the connected groups of the "in range" graph). ``None``: unlimited, all
            robots always in contact.
        line_of_sight: robots in range are in contact only if no wall lies between their
            centres (sonar-band radios through walls are lossy).
    """

    range: float | None = None
    line_of_sight: bool = False

    def __post_init__(self) -> None:
        _set(self, "range", _check_optional_real(self.range, "comm.range", low=0.0))
        _check_bool(self.line_of_sight, "comm.line_of_sight")

    @property
    def unlimited(self) -> bool:
        """Every robot always in contact (no range, no line of sight)."""
        return self.range is None and not self.line_of_sight


MAX_ROBOTS = 8
"""Largest ``EnvConfig.n_robots``."""


@dataclass(frozen=True, slots=True)
class EnvConfig:
    """Everything that defines a ``two_robot_explore`` episode (the manual's Arguments table).

    Attributes:
        world, robot, sonar, mapping, comm: the groups above.
        n_robots: robots in the team, ``2`` to :data:`MAX_ROBOTS`.
        max_cycles: truncation after this many steps.
        target_coverage: termination when the true covered fraction of the reachable free area
            reaches this, in ``(0, 1]``.
        reward_mode: ``"shared"``, ``"oracle"`` or ``"individual"``.
        coverage_reward: reward per newly covered m².
        collision_penalty: reward subtracted per new collision (robot–wall or robot–robot).
        time_penalty: reward subtracted every step.
        action_type: ``"continuous"`` (``Box(-1, 1, (2,))``) or ``"discrete"`` (5 actions).
    """

    world: WorldConfig = field(default_factory=WorldConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    sonar: SonarConfig = field(default_factory=SonarConfig)
    mapping: MappingConfig = field(default_factory=MappingConfig)
    comm: CommConfig = field(default_factory=CommConfig)
    n_robots: int = 2
    max_cycles: int = 1000
    target_coverage: float = 0.95
    reward_mode: str = "shared"
    coverage_reward: float = 0.1
    collision_penalty: float = 0.5
    time_penalty: float = 0.01
    action_type: str = "continuous"

    def __post_init__(self) -> None:
        _set(self, "world", config_from(WorldConfig, self.world, "world"))
        _set(self, "robot", config_from(RobotConfig, self.robot, "robot"))
        _set(self, "sonar", config_from(SonarConfig, self.sonar, "sonar"))
        _set(self, "mapping", config_from(MappingConfig, self.mapping, "mapping"))
        _set(self, "comm", config_from(CommConfig, self.comm, "comm"))
        _set(self, "n_robots", check_int(self.n_robots, "n_robots"))
        if not 2 <= self.n_robots <= MAX_ROBOTS:
            raise ValueError(f"n_robots must be between 2 and {MAX_ROBOTS}, got {self.n_robots}")
        _set(self, "max_cycles", check_int(self.max_cycles, "max_cycles", low=1))
        _set(self, "target_coverage", check_real(self.target_coverage, "target_coverage",
                                                 low=0.0, high=1.0))
        _check_choice(self.reward_mode, "reward_mode", REWARD_MODES)
        _set(self, "coverage_reward", check_real(self.coverage_reward, "coverage_reward",
                                                 low=0.0, low_inclusive=True))
        _set(self, "collision_penalty", check_real(self.collision_penalty, "collision_penalty",
                                                   low=0.0, low_inclusive=True))
        _set(self, "time_penalty", check_real(self.time_penalty, "time_penalty", low=0.0,
                                              low_inclusive=True))
        _check_choice(self.action_type, "action_type", ACTION_TYPES)
        if self.world.start_clearance < self.robot.radius:
            raise ValueError(
                f"world.start_clearance must be >= robot.radius ({self.robot.radius}), "
                f"got {self.world.start_clearance}"
            )
        if self.world.min_start_separation < 2 * self.robot.radius:
            raise ValueError(
                f"world.min_start_separation must be >= 2 * robot.radius "
                f"({2 * self.robot.radius} m) so robots do not start on top of each other, "
                f"got {self.world.min_start_separation}"
            )
        if self.world.source == "procedural" and self.world.door_width <= 2 * self.robot.radius:
            raise ValueError(
                f"world.door_width must be > 2 * robot.radius ({2 * self.robot.radius}) so a "
                f"robot fits through, got {self.world.door_width}"
            )

    @classmethod
    def from_kwargs(cls, **kwargs: Any) -> EnvConfig:
        """Build from keyword arguments; groups may be dicts. Unknown keys are a ``ValueError``.

        >>> EnvConfig.from_kwargs(max_cycles=50, sonar={"rays": 1}).sonar.rays
        1
        """
        allowed = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(k for k in kwargs if k not in allowed)
        if unknown:
            raise ValueError(f"unknown config keys {unknown}; allowed: {allowed}")
        return cls(**kwargs)

    def replace(self, **changes: Any) -> EnvConfig:
        """A copy with ``changes`` applied (validated like :meth:`from_kwargs`)."""
        allowed = [f.name for f in dataclasses.fields(self)]
        unknown = sorted(k for k in changes if k not in allowed)
        if unknown:
            raise ValueError(f"unknown config keys {unknown}; allowed: {allowed}")
        return dataclasses.replace(self, **changes)

    @property
    def max_turn_rate_rad(self) -> float:
        """``robot.max_turn_rate`` in radians per second."""
        return math.radians(self.robot.max_turn_rate)
