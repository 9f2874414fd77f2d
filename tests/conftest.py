"""Suite-wide settings: no hypothesis deadlines (first calls compile numba kernels), headless
rendering, and one torch thread (two collapse when the other core is busy)."""

import os

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

from hypothesis import settings  # noqa: E402

settings.register_profile("topomerge", deadline=None, max_examples=60)
settings.load_profile("topomerge")


def pytest_configure(config):
    try:
        import torch
    except ImportError:  # the topo, fusion and env tests run without it
        return
    torch.set_num_threads(1)
