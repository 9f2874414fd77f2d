"""The private hooks of :class:`~envs.explore.env.MultiRobotExploreEnv`: what the
constructor builds from a checked config (``_setup``, ``_build_spaces``), an episode's start
(``_begin``), and the stages of a step in the order ``step()`` calls them — actions, physics,
sensing and mapping, contacts, merging, rewards, ends, observations, infos (STYLE.md: public
``step``, private hooks). ``envs/explore/env.py`` holds the manual and the public API.

A mixin: the hooks read and write the env's attributes (the env module's manual and class
docstring say what each holds); only the env class uses it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from envs.explore.actions import action_space
from envs.explore.comm import TeamViews
from envs.explore.config import EnvConfig
from envs.explore.copies import History
from envs.explore.drift import odometry_noise_level
from envs.explore.feasibility import check_feasible, draw_world_and_starts, frame_radius
from envs.explore.global_state import GlobalState, state_space
from envs.explore.graph_merging import GraphMerging
from envs.explore.infos import step_infos
from envs.explore.localize import DriftCorrector
from envs.explore.mapping import (
    FusedMapSnapshot,
    OracleCoverage,
    RobotMap,
    RobotMapSnapshot,
    SharedMap,
    fused_states,
)
from envs.explore.merging import TeamMerging
from envs.explore.observations import Observer, observation_space
from envs.explore.raycast import RayCaster
from envs.explore.robot import Robot, build_space, simulate
from envs.explore.sonar import Sonar
from envs.explore.starts import check_start_poses
from envs.explore.submaps import ScanSettings
from envs.explore.worlds import World, load_world, procedural_world
from fusion.evaluation.bending import WallIndex
from fusion.rigid import Rigid2D
from topo.grid import CellState


def agent_names(n: int) -> tuple[str, ...]:
    """The agents of an ``n``-robot team: ``robot_0 … robot_{n-1}``."""
    return tuple(f"robot_{i}" for i in range(n))


class EpisodeHooks:
    """What ``reset`` and ``step`` do inside (module docstring)."""

    def _setup(self, config: EnvConfig, render_mode: str | None,
               file_world: World | None) -> None:
        """Everything ``__init__`` builds from a checked config (a copy passes the world file
        it already loaded: ``file_world``)."""
        if self.two_robot and config.n_robots != 2:
            raise ValueError(f"n_robots must be 2 for {self.metadata['name']}, got "
                             f"{config.n_robots}; use multi_robot_explore_v0 for larger teams")
        self.config = config
        self.render_mode = render_mode
        self.n_robots = config.n_robots
        self.possible_agents = list(agent_names(config.n_robots))
        self.agents: list[str] = []
        self._max_cycles = config.max_cycles
        cfg = config
        # A world file is loaded (and validated) once, here; procedural worlds every reset.
        self._file_world = file_world
        if cfg.world.source != "procedural":
            if self._file_world is None:
                self._file_world = load_world(cfg.world, robot_radius=cfg.robot.radius)
            extent = self._file_world.extent
        else:
            extent = (0.0, 0.0, *cfg.world.size)
        check_feasible(cfg, self._file_world)  # works for every seed, or refused here
        self.frame_radius = frame_radius(cfg, extent)
        self._build_spaces()
        self.state_space = state_space(config.n_robots)
        self._observer = Observer(config, self.frame_radius, self.two_robot)
        self._rng: np.random.Generator | None = None
        self._renderer = None
        self._ready = False
        self._snapshots: list[RobotMapSnapshot | None] = [None] * config.n_robots
        self._fused_snapshots: list[FusedMapSnapshot | None] = [None] * config.n_robots
        self._history: History | None = None  # how this episode came about (Copies)

    def _build_spaces(self) -> None:
        """One observation and one action space object per agent, built once."""
        agents = self.possible_agents
        self._observation_spaces = {a: observation_space(self.config, self.frame_radius,
                                                         self.two_robot) for a in agents}
        self._action_spaces = {a: action_space(self.config.action_type) for a in agents}

    def _begin(self, starts: np.ndarray | None) -> None:
        """Build a new episode from the generator as it is now, at the given start poses
        (``None``: drawn), and start recording its history (Copies)."""
        history = History(self._rng.bit_generator.state,
                           None if starts is None else starts.copy(), self._max_cycles)
        self._ready = False  # until the episode is built (a reset that raises leaves none)
        self.agents = []
        self._history = None
        cfg = self.config
        rng = self._rng
        if starts is None:
            self._world, starts = draw_world_and_starts(cfg, rng, self._file_world)
        else:
            self._world = (self._file_world if self._file_world is not None else
                           procedural_world(cfg.world, rng, robot_radius=cfg.robot.radius))
            check_start_poses(starts, self._world, cfg.robot.radius)
        world = self._world
        n = self.n_robots
        self.robots = [Robot(i, starts[i], cfg.robot) for i in range(n)]
        self.space = build_space(world.segments, self.robots)
        self.caster = RayCaster(world.segments, cfg.robot.radius, robots=n)
        self.sonars = [Sonar(cfg.sonar, cfg.robot.radius) for _ in range(n)]
        # map frames: each robot's start; the truth frame_i -> world is its start pose
        self.frames = [Rigid2D.from_pose(s) for s in starts]
        self._truths = [[f_i.inverse() @ f_j for f_j in self.frames] for f_i in self.frames]
        self.true_merge = self._truths[0][1]
        x0, y0, x1, y1 = world.extent
        corners = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]])
        self.maps = []
        model = cfg.mapping.sensor_model
        for s in starts:
            reach = float(np.max(np.hypot(*(corners - s[:2]).T)))
            radius = min(reach + cfg.sonar.max_range + 1.0, self.frame_radius)
            self.maps.append(RobotMap((-radius, -radius, radius, radius),
                                      cfg.mapping.grid_resolution, model))
        self.shared = SharedMap(self.maps[0].geometry)
        self.oracle = OracleCoverage(world.extent, world.resolution, world.reachable, model,
                                     robots=n)
        self._world_area = world.reachable_area  # fixed for the episode (a full-grid count)
        noise = odometry_noise_level(cfg.robot)
        self._merging = TeamMerging(n, cfg.mapping, noise, self._truths)
        self._correctors = [None] * n
        if cfg.robot.drift_correction and noise > 0.0:
            self._correctors = [
                DriftCorrector(cfg.robot, s.angles, s.mount_radius, cfg.sonar.max_range,
                               m.geometry.shape, m.geometry.origin, m.geometry.resolution)
                for s, m in zip(self.sonars, self.maps, strict=True)]
        self.views = TeamViews(self.maps, cfg.comm)
        self._graph = None  # mapping.pose_graph (issue 41): merging as a pose graph
        self._shared_incremental = True
        self._fused_truth = (0.0, 0.0)  # pose graph: robot 0's fused ATE, wall share (infos)
        if cfg.mapping.pose_graph:
            self._graph = GraphMerging(self.maps, cfg.mapping, cfg.robot, ScanSettings(
                self.sonars[0].angles, self.sonars[0].mount_radius, cfg.sonar.max_range,
                math.radians(cfg.sonar.cone) / 2.0, model))
            self._walls = WallIndex(world.segments)
        self._extracted_at = [0] * n  # known cells of each map at its last extraction
        self.steps = 0
        self._snapshots = [None] * n
        self._fused_snapshots = [None] * n
        self._state = GlobalState(world.extent, self.frames[0], self.oracle, self.shared)
        self._shared_delta = 0
        self._own_delta = [0] * n
        self._oracle_delta = 0
        self._coll_delta = [0] * n
        self._observer.reset(n)
        self.agents = list(self.possible_agents)
        self._ready = True
        self._contacts_changed = False
        self._contact(0)
        self._sense_and_map(travelled=[0.0] * n)
        self._history = history

    # ------------------------------------------------------------------ step

    def _apply_actions(self, commands: list[tuple[float, float]]) -> None:
        rcfg = self.config.robot
        w_max = math.radians(rcfg.max_turn_rate)
        for robot, (v, w) in zip(self.robots, commands, strict=True):
            robot.command(v * rcfg.max_speed, w * w_max)

    def _simulate(self) -> None:
        rcfg = self.config.robot
        self._coll_delta = simulate(self.space, self.robots, rcfg.dt, rcfg.substeps)

    def _sense_and_map(self, travelled: list[float]) -> None:
        cfg = self.config
        scfg = cfg.sonar
        half = math.radians(scfg.cone) / 2.0
        self._oracle_delta = 0
        poses = [robot.true_pose() for robot in self.robots]
        for i, pose in enumerate(poses):
            self.caster.discs[i] = pose[:2]
        if self._graph is not None:  # pose graph: anchors start before the step's scans
            self._graph.before_scans(self.steps, [r.odometry for r in self.robots], poses,
                                     self.maps)
        for i, (pose, sonar) in enumerate(zip(poses, self.sonars, strict=True)):
            sonar.measure(self.caster, pose, i, self._rng, travelled[i])
            if self._correctors[i] is not None:
                self._correctors[i].step(self.steps, self.robots[i].odometry,
                                         sonar.last if sonar.fresh else None,
                                         self.maps[i].grid.log_odds)
            if not sonar.fresh:
                self._own_delta[i] = 0
                continue
            rmap = self.maps[i]
            fresh = rmap.integrate(self.robots[i].odometry, sonar.last, sonar.angles,
                                   sonar.mount_radius, scfg.max_range, half)
            n_fresh, r0, r1, c0, c1 = fresh[:5].tolist()
            self._own_delta[i] = n_fresh
            if self._graph is not None:  # pose graph: the fused map is recomposed instead
                self._graph.add_scan(i, self.robots[i].odometry, sonar.last)
                if i == 0 and n_fresh and self._shared_incremental:
                    self._shared_delta += self.shared.add(0, rmap, (slice(r0, r1),
                                                                    slice(c0, c1)))
            elif n_fresh and (i == 0 or self.views.in_contact(0, i)):
                self._shared_delta += self.shared.add(i, rmap, (slice(r0, r1), slice(c0, c1)))
            self._oracle_delta += self.oracle.add(i, pose, sonar.true_last,
                                                  sonar.angles, sonar.mount_radius,
                                                  scfg.max_range, half)
        every = cfg.mapping.topo_every
        if every and self.steps % every == 0:
            for i, rmap in enumerate(self.maps):
                if rmap.n_ever and rmap.n_ever >= self._extracted_at[i] * (
                        1.0 + cfg.mapping.topo_growth):
                    self._extracted_at[i] = rmap.n_ever
                    rmap.extract(cfg.mapping.topo)
                    self._observer.graphs[i].refresh(rmap.topomap)

    def _contact(self, step: int) -> None:
        """Who is in contact now (before this step's odometry and scans enter the maps);
        robot 0's fused map takes in what a merged teammate met again mapped meanwhile."""
        gained, changed = self.views.update(
            step, np.array([r._pose()[:2] for r in self.robots]),
            [r.odometry for r in self.robots], self.space)
        self._contacts_changed |= changed
        for i, j in gained:
            if i == 0 and j in self.shared.members and self._graph is None:
                self._shared_delta += self.shared.add(j, self.maps[j],
                                                      self.maps[j].known_window())

    def _fuse(self) -> None:
        """Merge the pairs due; when what a robot knows changes, its fused map (robot 0's
        is rebuilt)."""
        if self._graph is not None:
            self._fuse_graph()
            return
        changed = self._merging.step(self.steps, self.views)
        if not (changed or self._contacts_changed):
            return
        self._contacts_changed = False
        centres = {i: c for i, m in enumerate(self.maps) if (c := m.known_centre()) is not None}
        if 0 in self._merging.refresh(self.views, centres):
            members = {j: f for j, f in self._merging.frames[0].items() if j != 0}
            known = {j: self.views.view(0, j) for j in (0, *members)}
            self._shared_delta += self.shared.rebuild(known, members)

    def _fuse_graph(self) -> None:
        """``mapping.pose_graph`` (issue 41): on merge steps, window alignments into the pose
        graph, every robot's fused frames and working map (its own grid, straightened) from
        it, and robot 0's fused map recomposed from the submaps (its own grid, added to step
        by step, while it holds only itself)."""
        if self.steps % self.config.mapping.merge_every:
            return
        graph = self._graph
        graph.step(self.views)
        for r in range(self.n_robots):
            self._merging.frames[r] = graph.frames(r)
            if graph.straighten(r, self.maps):  # its topological map follows at the next chance
                self._extracted_at[r] = 0
        trivial = graph.trivial(0)
        states = self.maps[0].states  # robot 0's fused map: its own grid while trivial
        if trivial and not self._shared_incremental:
            self._shared_delta += self.shared.rebuild({0: self.maps[0]}, {})
        elif not trivial:
            states = self.maps[0].grid.model.classify(
                graph.fused_log_odds(0, self.maps, self.views))
            known = states != CellState.UNKNOWN
            count = int(np.count_nonzero(known))
            self.shared.ever[...] = known
            self._shared_delta += count - self.shared.count
            self.shared.count = count
        self.shared.members = {j: f for j, f in self._merging.frames[0].items() if j != 0}
        self._shared_incremental = trivial
        ate, wall = graph.fused_truth(self.maps, self.views, self._walls, states)
        self._fused_truth = (ate, 0.0 if math.isnan(wall) else wall)

    def _fused_states(self, r: int) -> np.ndarray:
        """Robot ``r``'s fused map now (``fused_map``): ``(H, W)`` int8 cell states on its own
        grid, a new array (:meth:`_fused_window` pasted on unknown)."""
        out = np.zeros_like(self.maps[r].states)
        fused = self._fused_window(r)
        if fused is not None:
            (rows, cols), states = fused
            out[rows, cols] = states
        return out

    def _fused_window(self, r: int) -> tuple[tuple[slice, slice], np.ndarray] | None:
        """Robot ``r``'s fused map as the window of its own grid holding every known cell and
        a new int8 array of the states there (``None`` before its first scan): with the pose
        graph its component's patches composed at their corrections (its own grid while it
        has no teammate and no loop closure); else its own map with the teammates it holds
        moved in by the rigid frames in use (:func:`fused_states`). The one compositor of
        ``fused_map`` and the renderer's fused panel."""
        own = self.maps[r]
        graph = self._graph
        if graph is None:
            return fused_states(own, [(self.views.view(r, j), to_r) for j, (to_r, _)
                                      in sorted(self._merging.frames[r].items()) if j != r])
        if graph.trivial(r):
            win = own.known_window()
            return None if win is None else (win, own.states[win].copy())
        states = own.grid.model.classify(graph.fused_log_odds(r, self.maps, self.views))
        rows, cols = np.nonzero(states.any(axis=1))[0], np.nonzero(states.any(axis=0))[0]
        if not len(rows):
            return None
        win = slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)
        return win, states[win].copy()

    # ------------------------------------------------------------------ rewards, ends
    def _rewards(self) -> dict[str, float]:
        cfg = self.config
        coll = self._coll_delta
        if cfg.reward_mode == "individual":
            return {a: float(cfg.coverage_reward * self._own_delta[i]
                             * self.maps[i].geometry.resolution ** 2
                             - cfg.collision_penalty * coll[i] - cfg.time_penalty)
                    for i, a in enumerate(self.agents)}
        if cfg.reward_mode == "shared":
            gained = self._shared_delta * self.shared.geometry.resolution ** 2
        else:
            gained = self._oracle_delta * self.oracle.geometry.resolution ** 2
        r = float(cfg.coverage_reward * gained - cfg.collision_penalty * sum(coll)
                  - cfg.time_penalty)
        return dict.fromkeys(self.agents, r)

    def _terminated(self) -> bool:
        return bool(self.oracle.fraction >= self.config.target_coverage)

    def _truncated(self) -> bool:
        return self.steps >= self._max_cycles

    def _terminations(self) -> dict[str, bool]:
        return dict.fromkeys(self.agents, self._terminated())

    def _truncations(self) -> dict[str, bool]:
        return dict.fromkeys(self.agents, self._truncated())

    def _advance(self, commands: list[tuple[float, float]]) -> None:
        """One step's state change from every robot's parsed ``(v, ω)`` commands (recorded
        for copies): physics, contacts, odometry, sensing, mapping, merging; no outputs."""
        self._apply_actions(commands)
        self._simulate()
        self.steps += 1
        n = self.n_robots
        self._snapshots = [None] * n
        self._fused_snapshots = [None] * n
        self._shared_delta = 0
        self._contact(self.steps)
        travelled = [0.0] * n
        for i, robot in enumerate(self.robots):
            before = robot.travelled
            robot.update_odometry(self.config.robot.odometry_noise, self._rng)
            travelled[i] = robot.travelled - before
        self._sense_and_map(travelled)
        self._fuse()
        self._history.commands.append(commands)

    def _observe(self) -> dict[str, dict[str, np.ndarray]]:
        live = [r.odometry for r in self.robots]
        return {a: self._observe_one(i, live) for i, a in enumerate(self.possible_agents)
                if a in self.agents}

    def _observe_one(self, i: int, live: list[np.ndarray] | None = None
                     ) -> dict[str, np.ndarray]:
        """Robot ``i``'s observation (``live``: every robot's odometry now)."""
        return self._observer.observe(i, self.robots, self.sonars, self.maps,
                                      self._merging.frames, self.views, self.steps,
                                      self._max_cycles, live)

    def _infos(self) -> dict[str, dict[str, Any]]:
        """This step's infos (manual, Infos; :func:`envs.explore.infos.step_infos`)."""
        errors = self.merge_errors() if self.shared.members else (0.0, 0.0)
        return step_infos(self.agents, self.possible_agents, self.robots, self.maps,
                          self.oracle, self.shared, self._world_area, self._merging,
                          self.views, errors, not self.two_robot,
                          None if self._graph is None else self._fused_truth)
