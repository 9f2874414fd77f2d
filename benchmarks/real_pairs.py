"""Build the real-map development set: pairs of occupancy maps from separate traversals of
the same real buildings, with the true transform between them (issue 43).

    python benchmarks/real_pairs.py --mirror [GITDIR] [--out data/real_pairs] [--seed 0]
    python benchmarks/real_pairs.py --logs DIR [--out data/real_pairs] [--seed 0]

Why: the grid alignment's accept rule was fitted on the env's simulated maps only; real sensor
maps (clutter, glass, people, long beams, SLAM blur) need a set of their own to check and fit
it on.

Source: the 13 "corrected" CARMEN laser logs of the Freiburg / Radish SLAM benchmark (real SICK
scans, each at its SLAM-corrected pose, the accepted ground truth of Kümmerle et al., "On
measuring the accuracy of SLAM algorithms", Autonomous Robots 27(4), 2009), as redistributed in
``github.com/acschaefer/ple`` (``data/carmen/<name>-corrected.log.gz``, GPL-3.0 repository;
the recordings are Radish's, radish.sourceforge.net, credited to their contributors). The logs
are not part of this repository: ``--logs DIR`` reads ``DIR/<name>-corrected.log[.gz]``,
``--mirror GITDIR`` reads them from a git copy of that repository (default
:data:`DEFAULT_MIRROR`).

How (every step deterministic in ``--seed``):

* read each log's ``FLASER`` (and ``ROBOTLASER1``) lines: ranges and the laser's corrected pose
  (:func:`read_carmen`; ``FLASER`` beams from −90° counter-clockwise, 1° apart for 180/181
  readings, 0.5° for 360/361: :func:`flaser_step`);
* split the run into segments of ``--segment-m`` metres travelled (default 60; a remainder
  shorter than half of that joins the last segment): separate traversals of the building, each
  one robot's map (:func:`segments`);
* give every segment a frame of its own: its poses moved by a random rigid transform ``T``
  (about the segment's mean position, any rotation, a shift of up to ``--shift`` metres), so
  nothing is shared between two maps but the building;
* rasterise each segment's scans at those poses at 0.05 m (:func:`rasterise`: every beam drawn
  with ``skimage.draw.line``, hit and pass-through counts per cell; a beam longer than
  ``--hit-range`` marks free space only up to there, one without echo (``≥ --no-echo`` m)
  free space only up to ``--no-echo-free``; a cell is occupied when at least
  ``OCCUPIED_SHARE`` of the beams that reach it end in it, free when beams reach it
  otherwise) and write it as a ROS ``map_server`` map (``topo.maps.save_ros_map``);
* pair the segments: for every pair ``(A, B)`` of one building (A the earlier), the truth
  ``[x, y, theta]`` maps B's map frame into A's (``p_A = R(theta) p_B + (x, y)``, i.e.
  ``T_A ∘ T_B⁻¹``) and the overlap is the share of B's known cells that land on known cells of A
  under it. Kept: up to ``--per-building`` pairs with overlap ≥ ``MIN_OVERLAP``, spread over
  their overlap range, up to ``--disjoint`` pairs with overlap < ``MAX_DISJOINT`` and
  ``MAX_DISJOINT_M2`` (what a merge must reject), and ``--cross`` pairs per split of segments
  from two different buildings (truth ``null``, overlap 0, ``building`` ``"<a>+<b>"``).

Splits by building, fixed here: :data:`TEST_BUILDINGS` are ``test`` (held out), the others
``dev``. Output: ``<out>/<building>/seg_NN.yaml`` + ``.pgm`` and ``<out>/manifest.json``
(written atomically; ``a``/``b`` are paths relative to ``<out>``)::

    {"format": "topomerge.real_pairs", "version": 1, "source": ..., "licence": ...,
     "resolution": 0.05, "segment_m": 60.0, "seed": 0,
     "pairs": [{"id", "building", "split", "a", "b", "truth", "overlap", "overlap_m2"}]}
"""

from __future__ import annotations

