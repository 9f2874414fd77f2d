"""Derives skimage's Zhang–Suen lookup table from skimage's own outputs and checks it against
``topo._extract_kernels._ZHANG_LUT`` (run it: ``python tests/topo/zhang_lut_derivation.py``,
about a minute; not collected by pytest). skimage (BSD-3-Clause) ships the table only in its
compiled module.

The model is the one ``skimage.morphology._skeletonize._skeletonize_zhang`` documents: each
foreground pixel's 8-neighbour code (outside the image is background) indexes a table of
values 0–3; the first subpass of an iteration removes, all at once, the pixels of value 1 or 3,
the second those of value 2 or 3, and iterations repeat until one removes nothing. The unknowns
are the 512 bits "code ``n`` is removed in subpass ``p``".

A bit is fixed only by proof: for a test image, every assignment of the still unknown bits that
makes the model give skimage's output is enumerated (a pixel in skimage's output is never
removed, so its bits are forced to 0; the others branch), and a bit is fixed when all those
assignments give it the same value. Every image up to 4×4 fixes 499 bits, random images around
each of the 13 left fix 11 more, and in one-pixel-wide Ls every consistent assignment removes
code 10 (N and E set, NE not) in some subpass. Whether it goes in the first or the second subpass (values 1, 2, 3) never changes
an output: :func:`code_10_timing_is_invisible` shows that its two neighbours are never removed
beside it and decide the same with or without it, so the state after the subpass pair is the
same either way. The table uses 3, the value of its three rotations.
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np
from skimage.morphology import skeletonize

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from topo._extract_kernels import _ZHANG_LUT  # noqa: E402

# (row, col) offsets of code bits 0..7: NW, N, NE, E, SE, S, SW, W
OFFSETS = [(-1, -1), (-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1)]


def code(pixels: frozenset, r: int, c: int) -> int:
    return sum(1 << i for i, (dr, dc) in enumerate(OFFSETS) if (r + dr, c + dc) in pixels)


def consistent(x: frozenset, y: frozenset, known: dict, cap: int) -> list[dict] | None:
    """Every assignment of unknown bits under which the model thins ``x`` to ``y`` (``None``
    past ``cap`` branches)."""
    found: list[dict] = []
    budget = [cap]

    def run(state, p, removed_any, assumed):
        budget[0] -= 1
        if budget[0] < 0:
            raise OverflowError
        codes = [(q, (p, code(state, *q))) for q in sorted(state)]
        assumed = dict(assumed)
        for q, bit in codes:
            if q in y:
                value = known.get(bit, assumed.get(bit))
                if value == 1:
                    return
                assumed[bit] = 0
        free = sorted({bit for q, bit in codes
                       if q not in y and known.get(bit, assumed.get(bit)) is None})
        for values in itertools.product((0, 1), repeat=len(free)):
            trial = {**assumed, **dict(zip(free, values, strict=True))}
            gone = {q for q, bit in codes if known.get(bit, trial.get(bit)) == 1}
            after, any_gone = state - gone, removed_any or bool(gone)
            if p == 0:
                run(after, 1, any_gone, trial)
            elif any_gone:
                run(after, 0, False, trial)
            elif after == y:
                found.append(trial)

    try:
        run(x, 0, False, {})
    except OverflowError:
        return None
    return found


def skimage_output(x: frozenset, shape: tuple[int, int]) -> frozenset:
    img = np.zeros(shape, bool)
    for q in x:
        img[q] = True
    return frozenset(map(tuple, np.argwhere(skeletonize(img)).tolist()))


def learn(images, known: dict, cap: int = 20000) -> None:
    for x, shape in images:
        y = skimage_output(x, shape)
        assignments = consistent(x, y, known, cap)
        if assignments is None:
            continue
        assert assignments, f"the model cannot thin {sorted(x)} to skimage's {sorted(y)}"
        for bit in set.intersection(*(set(a) for a in assignments)):
            values = {a[bit] for a in assignments}
            if len(values) == 1:
                known[bit] = values.pop()


def every_image(h: int, w: int):
    cells = [(r, c) for r in range(h) for c in range(w)]
    for m in range(1, 1 << len(cells)):
        yield frozenset(q for i, q in enumerate(cells) if m >> i & 1), (h, w)


def around(n: int, size: int, density: float, count: int, rng):
    """Random ``size``-square images whose centre pixel has code ``n``."""
    mid = size // 2
    for _ in range(count):
        img = rng.random((size, size)) < density
        img[mid, mid] = True
        for i, (dr, dc) in enumerate(OFFSETS):
            img[mid + dr, mid + dc] = bool(n >> i & 1)
        yield frozenset(map(tuple, np.argwhere(img).tolist())), (size, size)


def l_shapes():
    """One-pixel-wide Ls: the corner pixel has code 10 (N and E)."""
    for arm in (2, 3, 4):
        corner = (arm + 1, 1)
        x = {corner} | {(corner[0] - k, 1) for k in range(1, arm + 1)}
        x |= {(corner[0], 1 + k) for k in range(1, arm + 1)}
        yield frozenset(x), (arm + 3, arm + 3)


def code_10_timing_is_invisible(lut: np.ndarray) -> bool:
    """A pixel of code 10 has two foreground neighbours, N and E. If neither is ever removed
    beside it (in either subpass) and each decides the same with it or without it, then
    removing it in the first, the second or both subpasses leaves the same state after the
    subpass pair, whatever the rest of the image: no other pixel sees it."""
    nw, n, ne, e, se, s, sw, w = (1 << i for i in range(8))
    north = [s | se | a | b | c for a in (0, nw) for b in (0, n) for c in (0, ne)]
    east = [nw | w | a | b | c for a in (0, ne) for b in (0, e) for c in (0, se)]
    return (all(lut[m] == 0 and lut[m & ~s] == 0 for m in north)
            and all(lut[m] == 0 and lut[m & ~w] == 0 for m in east))


def main() -> None:
    known: dict = {}
    for h, w in ((3, 3), (3, 4), (4, 3), (4, 4)):
        learn(every_image(h, w), known)
    rng = np.random.default_rng(1)
    for size, density in ((5, 0.2), (6, 0.4), (7, 0.6)):
        for _, n in sorted({(p, n) for p in (0, 1) for n in range(256)} - set(known)):
            learn(around(n, size, density, 300, rng), known)
    print(len(known), "of 512 bits fixed by images up to 4x4 and around each code left")
    left = sorted({(p, n) for p in (0, 1) for n in range(256)} - set(known))
    assert left == [(0, 10), (1, 10)], left
    for x, shape in l_shapes():  # no assignment keeps the corner in both subpasses
        assignments = consistent(x, skimage_output(x, shape), known, 20000)
        assert assignments and all(a.get((0, 10)) or a.get((1, 10)) for a in assignments)
    derived = [known[(0, n)] + 2 * known[(1, n)] if n != 10 else 3 for n in range(256)]
    assert derived == _ZHANG_LUT.tolist(), "the table differs from the derivation"
    assert code_10_timing_is_invisible(_ZHANG_LUT)
    print("topo._extract_kernels._ZHANG_LUT is the derived table")


if __name__ == "__main__":
    main()
