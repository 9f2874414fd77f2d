"""Shared fixtures: small, fast env settings for the env tests."""

import os

import pytest

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

SMALL = {"world": {"size": (10.0, 10.0)}, "max_cycles": 200}
"""A 10 x 10 m building: every mechanism of the env, at a fraction of the default cost."""


@pytest.fixture
def small():
    return dict(SMALL)
