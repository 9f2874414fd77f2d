"""Exact copies of the env by replay (the env's manual, Copies): what is pickled and how a
copy is rebuilt.

What is pickled is the config, the render mode, the loaded world file, the generator's state
at the last ``reset``, the start poses given to it, each step's ``(v, ω)`` commands since and
any later ``max_cycles`` change; restoring builds a fresh env, resets it from that generator
state and steps it through the commands. Why: pymunk pickles bodies and contacts but not what a
step leaves to the next (the solver's bias velocities, joint impulses, the broadphase's pair
order), so an unpickled space drifts from the original after a contact; the env is
deterministic given the generator, the start poses and the commands.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(slots=True)
class History:
    """How the current episode came about, all a copy needs to replay it (manual, Copies):
    the generator's state at ``reset``, the start poses given (``None``: drawn), ``max_cycles``
    at ``reset``, each step's parsed ``(v, ω)`` commands, and ``(step, value)`` of every later
    ``max_cycles`` change."""

    rng_state: dict[str, Any]
    starts: np.ndarray | None
    max_cycles: int
    commands: list[list[tuple[float, float]]] = field(default_factory=list)
    max_cycles_changes: list[tuple[int, int]] = field(default_factory=list)


def _generator(state: dict[str, Any]) -> np.random.Generator:
    """A ``numpy.random.Generator`` in ``state`` (a ``bit_generator.state``)."""
    rng = np.random.Generator(getattr(np.random, state["bit_generator"])())
    rng.bit_generator.state = state
    return rng


class ReplayCopies:
    """Pickling and copying for the env by replay (module docstring). The env provides
    ``_setup``, ``_begin``, ``_advance``, ``_terminated``, ``_truncated``, ``config``,
    ``render_mode``, ``n_robots``, ``_file_world``, ``_rng``, ``_history``, ``_max_cycles``
    and the ``max_cycles`` property."""

    def __getstate__(self) -> dict[str, Any]:
        """The state for ``pickle`` and ``copy`` (manual, Copies): the config, the render mode,
        the loaded world file, the generator's state, and how the episode came about — the
        generator's state at ``reset``, the start poses given, the commands of every step
        since (a ``(steps, N, 2)`` float64 array) and ``max_cycles`` changes — plus the
        original's step count, agents, poses and contact counts, which the restored env must
        reproduce. No physics or grids: :meth:`__setstate__` replays."""
        h = self._history
        episode = None
        if h is not None:
            episode = {
                "rng": h.rng_state,
                "starts": h.starts,
                "max_cycles": h.max_cycles,
                "commands": np.array(h.commands, dtype=np.float64).reshape(
                    -1, self.n_robots, 2),
                "max_cycles_changes": list(h.max_cycles_changes),
                "check": self._replay_check(),
            }
        return {
            "config": self.config,
            "render_mode": self.render_mode,
            "file_world": self._file_world,
            "rng": None if self._rng is None else self._rng.bit_generator.state,
            "episode": episode,
        }

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Rebuild the env from :meth:`__getstate__`'s state: construct it, restore the
        generator as it was at ``reset``, reset and replay the recorded commands (no
        rendering, no warnings), so that it ends in exactly the original's state. The time
        grows with the steps since ``reset`` (Copies in ``docs/env_explore.md``).

        Raises:
            RuntimeError: the replay did not reproduce the original (step count, agents,
                poses, contacts or generator state differ: its internals were changed from
                outside, or the code it runs differs from the original's).
        """
        config, episode = state["config"], state["episode"]
        self._setup(config, state["render_mode"], state["file_world"])
        if episode is not None:
            self._rng = _generator(episode["rng"])
            self._max_cycles = episode["max_cycles"]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the original has shown them already
                self._begin(episode["starts"])
                self._replay(episode["commands"], episode["max_cycles_changes"])
            got = self._replay_check()
            if got != episode["check"]:
                raise RuntimeError(
                    f"the restored env does not reproduce the original: (steps, agents, "
                    f"poses, contacts) {got} after the replay, the original had "
                    f"{episode['check']}; was the original's state changed from outside "
                    f"step()/reset(), or does this process run other code?")
            self.config, self._max_cycles = config, config.max_cycles
        if state["rng"] is not None:
            if self._rng is None:
                self._rng = _generator(state["rng"])
            elif self._rng.bit_generator.state != state["rng"]:
                raise RuntimeError(
                    "the restored env does not reproduce the original: its generator drew a "
                    "different number of values during the replay")

    def _replay(self, commands: np.ndarray,
                max_cycles_changes: list[tuple[int, int]]) -> None:
        """Advance a freshly reset episode by the recorded ``commands`` (the outputs, which
        change no state, are not built), setting ``max_cycles`` where it was set."""
        changes = sorted(max_cycles_changes)  # stable: same-step changes keep their order
        c = 0
        for k, step_commands in enumerate(commands.tolist()):
            while c < len(changes) and changes[c][0] <= k:
                self.max_cycles = changes[c][1]
                c += 1
            self._advance(step_commands)
            if self._terminated() or self._truncated():
                self.agents = []
        for _, value in changes[c:]:
            self.max_cycles = value

    def _replay_check(self) -> tuple:
        """What a replay must reproduce: steps, agents, every robot's exact pose and
        contact count."""
        return (self.steps, tuple(self.agents), tuple(r._pose() for r in self.robots),
                tuple(r.collisions for r in self.robots))
