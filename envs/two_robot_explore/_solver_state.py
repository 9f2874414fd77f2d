"""The solver state chipmunk carries from one step to the next that pymunk's pickling leaves out,
read and written so that a pickled or copied env steps exactly as the original.

pymunk pickles bodies (position, velocity, forces...), shapes, joints (their settings) and the
cached contacts with their impulses, but not two things the next step uses:

* each body's **bias velocity** ``v_bias``, ``w_bias``: the solver's position correction of
  a step, integrated into the position at the start of the next step (non-zero after a robot
  pressed into a wall);
* each joint's **accumulated impulse** ``jAcc``: the warm start of the next step's solve (the
  robots' motor joints always work).

Neither has an accessor, so they are read from chipmunk's structs at their offsets in chipmunk
7.0 (double-precision ``cpFloat``, 64-bit pointers: ``cpBody.v_bias`` at byte 192, ``w_bias``
at 208, ``cpPivotJoint.jAcc`` at 200, ``cpGearJoint.jAcc`` at 144). :func:`usable` checks on
first use that these offsets hold what the structs' accessors and a step say they hold; where
they do not (another build of chipmunk), :func:`read` gives ``None`` and a restored env may
drift from the original after a contact (it still runs).
"""

from __future__ import annotations

import functools
import math
from typing import Any

import pymunk
from pymunk._chipmunk_cffi import ffi, lib

BODY_V_BIAS = 192
"""Byte offset of ``cpBody.v_bias`` (``cpVect``; ``w_bias``, a ``cpFloat``, follows)."""
PIVOT_J_ACC = 200
"""Byte offset of ``cpPivotJoint.jAcc`` (``cpVect``)."""
GEAR_J_ACC = 144
"""Byte offset of ``cpGearJoint.jAcc`` (``cpFloat``)."""
_JOINT_SETTINGS = 104
"""Byte offset of the first field after ``cpConstraint`` (the pivot's ``anchorA``, the gear's
``phase``), where :func:`usable` checks the layout."""


def _doubles(cdata: Any, offset: int) -> Any:
    """The ``double`` array starting ``offset`` bytes into the struct ``cdata`` points to."""
    return ffi.cast("double *", ffi.cast("char *", cdata) + offset)


def _slots(item: Any) -> tuple[int, int]:
    """``(offset, count)`` of the solver state doubles of a body or a joint."""
    if isinstance(item, pymunk.Body):
        return BODY_V_BIAS, 3
    if isinstance(item, pymunk.PivotJoint):
        return PIVOT_J_ACC, 2
    if isinstance(item, pymunk.GearJoint):
        return GEAR_J_ACC, 1
    raise TypeError(f"solver state is kept for bodies, pivot and gear joints, got "
                    f"{type(item).__name__}")


def _handle(item: Any) -> Any:
    return item._body if isinstance(item, pymunk.Body) else item._constraint


def read(items: tuple[Any, ...]) -> tuple[float, ...] | None:
    """The solver state of ``items`` (bodies, pivot and gear joints) as plain floats, ``None``
    where :func:`usable` is False."""
    return _read(items) if usable() else None


def write(items: tuple[Any, ...], values: tuple[float, ...] | None) -> None:
    """Put ``values`` (from :func:`read` of the same kinds of items) into ``items``; nothing
    for ``None``."""
    if values is not None and usable():
        _write(items, values)


def _read(items: tuple[Any, ...]) -> tuple[float, ...]:
    out: list[float] = []
    for item in items:
        offset, n = _slots(item)
        raw = _doubles(_handle(item), offset)
        out += [raw[i] for i in range(n)]
    return tuple(out)


def _write(items: tuple[Any, ...], values: tuple[float, ...]) -> None:
    k = 0
    for item in items:
        offset, n = _slots(item)
        raw = _doubles(_handle(item), offset)
        for i in range(n):
            raw[i] = values[k]
            k += 1
    if k != len(values):
        raise ValueError(f"values must hold {k} numbers for these items, got {len(values)}")


@functools.cache
def usable() -> bool:
    """Whether the offsets are chipmunk's here (checked once per process): a body's fields
    around ``v_bias`` read as its accessors say, a bias velocity written there moves the body
    in the next step and is cleared by it, and the joints' settings and impulses read as their
    accessors say after a step in which they work."""
    if ffi.sizeof("cpFloat") != 8 or ffi.sizeof("void *") != 8:
        return False
    body = pymunk.Body(2.0, 3.0)
    body.position = (1.5, -2.5)
    body.velocity = (0.75, -0.5)
    body.force = (7.0, 8.0)
    body.angle = 0.25
    body.angular_velocity = 0.625
    body.torque = 0.875
    raw = _doubles(body._body, 0)
    if [raw[i] for i in (2, 4, 8, 9, 10, 11, 12, 13, 14, 15, 16)] != [
            2.0, 3.0, 1.5, -2.5, 0.75, -0.5, 7.0, 8.0, 0.25, 0.625, 0.875]:
        return False
    space = pymunk.Space()
    space.add(body)
    body.velocity, body.angular_velocity, body.force, body.torque = (0.0, 0.0), 0.0, (0, 0), 0.0
    _write((body,), (1.0, 0.5, 0.5))
    space.step(1.0)
    if (tuple(body.position) != (2.5, -2.0) or body.angle != 0.75
            or _read((body,)) != (0.0, 0.0, 0.0)):
        return False
    motor = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
    pivot = pymunk.PivotJoint(motor, body, (0.25, 0.5), (-0.75, 0.125))
    gear = pymunk.GearJoint(motor, body, 0.375, 1.5)
    anchors = _doubles(pivot._constraint, _JOINT_SETTINGS)
    settings = _doubles(gear._constraint, _JOINT_SETTINGS)
    if ([anchors[i] for i in range(4)] != [0.25, 0.5, -0.75, 0.125]
            or [settings[0], settings[1]] != [0.375, 1.5]):
        return False
    space.add(motor, pivot, gear)
    motor.velocity, motor.angular_velocity = (1.0, 0.5), 1.0
    space.step(0.1)
    jx, jy, jg = _read((pivot, gear))
    return bool(jx and jg and math.sqrt(jx * jx + jy * jy) == lib.cpConstraintGetImpulse(
        pivot._constraint) and abs(jg) == lib.cpConstraintGetImpulse(gear._constraint))
