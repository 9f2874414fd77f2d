"""A scan's ray casts in one compiled call into chipmunk (numba), where the platform allows it.

Each sonar ray is chipmunk's ``cpSpaceSegmentQueryFirst`` — the function pymunk's
``Space.segment_query_first`` wraps. Called through pymunk's cffi binding, every call still
converts its arguments and result in Python (≈ 0.6 µs of a 0.75 µs cast); :func:`cast_rays`
loops over a scan's rays in compiled code and calls the C function directly, by its address.

The function takes two structs by value (``cpVect`` start and end, ``cpShapeFilter``), which
numba cannot declare. On the System V x86-64 and AAPCS64 calling conventions (Linux and macOS on
x86-64 and ARM64) a ``cpVect`` (two doubles) travels in two floating-point registers and a
``cpShapeFilter`` (16 bytes: a ``uintptr_t`` group, two 32-bit masks) in two integer
registers — exactly as two doubles and two 64-bit integers would — so the call is declared
that way (:func:`_query_first`). :data:`AVAILABLE` is ``True`` only on those platforms and when
the struct layouts are the ones assumed (checked at import), and :func:`usable` adds a check on
first use that the compiled casts find what pymunk's binding finds in a small scene; elsewhere
(e.g. Windows, which passes 16-byte structs by reference) the sonar keeps the cffi loop. Tests
check both against pymunk's public query, bit for bit.
"""

from __future__ import annotations

import functools
import math
import platform
import sys

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic
from pymunk._chipmunk_cffi import ffi, lib


def _layout_as_assumed() -> bool:
    """The struct sizes and offsets :func:`cast_rays` reads (double-precision chipmunk)."""
    return (ffi.sizeof("cpFloat") == 8 and ffi.sizeof("cpVect") == 16
            and ffi.sizeof("cpShapeFilter") == 16 and ffi.sizeof("cpSegmentQueryInfo") == 48
            and ffi.offsetof("cpSegmentQueryInfo", "normal") == 24
            and ffi.offsetof("cpSegmentQueryInfo", "alpha") == 40)


AVAILABLE = (sys.platform.startswith(("linux", "darwin"))
             and platform.machine().lower() in ("x86_64", "amd64", "aarch64", "arm64")
             and _layout_as_assumed())
"""Whether :func:`cast_rays` may be used here (module docstring)."""

QUERY_FIRST = int(ffi.cast("uintptr_t", ffi.addressof(lib, "cpSpaceSegmentQueryFirst")))
"""The address of ``cpSpaceSegmentQueryFirst``."""


def address(cdata) -> int:
    """The address of a cffi pointer (a ``cpSpace *``) as an integer."""
    return int(ffi.cast("uintptr_t", cdata))


def filter_words(shape_filter) -> np.ndarray:
    """A ``pymunk.ShapeFilter`` as the two 64-bit words of its ``cpShapeFilter`` struct."""
    struct = ffi.new("cpShapeFilter *", tuple(shape_filter))
    return np.frombuffer(ffi.buffer(struct), dtype=np.uint64).copy()


@intrinsic
def _query_first(typingctx, fn, space, sx, sy, ex, ey, radius, group, masks, info):
    """``cpSpaceSegmentQueryFirst(space, (sx, sy), (ex, ey), radius, filter, info)`` at address
    ``fn``, the structs passed as their registers (module docstring); returns the hit shape's
    address (0: none)."""
    sig = types.uintp(types.uintp, types.uintp, types.float64, types.float64, types.float64,
                      types.float64, types.float64, types.uint64, types.uint64, types.uintp)

    def codegen(context, builder, signature, args):
        i64, f64 = ir.IntType(64), ir.DoubleType()
        fnty = ir.FunctionType(i64, [i64, f64, f64, f64, f64, f64, i64, i64, i64])
        return builder.call(builder.inttoptr(args[0], fnty.as_pointer()), args[1:])

    return sig, codegen


@njit(cache=True, nogil=True)
def cast_rays(fn, space, x, y, ends, group, masks, info, alpha, nx, ny):
    """Cast a ray from ``(x, y)`` to each row of ``ends`` in the space at address ``space``
    (filter words ``group``, ``masks``; ``info``: 6 float64, the ``cpSegmentQueryInfo``
    written by each query): per ray the hit fraction ``alpha`` (``inf``: no hit) and the
    surface normal ``(nx, ny)`` (0 without a hit), as ``Sonar._cast``."""
    out = info.ctypes.data
    for i in range(ends.shape[0]):
        if _query_first(fn, space, x, y, ends[i, 0], ends[i, 1], 0.0, group, masks, out) == 0:
            alpha[i] = math.inf
            nx[i] = 0.0
            ny[i] = 0.0
        else:
            alpha[i] = info[5]
            nx[i] = info[3]
            ny[i] = info[4]


@functools.cache
def usable() -> bool:
    """:data:`AVAILABLE`, and on first call :func:`cast_rays` checked against chipmunk called
    through pymunk's binding on rays at a wall and a disc, hit and missed (once per process)."""
    if not AVAILABLE:
        return False
    import pymunk

    space = pymunk.Space()
    space.add(pymunk.Segment(space.static_body, (1.0, -1.0), (1.2, 1.0), 0.0))
    disc = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
    disc.position = (-1.0, 0.5)
    space.add(disc, pymunk.Circle(disc, 0.3))
    angles = np.linspace(-math.pi, math.pi, 13)
    ends = np.stack([3.0 * np.cos(angles), 0.1 + 3.0 * np.sin(angles)], axis=1)
    shape_filter = pymunk.ShapeFilter()
    info = ffi.new("cpSegmentQueryInfo *")
    flt = ffi.new("cpShapeFilter *", tuple(shape_filter))[0]
    want = []
    for e in ends:
        hit = lib.cpSpaceSegmentQueryFirst(space._space, (0.0, 0.1), tuple(e), 0.0, flt, info)
        want.append((math.inf, 0.0, 0.0) if hit == ffi.NULL
                    else (info.alpha, info.normal.x, info.normal.y))
    got = np.empty((3, len(ends)))
    words = filter_words(shape_filter)
    cast_rays(QUERY_FIRST, address(space._space), 0.0, 0.1, ends, words[0], words[1],
              np.zeros(6), got[0], got[1], got[2])
    return bool(np.array_equal(got.T, np.array(want)) and np.isfinite(got[0]).sum() >= 2)