import argparse
import gzip
import itertools
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from skimage.draw import line

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from topo.fileio import atomic_write_json  # noqa: E402
from topo.maps import FloorPlan, save_ros_map  # noqa: E402

BUILDINGS = ("acapulco", "aces", "belgioioso", "csail", "edmonton", "fhw", "freiburg-079",
             "freiburg-101", "freiburg-campus", "infinite-corridor", "intel", "orebro",
             "seattle")
"""The 13 corrected logs, by the name in ``<name>-corrected.log.gz``."""
TEST_BUILDINGS = frozenset({"aces", "csail", "freiburg-101", "intel", "orebro"})
"""Held out (``split: test``); the other eight are ``dev`` (fit on them)."""
DEFAULT_MIRROR = Path("/work/.mirror/acschaefer+ple/repo")
MIRROR_PATH = "data/carmen/{name}-corrected.log.gz"
SOURCE_URL = "https://github.com/acschaefer/ple/tree/master/data/carmen"
SOURCE = ("Freiburg/Radish 'corrected' CARMEN laser logs (real SICK lidar at the SLAM-corrected "
          "poses of the SLAM benchmark of Kuemmerle et al., Autonomous Robots 27(4), 2009), as "
          f"redistributed in {SOURCE_URL}; recordings from Radish (radish.sourceforge.net); maps "
          "rasterised by benchmarks/real_pairs.py")
LICENCE = ("Derived from the Radish datasets, credited to their contributors (see each "
           "dataset's Radish page); the carrying repository acschaefer/ple is GPL-3.0. The logs "
           "and these maps are not redistributed by topomerge: regenerate them with "
           "benchmarks/real_pairs.py")
RESOLUTION = 0.05
OCCUPIED_SHARE = 0.25
"""A cell is occupied when at least this share of the beams reaching it end in it: a wall
grazed by the beams that pass beside it stays a wall, a person walking by does not."""
MIN_OVERLAP = 0.10
MAX_DISJOINT = 0.01
MAX_DISJOINT_M2 = 1.0
"""A pair is disjoint (a merge must reject it) below both: less than 1 % and 1 m² shared."""
MIN_RANGE = 0.05
"""Shorter readings are the sensor's error codes (0): dropped."""


@dataclass(frozen=True)
class Scan:
    """One laser scan: ``ranges`` (K,) m, beam ``angles`` (K,) rad in the laser's frame, and
    the laser's corrected ``pose`` ``(x, y, theta)`` in the log's frame."""

    ranges: np.ndarray
    angles: np.ndarray
    pose: tuple[float, float, float]


def flaser_step(n: int) -> float:
    """The beam spacing (rad) of a ``FLASER`` scan of ``n`` readings from −90°: 1° for 180 or
    181 readings, 0.5° for 360 or 361 (the SICK modes, as CARMEN reads them), else 180° over
    ``n − 1`` gaps. Why: 180 readings 1° apart reach 89°, not 90°; with this spacing the
    segments' walls agree better under the truth than with 180° spread evenly."""
    if n in (180, 181):
        return math.pi / 180
    if n in (360, 361):
        return math.pi / 360
    return math.pi / max(n - 1, 1)


def _flaser(fields: list[str], where: str) -> Scan:
    n = int(fields[1])
    if n < 1 or len(fields) < 5 + n:
        raise ValueError(f"{where}: FLASER line with {len(fields)} fields for {n} readings")
    ranges = np.asarray(fields[2:2 + n], dtype=float)
    x, y, theta = (float(v) for v in fields[2 + n:5 + n])
    angles = -math.pi / 2 + flaser_step(n) * np.arange(n)
    return Scan(ranges, angles, (x, y, theta))


def _robotlaser(fields: list[str], where: str) -> Scan:
    start, fov, step = (float(v) for v in fields[2:5])
    n = int(fields[8])
    m = int(fields[9 + n])
    pose = 10 + n + m
    if len(fields) < pose + 3:
        raise ValueError(f"{where}: ROBOTLASER1 line too short for {n} readings")
    ranges = np.asarray(fields[9:9 + n], dtype=float)
    angles = start + step * np.arange(n) if step > 0 else np.linspace(start, start + fov, n)
    x, y, theta = (float(v) for v in fields[pose:pose + 3])
    return Scan(ranges, angles, (x, y, theta))


