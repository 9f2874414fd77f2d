"""Explorer names that say whether the robots know their relative start poses.

``NAME@known`` runs explorer ``NAME`` with the poses known (the env's
``mapping.merge_method="known"``: every teammate placed by its true start-frame transform from
the first step, the maps still exchanged only in contact); ``NAME@merged`` with them unknown,
found by merging (``"hybrid"``, the env's default). The second is for trained policies whose
run was trained with the poses known (``train.py --known-poses``): the same weights, judged
in the standard env. Shared by ``training_eval.py`` and ``team_size.py``.
"""
from __future__ import annotations

from typing import Any

POSE_SUFFIXES = {"@known": "known", "@merged": "hybrid"}
"""Suffix of an explorer's name → the env's ``mapping.merge_method`` it runs with."""


def split_poses(name: str) -> tuple[str, str | None]:
    """``name`` without its pose suffix, and the ``mapping.merge_method`` the suffix asks for
    (``None``: no suffix, the explorer's own config as it is)."""
    for suffix, method in POSE_SUFFIXES.items():
        if name.endswith(suffix):
            return name.removesuffix(suffix), method
    return name, None


def with_merge_method(config: dict[str, Any], method: str | None) -> dict[str, Any]:
    """``config`` (env ``EnvConfig`` fields) with ``mapping.merge_method`` set to ``method``,
    the rest of its ``mapping`` kept (``None``: ``config`` unchanged)."""
    if method is None:
        return config
    return {**config, "mapping": {**config.get("mapping", {}), "merge_method": method}}
