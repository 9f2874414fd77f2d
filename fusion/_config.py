"""Frozen config dataclasses of :mod:`fusion` from plain dicts (unknown keys refused)."""

from __future__ import annotations

import dataclasses
from typing import Any, TypeVar

C = TypeVar("C")


def config_from(cls: type[C], value: Any, name: str = "config") -> C:
    """``value`` as a ``cls`` instance: ``None`` → defaults, a ``cls`` as is, a dict → ``cls(**d)``.

    Raises:
        ValueError: a dict key that is not a field of ``cls`` (the message lists the allowed ones).
        TypeError: anything else than ``None``, a ``cls`` or a dict.
    """
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if isinstance(value, dict):
        allowed = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(str(k) for k in value if k not in allowed)
        if unknown:
            raise ValueError(f"{name} has unknown keys {unknown}; allowed: {allowed}")
        return cls(**value)
    raise TypeError(
        f"{name} must be a {cls.__name__}, a dict of its fields or None, got {type(value).__name__}"
    )