def read_carmen(text: str, name: str = "log") -> list[Scan]:
    """The laser scans of a CARMEN log's text, in order: ``FLASER`` (from −90° at
    :func:`flaser_step`, the pose after the ranges) and ``ROBOTLASER1`` (its own start angle
    and step, the laser pose after the remissions); other lines (``ODOM``, ``PARAM``,
    comments) are skipped.

    Raises:
        ValueError: a laser line too short for its reading count, or a log without scans
            (the message names ``name`` and the line).
    """
    scans = []
    for number, raw in enumerate(text.splitlines(), 1):
        fields = raw.split()
        if not fields:
            continue
        where = f"{name} line {number}"
        try:
            if fields[0] == "FLASER":
                scans.append(_flaser(fields, where))
            elif fields[0] == "ROBOTLASER1":
                scans.append(_robotlaser(fields, where))
        except (IndexError, ValueError) as err:
            raise ValueError(f"{where}: malformed {fields[0]} line ({err})") from err
    if not scans:
        raise ValueError(f"{name}: no FLASER or ROBOTLASER1 line: not a CARMEN laser log")
    return scans


def log_text(name: str, logs: Path | None, mirror: Path | None) -> str:
    """The text of building ``name``'s corrected log, from ``logs/<name>-corrected.log[.gz]``
    or from the git copy ``mirror`` of acschaefer/ple.

    Raises:
        FileNotFoundError: the log is in neither place (the message says where to get it).
    """
    where = f"get {SOURCE_URL}/{name}-corrected.log.gz"
    if logs is not None:
        for path in (logs / f"{name}-corrected.log.gz", logs / f"{name}-corrected.log"):
            if path.exists():
                data = path.read_bytes()
                return (gzip.decompress(data) if path.suffix == ".gz" else data).decode()
        raise FileNotFoundError(f"--logs {logs}: no {name}-corrected.log.gz in it ({where})")
    assert mirror is not None
    done = subprocess.run(["git", "-C", str(mirror), "show", "HEAD:" + MIRROR_PATH.format(
        name=name)], capture_output=True, check=False)
    if done.returncode != 0:
        raise FileNotFoundError(f"--mirror {mirror}: no {MIRROR_PATH.format(name=name)} "
                                f"({done.stderr.decode().strip()}); {where} and pass --logs DIR")
    return gzip.decompress(done.stdout).decode()


def segments(scans: list[Scan], segment_m: float) -> list[list[Scan]]:
    """``scans`` cut into consecutive runs of ``segment_m`` metres travelled; a remainder
    shorter than half of that joins the last run."""
    xy = np.array([s.pose[:2] for s in scans])
    travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    index = np.floor(travelled / segment_m).astype(int)
    count = int(index[-1]) + 1
    if count > 1 and travelled[-1] - (count - 1) * segment_m < segment_m / 2:
        index[index == count - 1] = count - 2
    return [[s for s, k in zip(scans, index, strict=True) if k == i]
            for i in range(int(index.max()) + 1)]


def matrix(x: float, y: float, theta: float) -> np.ndarray:
    """The 3 × 3 homogeneous matrix of the rigid transform ``p ↦ R(theta) p + (x, y)``."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def as_xyt(m: np.ndarray) -> list[float]:
    """``[x, y, theta]`` of a homogeneous rigid matrix, ``theta`` in (−π, π]."""
    return [float(m[0, 2]), float(m[1, 2]), float(math.atan2(m[1, 0], m[0, 0]))]


def random_frame(scans: list[Scan], rng: np.random.Generator, shift: float) -> np.ndarray:
    """A segment's own frame: the matrix taking the log's frame into it, a uniform rotation
    about the segment's mean position and a uniform shift of up to ``shift`` m per axis."""
    centre = np.mean([s.pose[:2] for s in scans], axis=0)
    theta = float(rng.uniform(-math.pi, math.pi))
    dx, dy = rng.uniform(-shift, shift, size=2)
    return matrix(float(dx), float(dy), theta) @ matrix(-centre[0], -centre[1], 0.0)


