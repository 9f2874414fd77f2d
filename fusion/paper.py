"""The paper's worked example, rebuilt: a 4-vertex map A and a 7-vertex map B.

The paper gives its ICP-SVD answer — ``R = [[0.9540, −0.2997], [0.2997, 0.9540]]`` (≈ 17.44°),
``T = (−36.461, −25.258)``, 11 iterations at ``τ = 0.1`` — and its map sizes (4 and 7 vertices) but
not the vertex coordinates. This module builds maps of those sizes whose true relation *is* the
paper's ``(R, T)``, in the paper's units (no scale is given; the values suggest decimetres or
pixels, so call them "map units"):

* B: a rectangular corridor loop ``b0..b3`` with three side corridors ending at ``b4..b6``.
* A: only the loop, as seen by a robot that explored less: ``a_k = R b_k + T``.

The loop is a rectangle, which looks the same after a half turn — so, like the paper's exhaustive
search (two best fusions, at 136° and 316°), the baseline finds two equally scored optima 180°
apart. And because B has three vertices that A lacks, the paper's initialisation
(``T = mean(M) − mean(D)``) starts from a biased centroid: see ``examples/paper_example.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusion.rigid import Rigid2D
from topo.graph import TopoMap

PAPER_R = np.array([[0.9540, -0.2997], [0.2997, 0.9540]])
"""The rotation the paper reports (printed to 4 digits, so only orthonormal to ~3e-5)."""
PAPER_T = np.array([-36.461, -25.258])
"""The translation the paper reports."""
PAPER_THETA = math.atan2(PAPER_R[1, 0], PAPER_R[0, 0])
"""≈ 0.3044 rad ≈ 17.44°."""
PAPER_ITERATIONS = 11
PAPER_TAU = 0.1
PAPER_EXHAUSTIVE_OPTIMA_DEG = (136.0, 316.0)
"""The paper's two best exhaustive-search angles (it rotates A; topomerge moves B)."""

_B_XY = np.array(
    [
        [10.0, 10.0],  # b0  loop corner
        [40.0, 10.0],  # b1  loop junction (side corridor to b4)
        [40.0, 30.0],  # b2  loop junction (side corridor to b6)
        [10.0, 30.0],  # b3  loop junction (side corridor to b5)
        [58.0, 10.0],  # b4  dead end
        [10.0, 50.0],  # b5  dead end
        [40.0, 52.0],  # b6  dead end
    ]
)
_B_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [1, 4], [3, 5], [2, 6]])
_LOOP = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])


@dataclass(frozen=True, slots=True)
class PaperExample:
    """The example's two maps, the true transform B → A, and a sensible ω tolerance."""

    map_a: TopoMap
    map_b: TopoMap
    truth: Rigid2D
    eps: float
    shared_b: np.ndarray
    """Indices of B's vertices that A also has (A's vertex k is B's ``shared_b[k]``)."""


def paper_truth() -> Rigid2D:
    """The paper's ICP-SVD answer as a :class:`Rigid2D` (``p_A = R p_B + T``)."""
    return Rigid2D(PAPER_THETA, PAPER_T)


def paper_example() -> PaperExample:
    """Build the example (deterministic; no randomness involved)."""
    truth = paper_truth()
    map_b = TopoMap.from_arrays(_B_XY, _B_EDGES)
    map_a = TopoMap.from_arrays(truth.apply(_B_XY[:4]), _LOOP)
    return PaperExample(map_a=map_a, map_b=map_b, truth=truth, eps=1.0, shared_b=np.arange(4))
