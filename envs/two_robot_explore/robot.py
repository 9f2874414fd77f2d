"""Robots: Pioneer3-DX-like differential-drive discs in pymunk, and their odometry.

:func:`build_space` makes a fresh ``pymunk.Space`` for an episode (walls from the world's
segments, one dynamic disc per robot, contacts counted), and :class:`Robot` wraps one disc: it
turns a ``(v, ω)`` command into body velocities before each physics substep, and keeps the
robot's odometry in its own start frame. The physics is stepped once per substep for the whole
space (never per robot).
"""

from __future__ import annotations

import math

import numpy as np
import pymunk

from envs.two_robot_explore.config import RobotConfig

MOTOR_FORCE = 2000.0
"""Newtons (and newton-metres) the wheels can exert on the 10 kg disc: full speed in ~4 ms."""

WALL_COLLISION_TYPE = 100
"""``collision_type`` of wall segments; robot ``i`` has ``collision_type = i + 1``."""


class Robot:
    """One differential-drive disc.

    Attributes:
        index: 0 or 1.
        body, shape: the pymunk dynamic body and its circle.
        sensor_filter: a ``ShapeFilter`` for pymunk queries that skips this robot's own disc (a
            ray starting inside the disc would hit it at ``alpha = 0``) but sees walls and the
            teammate: what the env's ray caster does for this robot's sonar.
        start: ``(x, y, heading)`` true start pose in the world frame.
        odometry: ``(x, y, heading)`` estimated pose in the robot's own start frame (the frame
            of its maps).
        collisions: contacts begun so far this episode.
        travelled: metres driven this episode (true).
    """

    __slots__ = ("index", "body", "shape", "motor", "joints", "sensor_filter", "start",
                 "odometry", "collisions", "travelled", "_v", "_w", "_last_true")

    def __init__(self, index: int, start: np.ndarray, cfg: RobotConfig) -> None:
        self.index = index
        bit = 1 << (index + 1)
        mass = 10.0
        self.body = pymunk.Body(mass, pymunk.moment_for_circle(mass, 0.0, cfg.radius))
        self.body.position = (float(start[0]), float(start[1]))
        self.body.angle = float(start[2])
        self.shape = pymunk.Circle(self.body, cfg.radius)
        self.shape.friction = 0.0
        self.shape.elasticity = 0.0
        self.shape.collision_type = index + 1
        self.shape.filter = pymunk.ShapeFilter(categories=bit)
        # The wheels: a kinematic "motor" body carrying the commanded velocity, coupled to the
        # disc by force-limited velocity joints (pymunk's top-down tank pattern), so contacts
        # always win and a robot driving into a wall stops at it instead of sinking in.
        self.motor = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        self.motor.position = self.body.position
        pivot = pymunk.PivotJoint(self.motor, self.body, (0.0, 0.0), (0.0, 0.0))
        pivot.max_bias = 0.0
        pivot.max_force = MOTOR_FORCE
        gear = pymunk.GearJoint(self.motor, self.body, 0.0, 1.0)
        gear.error_bias = 0.0
        gear.max_bias = 0.0
        gear.max_force = MOTOR_FORCE
        self.joints = (pivot, gear)
        self.sensor_filter = pymunk.ShapeFilter(mask=pymunk.ShapeFilter.ALL_MASKS() ^ bit)
        self.start = np.array(start, dtype=np.float64)
        self.odometry = np.zeros(3)
        self.collisions = 0
        self.travelled = 0.0
        self._v = 0.0
        self._w = 0.0
        self._last_true = tuple(self.start.tolist())  # true pose at the last odometry update

    def command(self, v: float, w: float) -> None:
        """Set the forward speed ``v`` (m/s) and turn rate ``w`` (rad/s) for the next step."""
        self._v = v
        self._w = w

    def drive(self) -> None:
        """Apply the command to the motor body (called before every physics substep)."""
        a = self.body.angle
        self.motor.velocity = (self._v * math.cos(a), self._v * math.sin(a))
        self.motor.angular_velocity = self._w

    def true_pose(self) -> np.ndarray:
        """``(x, y, heading)`` in the world frame, heading wrapped to ``(-pi, pi]``."""
        return np.array(self._pose())

    def _pose(self) -> tuple[float, float, float]:
        """:meth:`true_pose` as a tuple of floats."""
        p = self.body.position
        a = self.body.angle
        return p.x, p.y, math.atan2(math.sin(a), math.cos(a))

    def update_odometry(self, noise: tuple[float, float], rng: np.random.Generator) -> None:
        """Integrate this step's true motion, seen in the robot frame, into :attr:`odometry`.

        The increment ``(dx, dy, dθ)`` (robot frame at the step's start) gets Gaussian noise
        with standard deviation ``noise[0] · |d|`` on translation and
        ``noise[1] · |dθ| + noise[1] · 0.1 · |d|`` on rotation; with ``noise = (0, 0)`` the
        odometry is the true pose expressed in the start frame.
        """
        # Python floats throughout (the same IEEE arithmetic as numpy scalars, less overhead)
        x, y, th = self._pose()
        px, py, pth = self._last_true
        self._last_true = x, y, th
        dxw, dyw = x - px, y - py
        c, s = math.cos(pth), math.sin(pth)
        dx, dy = c * dxw + s * dyw, -s * dxw + c * dyw
        dth = math.atan2(math.sin(th - pth), math.cos(th - pth))
        dist = math.hypot(dx, dy)
        self.travelled += dist
        if noise[0] > 0.0 or noise[1] > 0.0:
            n = rng.standard_normal(3)
            dx += noise[0] * dist * n[0]
            dy += noise[0] * dist * n[1]
            dth += noise[1] * (abs(dth) + 0.1 * dist) * n[2]
        ox, oy, oth = self.odometry.tolist()
        c, s = math.cos(oth), math.sin(oth)
        th = oth + dth
        self.odometry[0] = ox + c * dx - s * dy
        self.odometry[1] = oy + s * dx + c * dy
        self.odometry[2] = math.atan2(math.sin(th), math.cos(th))


