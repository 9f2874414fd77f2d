"""Robots: Pioneer3-DX-like differential-drive discs in pymunk, and their odometry.

:func:`build_space` makes a fresh ``pymunk.Space`` for an episode (walls from the world's
segments, one dynamic disc per robot, contacts counted), and :class:`Robot` wraps one disc: it
turns a ``(v, ω)`` command into body velocities before each physics substep, and keeps the
robot's odometry in its own start frame, erring as :attr:`RobotConfig.odometry_model` says
(:func:`sample_odometry`). :meth:`Robot.odometry_frame` is where that frame has drifted to in the
world. The physics is stepped once per substep for the whole space (never per robot).
"""

from __future__ import annotations

import math

import numpy as np
import pymunk

from envs.explore.config import RobotConfig
from fusion.rigid import Rigid2D

MOTOR_FORCE = 2000.0
"""Newtons (and newton-metres) the wheels can exert on the 10 kg disc: full speed in ~4 ms."""

WALL_COLLISION_TYPE = 100
"""``collision_type`` of wall segments; robot ``i`` has ``collision_type = i + 1``."""


class Robot:
    """One differential-drive disc.

    Attributes:
        index: its index in the team, 0 … N − 1.
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
                 "odometry", "collisions", "travelled", "_v", "_w", "_last_true", "_noise",
                 "_alphas")

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
        self._noise = cfg.odometry_noise
        # the rot1-trans-rot2 model's alphas, None when that model is off or noise-free
        self._alphas = (cfg.odometry_alphas if cfg.odometry_model == "rot_trans_rot"
                        and any(cfg.odometry_alphas) else None)

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

    def odometry_frame(self) -> Rigid2D:
        """The transform from the robot's current odometry frame to the world: true pose ∘
        odometry⁻¹. With perfect odometry it is the start pose (the map frame); with drift it
        moves, and the frame in which the robot's *current* surroundings are mapped right is
        this one, so the drift-aware truth of a merge of robot ``j``'s map onto robot ``i``'s
        is ``robots[i].odometry_frame().inverse() @ robots[j].odometry_frame()``
        (:func:`envs.explore.drift.drift_aware_truth`)."""
        x, y, th = self._pose()
        ox, oy, oth = self.odometry.tolist()
        return Rigid2D(th, (x, y)) @ Rigid2D(oth, (ox, oy)).inverse()

    def update_odometry(self, noise: tuple[float, float] | None,
                        rng: np.random.Generator) -> None:
        """Integrate this step's true motion, seen in the robot frame, into :attr:`odometry`.

        Model ``"increment"`` (``noise``: ``RobotConfig.odometry_noise``, ``None`` = the
        robot's config's): the increment ``(dx, dy, dθ)`` (robot frame at the step's start)
        gets Gaussian noise with standard deviation ``noise[0] · |d|`` on translation and
        ``noise[1] · |dθ| + noise[1] · 0.1 · |d|`` on rotation. Model ``"rot_trans_rot"``: the
        increment is read through :func:`sample_odometry` with the config's alphas (``noise``
        must then be ``None`` or zero). Noise-free (the default), the odometry is the true
        pose expressed in the start frame and ``rng`` is not drawn from; otherwise each step
        draws three standard normals from ``rng``.
        """
        if noise is None:
            noise = self._noise
        if self._alphas is not None:
            self._update_rot_trans_rot(rng)
            return
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

    def _update_rot_trans_rot(self, rng: np.random.Generator) -> None:
        """:meth:`update_odometry` for the ``"rot_trans_rot"`` model."""
        x, y, th = self._pose()
        px, py, pth = self._last_true
        self._last_true = x, y, th
        self.travelled += math.hypot(x - px, y - py)
        rot1, trans, rot2 = sample_odometry((px, py, pth), (x, y, th), self._alphas, rng)
        ox, oy, oth = self.odometry.tolist()
        heading = oth + rot1
        th = heading + rot2
        self.odometry[0] = ox + trans * math.cos(heading)
        self.odometry[1] = oy + trans * math.sin(heading)
        self.odometry[2] = math.atan2(math.sin(th), math.cos(th))


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def sample_odometry(before: tuple[float, float, float], after: tuple[float, float, float],
                    alphas: tuple[float, float, float, float],
                    rng: np.random.Generator) -> tuple[float, float, float]:
    """An odometry reading ``(rot1, trans, rot2)`` of the true motion ``before → after``
    (poses ``(x, y, heading)``): the rot1-trans-rot2 model of Thrun, Burgard and Fox,
    *Probabilistic Robotics* (2005), table 5.6, ``sample_motion_model_odometry``, read the way
    ROS ``amcl``'s ``diff`` odometry model reads it (the alphas weigh variances):

    ``rot1 − ε(α1·rot1² + α2·trans²)``, ``trans − ε(α3·trans² + α4·rot1² + α4·rot2²)``,
    ``rot2 − ε(α1·rot2² + α2·trans²)``, ``ε(v)`` a zero-mean normal of variance ``v``
    (three standard normals from ``rng``, always drawn). As in ``amcl`` a step backwards
    (``rot1`` near ±π) has its rotation noise measured from π, and a turn in place
    (``trans = 0``) has ``rot1 = 0``. Applied once per env step (``RobotConfig.dt``), so the
    drift over a path depends on the step length as it does for a filter's update period.
    """
    a1, a2, a3, a4 = alphas
    dx, dy = after[0] - before[0], after[1] - before[1]
    trans = math.hypot(dx, dy)
    rot1 = _wrap(math.atan2(dy, dx) - before[2]) if trans > 0.0 else 0.0
    rot2 = _wrap(after[2] - before[2] - rot1)
    r1 = min(abs(rot1), math.pi - abs(rot1))
    r2 = min(abs(rot2), math.pi - abs(rot2))
    t2 = trans * trans
    n = rng.standard_normal(3)
    return (rot1 - math.sqrt(a1 * r1 * r1 + a2 * t2) * float(n[0]),
            trans - math.sqrt(a3 * t2 + a4 * (r1 * r1 + r2 * r2)) * float(n[1]),
            rot2 - math.sqrt(a1 * r2 * r2 + a2 * t2) * float(n[2]))


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


def simulate(space: pymunk.Space, robots: list[Robot], dt: float, substeps: int
             ) -> list[int]:
    """Advance the whole space by ``dt`` in ``substeps`` fixed substeps (HighwayEnv style);
    returns the contacts each robot began meanwhile (the growth of its ``collisions``)."""
    before = [robot.collisions for robot in robots]
    h = dt / substeps
    for _ in range(substeps):
        for robot in robots:
            robot.drive()
        space.step(h)
    return [robot.collisions - b for robot, b in zip(robots, before, strict=True)]