def rasterise(scans: list[Scan], frame: np.ndarray, *, resolution: float = RESOLUTION,
              hit_range: float = 15.0, no_echo: float = 30.0, no_echo_free: float = 8.0,
              name: str = "map") -> FloorPlan:
    """The trinary occupancy map of ``scans`` at their poses moved by ``frame`` (3 × 3, log
    frame → map frame): every beam drawn cell by cell (``skimage.draw.line``), the end cell a
    hit unless the reading is longer than ``hit_range`` (the beam cut there, free space only)
    or ≥ ``no_echo`` (no echo: free space only, up to ``no_echo_free``); occupied where at
    least :data:`OCCUPIED_SHARE` of the beams reaching a cell end in it, free where beams
    reach it otherwise, unknown elsewhere. The grid spans the beams plus one cell; its origin
    is a multiple of ``resolution``."""
    starts, ends, hits = [], [], []
    for s in scans:
        ok = s.ranges >= MIN_RANGE
        r = s.ranges[ok]
        hit = (r < no_echo) & (r <= hit_range)
        r = np.where(r >= no_echo, min(no_echo_free, hit_range), np.minimum(r, hit_range))
        x, y, theta = s.pose
        a = theta + s.angles[ok]
        local = np.stack([x + r * np.cos(a), y + r * np.sin(a), np.ones_like(r)])
        ends.append((frame @ local)[:2].T)
        starts.append(np.broadcast_to((frame @ np.array([x, y, 1.0]))[:2], (r.size, 2)))
        hits.append(hit)
    start, end, hit = np.concatenate(starts), np.concatenate(ends), np.concatenate(hits)
    both = np.concatenate([start, end])
    lo = np.floor(both.min(axis=0) / resolution) - 1
    hi = np.floor(both.max(axis=0) / resolution) + 2
    width, height = (hi - lo).astype(int)
    origin = (float(lo[0] * resolution), float(lo[1] * resolution))
    c0 = np.floor(start / resolution - lo).astype(int)
    c1 = np.floor(end / resolution - lo).astype(int)
    passed, ended = [], []
    for (x0, y0), (x1, y1), h in zip(c0, c1, hit, strict=True):
        rr, cc = line(y0, x0, y1, x1)
        flat = rr * width + cc
        if h:
            passed.append(flat[:-1])
            ended.append(flat[-1:])
        else:
            passed.append(flat)
    size = width * height
    n_hit = np.bincount(np.concatenate(ended or [np.zeros(0, int)]), minlength=size)
    n_pass = np.bincount(np.concatenate(passed), minlength=size)
    reach = (n_hit + n_pass).reshape(height, width)
    occupied = (n_hit.reshape(height, width) >= OCCUPIED_SHARE * reach) & (reach > 0)
    return FloorPlan(free=(reach > 0) & ~occupied, occupied=occupied, resolution=resolution,
                     origin=origin, name=name)


def known_overlap(a: FloorPlan, b: FloorPlan, truth: np.ndarray) -> tuple[float, float]:
    """``(share, m²)`` of ``b``'s known cells whose centres, moved by ``truth`` (b's map frame
    → a's), fall on a known cell of ``a``."""
    rows, cols = np.nonzero(b.free | b.occupied)
    if rows.size == 0:
        return 0.0, 0.0
    xy = np.stack([b.origin[0] + (cols + 0.5) * b.resolution,
                   b.origin[1] + (rows + 0.5) * b.resolution, np.ones(rows.size)])
    pa = truth @ xy
    ix = np.floor((pa[0] - a.origin[0]) / a.resolution).astype(int)
    iy = np.floor((pa[1] - a.origin[1]) / a.resolution).astype(int)
    h, w = a.shape
    inside = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
    known = np.zeros(rows.size, bool)
    known[inside] = (a.free | a.occupied)[iy[inside], ix[inside]]
    count = int(known.sum())
    return count / rows.size, count * b.resolution ** 2


