"""Timing helpers shared by the benchmark scripts (medians, warm-up, interleaving, the CPU
time of an env's stages)."""

from __future__ import annotations

import statistics
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from typing import Any


def median_time(fn: Callable[[], object], repeats: int) -> float:
    """Median wall time of ``fn()`` over ``repeats`` calls, after one warm-up call (compiled
    kernels load on the first call)."""
    return interleaved_medians({"fn": fn}, repeats)["fn"]


def interleaved_medians(fns: dict[str, Callable[[], object]], repeats: int) -> dict[str, float]:
    """Median wall time of each function, timed round-robin so that a busy machine slows all of
    them alike (their ratios stay fair)."""
    for fn in fns.values():
        fn()
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t0)
    return {k: statistics.median(v) for k, v in times.items()}


class StageClock:
    """CPU seconds spent in each of an env's hooks (``stages``: method names such as
    ``"_fuse"``), by wrapping them on the instance: ``seconds[name]`` accumulates."""

    def __init__(self, env: Any, stages: Sequence[str]) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        for name in stages:
            setattr(env, name, self._wrap(name, getattr(env, name)))

    def _wrap(self, name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        seconds = self.seconds
        clock = time.process_time

        def timed(*args: Any, **kwargs: Any) -> Any:
            t0 = clock()
            out = fn(*args, **kwargs)
            seconds[name] += clock() - t0
            return out

        return timed
