"""Rendering with pygame-ce (the ``render`` extra): four panels in one frame.

Top left, the world: free space, what the team has truly seen (tinted), the wall segments,
every robot with its sonar cones drawn out to each reading. Top right, the shared map in
robot 0's frame with the merged topological map (once a merge is accepted). Bottom, robot 0's
and robot 1's own occupancy grids and topological maps, each in its own frame (in a larger
team the others' own maps are not drawn).

pygame is imported here, never at package import; without it rendering raises an
``ImportError`` that names the extra to install. ``"rgb_array"`` needs no display;
``"human"`` opens a window (set ``SDL_VIDEODRIVER=dummy`` to run headless).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from envs.explore.mapping import Geometry

if TYPE_CHECKING:
    from envs.explore.env import TwoRobotExploreEnv

PANEL = 320
"""Side of one panel in pixels (the frame is 2 × 2 panels)."""

ROBOT_COLOURS = ((220, 60, 40), (40, 100, 220), (40, 160, 70), (200, 150, 20),
                 (150, 60, 190), (20, 170, 170), (200, 60, 140), (110, 110, 110))
"""One colour per robot (``robot_0`` … ``robot_7``)."""
STATE_COLOURS = np.array([[150, 150, 150], [255, 255, 255], [20, 20, 20]], dtype=np.uint8)
"""Panel colour of each cell state: unknown grey, free white, occupied black."""

KIND_COLOURS = ((230, 140, 0), (160, 0, 160), (0, 150, 90), (200, 30, 30))
"""Node colour per ``topo.NodeKind``: junction orange, dead end purple, corner green, gateway
red (a frontier node is drawn hollow)."""


def _import_pygame():
    try:
        import pygame
    except ImportError as exc:
        raise ImportError(
            "rendering two_robot_explore needs pygame-ce: pip install 'topomerge[render]'"
        ) from exc
    return pygame


class _View:
    """Maps metres of a rectangle ``(x0, y0, x1, y1)`` onto a square panel (y up)."""

    def __init__(self, box: tuple[float, float, float, float], offset: tuple[int, int]) -> None:
        x0, y0, x1, y1 = box
        span = max(x1 - x0, y1 - y0, 1e-6)
        self.scale = (PANEL - 8) / span
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        self.x0 = cx - span / 2
        self.y1 = cy + span / 2
        self.off = offset

    def px(self, x: float, y: float) -> tuple[int, int]:
        return (int(self.off[0] + 4 + (x - self.x0) * self.scale),
                int(self.off[1] + 4 + (self.y1 - y) * self.scale))


class Renderer:
    """Draws a :class:`TwoRobotExploreEnv` (``mode`` ``"human"`` or ``"rgb_array"``)."""

    def __init__(self, mode: str, fps: int) -> None:
        self.pygame = _import_pygame()
        self.mode = mode
        self.fps = fps
        pg = self.pygame
        self.surface = pg.Surface((2 * PANEL, 2 * PANEL))
        self.window = None
        self.clock = None
        pg.font.init()
        self.font = pg.font.Font(None, 18)
        if mode == "human":
            pg.display.init()
            self.window = pg.display.set_mode((2 * PANEL, 2 * PANEL))
            pg.display.set_caption("two_robot_explore_v0")
            self.clock = pg.time.Clock()

    # ------------------------------------------------------------------ helpers
    def _blit_cells(self, rgb: np.ndarray, geom: Geometry, rows: slice, cols: slice,
                    view: _View) -> None:
        """Blit an ``(h, w, 3)`` image of cells ``[rows, cols]`` of ``geom`` (row 0 bottom)."""
        pg = self.pygame
        if rgb.size == 0:
            return
        img = pg.surfarray.make_surface(np.ascontiguousarray(rgb[::-1].transpose(1, 0, 2)))
        x0 = geom.origin[0] + cols.start * geom.resolution
        y0 = geom.origin[1] + rows.start * geom.resolution
        x1 = geom.origin[0] + cols.stop * geom.resolution
        y1 = geom.origin[1] + rows.stop * geom.resolution
        a = view.px(x0, y1)
        b = view.px(x1, y0)
        size = (max(b[0] - a[0], 1), max(b[1] - a[1], 1))
        self.surface.blit(pg.transform.scale(img, size), a)

    def _draw_graph(self, topo, view: _View, transform=None) -> None:
        pg = self.pygame
        if topo is None or topo.n_nodes == 0:
            return
        xy = topo.xy if transform is None else transform.apply(topo.xy)
        pts = [view.px(x, y) for x, y in xy.tolist()]
        if topo.paths is not None:
            for path in topo.paths:
                line = path if transform is None else transform.apply(path)
                pg.draw.lines(self.surface, (0, 120, 200), False,
                              [view.px(x, y) for x, y in line.tolist()], 2)
        else:
            for u, v in topo.edges.tolist():
                pg.draw.line(self.surface, (0, 120, 200), pts[u], pts[v], 2)
        for p, k, f in zip(pts, topo.kinds.tolist(), topo.frontier.tolist(), strict=True):
            pg.draw.circle(self.surface, KIND_COLOURS[k], p, 4, width=1 if f else 0)

    def _label(self, text: str, pos: tuple[int, int]) -> None:
        self.surface.blit(self.font.render(text, True, (0, 0, 0), (255, 255, 255)), pos)

    # ------------------------------------------------------------------ panels
    def _world_panel(self, env: TwoRobotExploreEnv) -> None:
        pg = self.pygame
        world = env.world
        view = _View(world.extent, (0, 0))
        g = Geometry(world.origin, world.resolution, world.shape)
        rgb = np.full(world.shape + (3,), 110, dtype=np.uint8)
        rgb[world.free] = 255
        rgb[env.oracle.union & world.free] = (255, 236, 170)
        h, w = world.shape
        self._blit_cells(rgb, g, slice(0, h), slice(0, w), view)
        for x0, y0, x1, y1 in world.segments.tolist():
            pg.draw.line(self.surface, (0, 0, 0), view.px(x0, y0), view.px(x1, y1), 2)
        for i, (robot, sonar) in enumerate(zip(env.robots, env.sonars, strict=True)):
            pose = robot.true_pose()
            origins = sonar.origins(pose)
            half = math.radians(sonar.cfg.cone) / 2
            colour = tuple(min(255, c + 60) for c in ROBOT_COLOURS[i])
            for (ox, oy), a, r in zip(origins.tolist(), sonar.angles.tolist(),
                                      sonar.last.tolist(), strict=True):
                th = pose[2] + a
                cone = [view.px(ox, oy)] + [
                    view.px(ox + r * math.cos(th + d), oy + r * math.sin(th + d))
                    for d in (-half, 0.0, half)]
                pg.draw.polygon(self.surface, colour, cone, 1)
            centre = view.px(pose[0], pose[1])
            rad = max(int(env.config.robot.radius * view.scale), 3)
            pg.draw.circle(self.surface, ROBOT_COLOURS[i], centre, rad)
            tip = view.px(pose[0] + 1.5 * env.config.robot.radius * math.cos(pose[2]),
                          pose[1] + 1.5 * env.config.robot.radius * math.sin(pose[2]))
            pg.draw.line(self.surface, (0, 0, 0), centre, tip, 2)
        self._label(f"world  step {env.steps}  true coverage {env.oracle.fraction:.0%}", (4, 4))

    def _map_panel(self, env: TwoRobotExploreEnv, i: int, offset: tuple[int, int]) -> None:
        rmap = env.maps[i]
        win = rmap.known_window()
        if win is not None:
            rows, cols = win
            g = rmap.geometry
            box = (g.origin[0] + cols.start * g.resolution, g.origin[1] + rows.start * g.resolution,
                   g.origin[0] + cols.stop * g.resolution, g.origin[1] + rows.stop * g.resolution)
            view = _View(box, offset)
            self._blit_cells(STATE_COLOURS[rmap.states[win]], g, rows, cols, view)
            self._draw_graph(rmap.topomap, view)
            odo = env.robots[i].odometry
            self.pygame.draw.circle(self.surface, ROBOT_COLOURS[i], view.px(odo[0], odo[1]), 5)
        self._label(f"robot_{i} map (own frame)  {rmap.n_ever * rmap.geometry.resolution ** 2:.0f}"
                    f" m2", (offset[0] + 4, offset[1] + 4))

    def _shared_panel(self, env: TwoRobotExploreEnv, offset: tuple[int, int]) -> None:
        m0 = env.maps[0]
        members = env.shared.members
        fused = env._fused_window(0)
        if fused is None:
            return
        g = m0.geometry
        (rows, cols), states = fused
        box = (g.origin[0] + cols.start * g.resolution, g.origin[1] + rows.start * g.resolution,
               g.origin[0] + cols.stop * g.resolution, g.origin[1] + rows.stop * g.resolution)
        view = _View(box, offset)
        self._blit_cells(STATE_COLOURS[states], g, rows, cols, view)
        merge = env.merge
        if env._graph is not None:
            pass  # maps that bend: no one rigid frame carries the topological maps onto it
        elif (len(members) == 1 and merge is not None and merge.accepted
                and getattr(merge, "merged", None) is not None):
            self._draw_graph(merge.merged, view)  # the last merge fused the two graphs
        else:  # each graph moved by its transform in use
            self._draw_graph(m0.topomap, view)
            for j, (to_0, _) in sorted(members.items()):
                self._draw_graph(env.views.view(0, j).topomap, view, to_0)
        n = len(members) + 1
        status = f"{n} of {env.n_robots} robots merged" if members else "not merged"
        self._label(f"fused map (robot_0 frame), {status}", (offset[0] + 4, offset[1] + 4))

    # ------------------------------------------------------------------ frame
    def draw(self, env: TwoRobotExploreEnv) -> np.ndarray | None:
        """Draw one frame; the image for ``"rgb_array"``, ``None`` for ``"human"``."""
        pg = self.pygame
        self.surface.fill((235, 235, 235))
        self._world_panel(env)
        self._shared_panel(env, (PANEL, 0))
        self._map_panel(env, 0, (0, PANEL))
        self._map_panel(env, 1, (PANEL, PANEL))
        for k in (1, 2):
            pg.draw.line(self.surface, (90, 90, 90), (0, PANEL), (2 * PANEL, PANEL), k)
            pg.draw.line(self.surface, (90, 90, 90), (PANEL, 0), (PANEL, 2 * PANEL), k)
        if self.mode == "human":
            pg.event.pump()
            self.window.blit(self.surface, (0, 0))
            pg.display.flip()
            self.clock.tick(self.fps)
            return None
        return np.ascontiguousarray(pg.surfarray.array3d(self.surface).transpose(1, 0, 2))

    def close(self) -> None:
        """Close the window (human mode)."""
        if self.window is not None:
            self.pygame.display.quit()
            self.window = None