def _spread(items: list, key, count: int) -> list:
    """At most ``count`` of ``items`` at evenly spaced ranks of ``key`` (all when fewer)."""
    if len(items) <= count:
        return items
    ranked = sorted(items, key=key)
    picks = np.unique(np.round(np.linspace(0, len(ranked) - 1, count)).astype(int))
    return [ranked[i] for i in picks]


def _building(name: str, args: argparse.Namespace, index: int) -> tuple[list, list[str]]:
    """Rasterise and write one building's segments; its kept same-building pairs and the
    segment files (relative to ``args.out``)."""
    scans = read_carmen(log_text(name, args.logs, args.mirror), name)
    rng = np.random.default_rng([args.seed, index])
    parts = segments(scans, args.segment_m)
    frames, plans, files = [], [], []
    for k, part in enumerate(parts):
        frame = random_frame(part, rng, args.shift)
        plan = rasterise(part, frame, hit_range=args.hit_range, no_echo=args.no_echo,
                         no_echo_free=args.no_echo_free, name=f"{name}_seg{k:02d}")
        rel = f"{name}/seg_{k:02d}.yaml"
        save_ros_map(plan, args.out / rel)
        frames.append(frame)
        plans.append(plan)
        files.append(rel)
    split = "test" if name in TEST_BUILDINGS else "dev"
    overlapping, disjoint = [], []
    for i, j in itertools.combinations(range(len(parts)), 2):
        truth = frames[i] @ np.linalg.inv(frames[j])
        share, area = known_overlap(plans[i], plans[j], truth)
        row = {"id": f"{name}_{i:02d}_{j:02d}", "building": name, "split": split,
               "a": files[i], "b": files[j], "truth": [round(v, 6) for v in as_xyt(truth)],
               "overlap": round(share, 4), "overlap_m2": round(area, 2)}
        if share >= MIN_OVERLAP:
            overlapping.append(row)
        elif share < MAX_DISJOINT and area < MAX_DISJOINT_M2:
            disjoint.append(row)
    kept = list(_spread(overlapping, lambda r: r["overlap"], args.per_building))
    if disjoint:
        picks = rng.choice(len(disjoint), size=min(args.disjoint, len(disjoint)), replace=False)
        kept += [disjoint[i] for i in sorted(picks)]
    sizes = [p.shape for p in plans]
    print(f"{name:18s} {split:4s} {len(scans):5d} scans {len(parts):3d} segments "
          f"{len(overlapping):4d} overlapping {len(disjoint):4d} disjoint, kept {len(kept):3d};"
          f" cells {min(min(s) for s in sizes)}..{max(max(s) for s in sizes)}", flush=True)
    return kept, files


def _cross(files: dict[str, list[str]], split: str, count: int,
           rng: np.random.Generator) -> list[dict]:
    """``count`` pairs (each once) of segments of two different buildings of ``split``."""
    names = sorted(n for n in files if ("test" if n in TEST_BUILDINGS else "dev") == split)
    rows: list[dict] = []
    seen: set[frozenset[str]] = set()
    for _ in range(100 * count if len(names) > 1 else 0):
        if len(rows) == count:
            break
        na, nb = (names[i] for i in rng.choice(len(names), size=2, replace=False))
        fa, fb = files[na][rng.integers(len(files[na]))], files[nb][rng.integers(len(files[nb]))]
        if frozenset((fa, fb)) in seen:
            continue
        seen.add(frozenset((fa, fb)))
        rows.append({"id": f"cross_{split}_{len(rows):02d}", "building": f"{na}+{nb}",
                     "split": split, "a": fa, "b": fb, "truth": None, "overlap": 0.0,
                     "overlap_m2": 0.0})
    return rows


