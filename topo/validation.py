"""Input validation shared by every package: every error names the argument, the value and what
is allowed (STYLE.md §8); :func:`config_from` turns plain dicts into the frozen config
dataclasses."""

from __future__ import annotations

import dataclasses
import numbers
from collections.abc import Mapping
from typing import Any, TypeVar

import numpy as np

_NOT_ARRAYS = (str, bytes, dict, set, frozenset)

C = TypeVar("C")


def _describe(value: object) -> str:
    if isinstance(value, np.ndarray):
        return f"array of shape {value.shape} and dtype {value.dtype}"
    return type(value).__name__


def as_points(value: object, name: str, *, min_points: int = 0) -> np.ndarray:
    """Return ``value`` as a finite float64 ``(N, 2)`` array, or raise naming ``name``.

    Array-likes (lists, tuples, arrays) are accepted; strings, mappings, sets and ``None`` are a
    ``TypeError``; wrong shape, too few points or NaN/inf are a ``ValueError``.
    """
    if value is None or isinstance(value, _NOT_ARRAYS):
        raise TypeError(f"{name} must be an array of shape (N, 2), got {_describe(value)}")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"{name} must be a numeric array of shape (N, 2), got {_describe(value)}"
        ) from exc
    if arr.size == 0 and arr.ndim <= 2 and (arr.ndim < 2 or arr.shape[1] in (0, 2)):
        arr = np.empty((0, 2))
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name} must have shape (N, 2), got shape {arr.shape}")
    if arr.shape[0] < min_points:
        raise ValueError(f"{name} must have at least {min_points} points, got {arr.shape[0]}")
    if not np.isfinite(arr).all():
        row = int(np.argwhere(~np.isfinite(arr))[0, 0])
        raise ValueError(f"{name} must be finite, got {arr[row].tolist()} at row {row}")
    return arr


def check_real(value: object, name: str, *, low: float | None = None,
               low_inclusive: bool = False, high: float | None = None,
               high_inclusive: bool = True) -> float:
    """Return ``value`` as a finite float within the stated bounds, or raise naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {_describe(value)}")
    out = float(value)
    if not np.isfinite(out):
        raise ValueError(f"{name} must be finite, got {out}")
    if low is not None and (out < low or (out == low and not low_inclusive)):
        raise ValueError(f"{name} must be {'>=' if low_inclusive else '>'} {low}, got {out}")
    if high is not None and (out > high or (out == high and not high_inclusive)):
        raise ValueError(f"{name} must be {'<=' if high_inclusive else '<'} {high}, got {out}")
    return out


def check_int(value: object, name: str, *, low: int | None = None) -> int:
    """Return ``value`` as an int ``>= low``, or raise naming ``name`` (bools are refused)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {_describe(value)}")
    out = int(value)
    if low is not None and out < low:
        raise ValueError(f"{name} must be >= {low}, got {out}")
    return out


def config_from(cls: type[C], value: Any, name: str = "config") -> C:
    """``value`` as a ``cls`` config dataclass: ``None`` → the defaults, a ``cls`` as is, a
    mapping → ``cls(**value)`` (the one dict-to-config adapter of every package's configs).

    Raises:
        ValueError: a key that is not a field of ``cls`` (the message lists the allowed ones),
            or an invalid field value (``cls.__post_init__``).
        TypeError: anything else than ``None``, a ``cls`` or a mapping.
    """
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if isinstance(value, Mapping):
        allowed = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(str(k) for k in value if k not in allowed)
        if unknown:
            raise ValueError(f"{name} has unknown keys {unknown}; allowed: {allowed}")
        return cls(**value)
    raise TypeError(
        f"{name} must be a {cls.__name__}, a dict of its fields or None, got {type(value).__name__}"
    )
