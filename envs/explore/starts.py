"""What ``reset`` is given, read and checked: the seed and the ``start_poses`` option.

Without start poses the env draws the starts (``envs.explore.feasibility.draw_world_and_starts``,
manual, Starting State).
"""

from __future__ import annotations

import math
import numbers
import warnings
from typing import Any

import numpy as np

from envs.explore.worlds import World


def check_seed(seed: object) -> int | None:
    """``reset``'s ``seed`` as an ``int`` (or ``None``: continue the env's generator).

    Raises:
        TypeError: not ``None`` or an integer (``bool`` is refused, numpy integers are fine).
        ValueError: a negative integer (``numpy.random.default_rng`` takes none).
    """
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise TypeError(f"seed must be None or a non-negative integer, got {seed!r} "
                        f"({type(seed).__name__})")
    if seed < 0:
        raise ValueError(f"seed must be None or a non-negative integer, got {seed}")
    return int(seed)


def parse_reset_options(options: dict[str, Any] | None, n: int, env_name: str
                        ) -> np.ndarray | None:
    """The start poses the reset ``options`` give for ``n`` robots: an ``(n, 3)`` float64
    array of ``[x, y, θ]`` (world frame, radians), or ``None`` (no options or no
    ``"start_poses"``: drawn). Other keys are ignored with a warning naming ``env_name``,
    attributed to the caller of ``reset`` (call this from ``reset`` itself).

    Raises:
        TypeError: ``options`` is not a dict or ``None``, or the poses are not numeric.
        ValueError: the poses are not finite or not of shape ``(n, 3)``.
    """
    if options is None:
        return None
    if not isinstance(options, dict):
        raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
    unknown = sorted(str(k) for k in options if k != "start_poses")
    if unknown:
        warnings.warn(f"reset options {unknown} are not used by {env_name}; known: "
                      f"['start_poses']", stacklevel=3)
    if "start_poses" not in options:
        return None
    try:
        starts = np.asarray(options["start_poses"], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError("options['start_poses'] must be numeric [[x, y, theta], ...], "
                        "one row per robot") from exc
    if starts.shape != (n, 3) or not np.all(np.isfinite(starts)):
        raise ValueError(f"options['start_poses'] must be finite with shape ({n}, 3) (one "
                         f"[x, y, theta] per robot), got {starts.tolist()}")
    return starts


def check_start_poses(starts: np.ndarray, world: World, robot_radius: float) -> None:
    """Check parsed start poses (:func:`parse_reset_options`) against the episode's ``world``.

    Raises:
        ValueError: a start is not a drivable position of ``world`` (free with the robot's
            clearance), or two robots of radius ``robot_radius`` overlap.
    """
    ij = world.cell_of(starts[:, :2])
    h, w = world.shape
    for k, (iy, ix) in enumerate(ij):
        if not (0 <= iy < h and 0 <= ix < w) or not world.drivable[iy, ix]:
            raise ValueError(
                f"options['start_poses'][{k}] = {starts[k, :2].tolist()} is not a drivable "
                f"position of world {world.name!r} (free with robot clearance)")
    for i in range(len(starts)):
        for j in range(i + 1, len(starts)):
            if math.dist(starts[i, :2], starts[j, :2]) < 2 * robot_radius:
                raise ValueError(f"options['start_poses'] put robots {i} and {j} on top "
                                 f"of each other")