def overlay(out: Path, pair: dict) -> Path:
    """Write ``<out>/<id>.png``: A's free cells light grey, its walls black, B's walls moved
    into A's frame by the truth in red (a right truth puts red on black)."""
    from PIL import Image

    from topo.maps import load_ros_map

    a, b = load_ros_map(out / pair["a"]), load_ros_map(out / pair["b"])
    rgb = np.full(a.shape + (3,), 205, np.uint8)
    rgb[a.free] = 250
    rgb[a.occupied] = 0
    if pair["truth"] is not None:
        rows, cols = np.nonzero(b.occupied)
        xy = np.stack([b.origin[0] + (cols + 0.5) * b.resolution,
                       b.origin[1] + (rows + 0.5) * b.resolution, np.ones(rows.size)])
        pa = matrix(*pair["truth"]) @ xy
        ix = np.floor((pa[0] - a.origin[0]) / a.resolution).astype(int)
        iy = np.floor((pa[1] - a.origin[1]) / a.resolution).astype(int)
        inside = (ix >= 0) & (ix < a.shape[1]) & (iy >= 0) & (iy < a.shape[0])
        rgb[iy[inside], ix[inside]] = (230, 0, 0)
    path = out / f"{pair['id']}.png"
    Image.fromarray(np.ascontiguousarray(rgb[::-1])).save(path)
    return path


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--logs", type=Path, help="folder of <name>-corrected.log[.gz]")
    source.add_argument("--mirror", type=Path, nargs="?", const=DEFAULT_MIRROR,
                        help=f"git copy of acschaefer/ple (default {DEFAULT_MIRROR})")
    parser.add_argument("--out", type=Path, default=ROOT / "data" / "real_pairs")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--buildings", nargs="+", choices=BUILDINGS, default=list(BUILDINGS))
    parser.add_argument("--segment-m", type=float, default=60.0)
    parser.add_argument("--shift", type=float, default=3.0)
    parser.add_argument("--hit-range", type=float, default=15.0)
    parser.add_argument("--no-echo", type=float, default=30.0)
    parser.add_argument("--no-echo-free", type=float, default=8.0)
    parser.add_argument("--per-building", type=int, default=20)
    parser.add_argument("--disjoint", type=int, default=4)
    parser.add_argument("--cross", type=int, default=8)
    parser.add_argument("--show", nargs="+", metavar="ID",
                        help="only draw these pairs of <out>/manifest.json to <out>/<ID>.png")
    args = parser.parse_args(argv)
    if args.show:
        import json

        rows = {r["id"]: r for r in json.loads((args.out / "manifest.json").read_text())["pairs"]}
        for key in args.show:
            if key not in rows:
                parser.error(f"--show {key}: no such pair in {args.out / 'manifest.json'}")
            print(overlay(args.out, rows[key]))
        return
    if args.logs is None and args.mirror is None:
        args.mirror = DEFAULT_MIRROR
    for key in ("segment_m", "shift", "hit_range", "no_echo", "no_echo_free"):
        if not getattr(args, key) > 0:
            parser.error(f"--{key.replace('_', '-')} {getattr(args, key)}: must be > 0")
    if args.logs is None and not args.mirror.exists():
        parser.error(f"--mirror {args.mirror}: not found; download the logs from {SOURCE_URL} "
                     "and pass --logs DIR")
    pairs, files = [], {}
    for name in args.buildings:
        kept, files[name] = _building(name, args, BUILDINGS.index(name))
        pairs += kept
    rng = np.random.default_rng([args.seed, len(BUILDINGS)])
    for split in ("dev", "test"):
        pairs += _cross(files, split, args.cross, rng)
    manifest = {"format": "topomerge.real_pairs", "version": 1, "source": SOURCE,
                "licence": LICENCE, "resolution": RESOLUTION, "segment_m": args.segment_m,
                "seed": args.seed, "pairs": pairs}
    atomic_write_json(args.out / "manifest.json", manifest)
    print(f"{len(pairs)} pairs -> {args.out / 'manifest.json'}")


if __name__ == "__main__":
    main()