def start_frame_pose(start: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """``pose`` (world frame) expressed in the frame whose origin/heading is ``start``."""
    c, s = math.cos(start[2]), math.sin(start[2])
    dx, dy = pose[0] - start[0], pose[1] - start[1]
    th = pose[2] - start[2]
    return np.array([c * dx + s * dy, -s * dx + c * dy, math.atan2(math.sin(th), math.cos(th))])


def build_space(segments: np.ndarray, robots: list[Robot]) -> pymunk.Space:
    """A fresh space: zero gravity, no damping, 10 solver iterations, 2 mm collision slop, walls,
    robots, and a contact counter (each contact that begins adds one to every robot it involves)."""
    space = pymunk.Space()
    space.gravity = (0.0, 0.0)
    space.damping = 1.0
    space.iterations = 10
    space.collision_slop = 0.002  # metres of allowed overlap (pymunk's default 0.1 is 10 cm)
    _add_walls(space, segments)
    for robot in robots:
        space.add(robot.body, robot.shape, robot.motor, *robot.joints)
    by_type = {r.shape.collision_type: r for r in robots}

    def count_contact(arbiter: pymunk.Arbiter, _space: pymunk.Space, _data: object) -> None:
        for shape in arbiter.shapes:
            robot = by_type.get(shape.collision_type)
            if robot is not None:
                robot.collisions += 1

    space.on_collision(None, None, begin=count_contact)
    return space


def _add_walls(space: pymunk.Space, segments: np.ndarray) -> None:
    static = space.static_body
    walls = []
    for x0, y0, x1, y1 in segments.tolist():
        seg = pymunk.Segment(static, (x0, y0), (x1, y1), 0.0)
        seg.friction = 0.0
        seg.elasticity = 0.0
        seg.collision_type = WALL_COLLISION_TYPE
        walls.append(seg)
    space.add(*walls)


def simulate(space: pymunk.Space, robots: list[Robot], dt: float, substeps: int) -> None:
    """Advance the whole space by ``dt`` in ``substeps`` fixed substeps (HighwayEnv style)."""
    h = dt / substeps
    for _ in range(substeps):
        for robot in robots:
            robot.drive()
        space.step(h)
