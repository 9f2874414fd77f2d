"""Map-pair datasets on disk: the versioned format, atomic writes, typed loading.

A **map pair** is what two robots knew at one moment of an episode — both topological maps and
both occupancy grids, each in its robot's own frame — plus the ground truth a merge is judged
against: the rigid transform taking robot B's frame onto robot A's (``p_A = R p_B + T``) and the
overlap of the two explored areas.

Layout of a dataset folder (format ``topomerge.map_pairs``, version :data:`FORMAT_VERSION`)::

    DIR/
      dataset.json          what generated it (explorer, world, seed, snapshots, env config) —
                            a resumed run must match it — and ``pairs``, how many pairs it
                            holds (ids 0 … pairs − 1; absent in datasets made before it existed)
      index.json            one summary row per pair (rebuilt from the pair files at any time)
      .lock                 only while a writer runs (:data:`LOCK_FILE`): one writer at a time
      pairs/
        pair_000000.npz     one compressed numpy archive per pair (arrays below)
        pair_000001.npz
        ...

Arrays of a pair file (``X`` is ``a`` or ``b``):

| key               | dtype   | shape  | meaning                                          |
|-------------------|---------|--------|--------------------------------------------------|
| ``meta``          | str     | ()     | JSON metadata (below)                            |
| ``X_xy``          | float64 | (N, 2) | topological map nodes (m, robot X's frame)       |
| ``X_kinds``       | int8    | (N,)   | :class:`topo.NodeKind` codes                      |
| ``X_edges``       | int64   | (E, 2) | paths as node index pairs                        |
| ``X_lengths``     | float64 | (E,)   | path lengths (m)                                 |
| ``X_path_xy``     | float64 | (K, 2) | all path polylines, concatenated (optional)      |
| ``X_path_offsets``| int64   | (E+1,) | polyline ``e`` = ``X_path_xy[off[e]:off[e+1]]``  |
| ``X_clearance``   | float64 | (N,)   | node clearances (m; optional, 0 if absent)       |
| ``X_frontier``    | bool    | (N,)   | nodes on the frontier (optional, none if absent) |
| ``X_grid``        | int8    | (H, W) | cell-state codes ``[iy, ix]``, row 0 at bottom   |

``meta`` holds: format, version, pair_id, transform ``[theta, tx, ty]`` (B → A), overlap,
world_id, seed, explorer, step, episode, snapshot, each grid's resolution and origin, extra.
In a team's dataset (``python -m agents.dataset generate --robots N``) every robot pair
``i < j`` of a snapshot is a pair: ``extra["robots"] = [i, j]``, map A is robot i's, map B
robot j's and the transform takes j's frame onto i's; a pair without that key is robots
``(0, 1)``. Pairs made with drifting odometry (``--odometry``) also hold in ``extra`` the truth
at the robots' current places (``current_transform``, ``current_places``) and both robots'
trajectories (``trajectory_a``, ``trajectory_b``: rows ``[x, y, θ, true x, true y, true θ]``,
odometry in the robot's map frame, truth in its start frame), which
``fusion.evaluation.bending.PairTrajectories`` reads.

Every file is written to a temporary name in the same folder and renamed into place, so a pair
file either exists whole or not at all; anything else in ``pairs/`` is an error naming the file
and what to do: a foreign file, a pair file beyond the manifest's ``pairs`` (a stray: indexing
it would count a pair the dataset does not have), a pair file holding another pair id (a copy),
a corrupt file (delete it and rerun the generating command, which writes it again).
"""

from __future__ import annotations

import io
import json
import re
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fusion.rigid import Rigid2D
from topo.fileio import TEMP_PREFIX, atomic_write_bytes, atomic_write_json
from topo.graph import TopoMap

FORMAT = "topomerge.map_pairs"
FORMAT_VERSION = 1
PAIR_FILE = re.compile(r"^pair_(\d{6,})\.npz$")
LOCK_FILE = ".lock"
"""Name of the lock file a writer holds in the dataset folder (``topo.fileio.exclusive_lock``)."""


class DatasetError(ValueError):
    """A dataset folder or file that is not what this format expects (names the file)."""


_REWRITE = ("delete it and rerun the command that generated the dataset (python -m "
            "agents.dataset generate with its settings): it writes the missing pair again")


@dataclass(frozen=True, slots=True, eq=False)
class GridSnapshot:
    """An occupancy grid's states at one moment: ``states[iy, ix]`` (row 0 at the bottom) of
    ``topo`` cell-state codes, cell size ``resolution`` (m) and the world position ``origin`` of
    the lower-left corner of cell (0, 0), in the robot's own frame."""

    states: np.ndarray
    resolution: float
    origin: tuple[float, float]


@dataclass(frozen=True, slots=True, eq=False)
class MapPair:
    """One stored pair: both robots' maps at one moment and the truth relating their frames.

    Attributes:
        pair_id: position in the dataset (``pair_000042.npz`` is pair 42).
        map_a, map_b: topological maps of robot A (``robot_0``) and B (``robot_1``), own frames.
        grid_a, grid_b: their occupancy grids.
        transform: the true B → A transform (``p_A = R p_B + T``).
        overlap: explored area both robots share / the smaller robot's explored area, in [0, 1].
        world_id: which world (procedural seed or map file name).
        seed: the episode's seed.
        explorer: the explorer's name.
        step: env step at which the snapshot was taken.
        episode, snapshot: which episode of the run and which snapshot within it.
        extra: further JSON-safe metadata (kept as read).
    """

    pair_id: int
    map_a: TopoMap
    map_b: TopoMap
    grid_a: GridSnapshot
    grid_b: GridSnapshot
    transform: Rigid2D
    overlap: float
    world_id: str
    seed: int
    explorer: str
    step: int
    episode: int
    snapshot: int
    extra: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """The JSON-safe row of ``index.json``."""
        return {
            "pair_id": self.pair_id, "episode": self.episode, "snapshot": self.snapshot,
            "step": self.step, "seed": self.seed, "world_id": self.world_id,
            "explorer": self.explorer, "overlap": self.overlap,
            "nodes_a": self.map_a.n_nodes, "nodes_b": self.map_b.n_nodes,
            "theta_deg": self.transform.degrees,
        }


def pair_path(root: str | Path, pair_id: int) -> Path:
    """Where pair ``pair_id`` lives in dataset ``root``."""
    return Path(root) / "pairs" / f"pair_{pair_id:06d}.npz"


def _map_arrays(prefix: str, m: TopoMap) -> dict[str, np.ndarray]:
    out = {
        f"{prefix}_xy": m.xy, f"{prefix}_kinds": m.kinds,
        f"{prefix}_edges": m.edges, f"{prefix}_lengths": m.lengths,
        f"{prefix}_clearance": m.clearance, f"{prefix}_frontier": m.frontier,
    }
    if m.paths is not None:
        sizes = [len(p) for p in m.paths]
        out[f"{prefix}_path_offsets"] = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        out[f"{prefix}_path_xy"] = (np.concatenate(m.paths) if m.paths
                                    else np.empty((0, 2)))
    return out


def write_pair(root: str | Path, pair: MapPair) -> Path:
    """Store ``pair`` as ``root/pairs/pair_<id>.npz`` atomically; returns the path."""
    meta = {
        "format": FORMAT, "version": FORMAT_VERSION, "pair_id": pair.pair_id,
        "transform": [pair.transform.theta, *pair.transform.T.tolist()],
        "overlap": pair.overlap, "world_id": pair.world_id, "seed": pair.seed,
        "explorer": pair.explorer, "step": pair.step, "episode": pair.episode,
        "snapshot": pair.snapshot,
        "grid_a": {"resolution": pair.grid_a.resolution, "origin": list(pair.grid_a.origin)},
        "grid_b": {"resolution": pair.grid_b.resolution, "origin": list(pair.grid_b.origin)},
        "extra": pair.extra,
    }
    arrays = {
        "meta": np.array(json.dumps(meta)),
        **_map_arrays("a", pair.map_a), **_map_arrays("b", pair.map_b),
        "a_grid": np.asarray(pair.grid_a.states, dtype=np.int8),
        "b_grid": np.asarray(pair.grid_b.states, dtype=np.int8),
    }
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    path = pair_path(root, pair.pair_id)
    atomic_write_bytes(path, buf.getvalue())
    return path


# --------------------------------------------------------------------------- reading
def _read_map(z: Any, prefix: str) -> TopoMap:
    paths = None
    if f"{prefix}_path_offsets" in z:
        off, pts = z[f"{prefix}_path_offsets"], z[f"{prefix}_path_xy"]
        paths = [pts[off[e]:off[e + 1]] for e in range(len(off) - 1)]
    extra = [z[k] if k in z else None for k in (f"{prefix}_clearance", f"{prefix}_frontier")]
    return TopoMap.from_arrays(z[f"{prefix}_xy"], z[f"{prefix}_edges"], z[f"{prefix}_kinds"],
                               z[f"{prefix}_lengths"], paths, *extra)


def read_pair(path: str | Path) -> MapPair:
    """Load one pair file; a truncated, foreign or invalid file raises :class:`DatasetError`
    naming it."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if meta.get("format") != FORMAT or meta.get("version") != FORMAT_VERSION:
                raise DatasetError(
                    f"{path}: not a {FORMAT} version {FORMAT_VERSION} pair "
                    f"(format={meta.get('format')!r}, version={meta.get('version')!r})")
            theta, tx, ty = meta["transform"]
            named = PAIR_FILE.match(path.name)
            if named is not None and int(named.group(1)) != int(meta["pair_id"]):
                raise DatasetError(f"{path}: holds pair {int(meta['pair_id'])}, not "
                                   f"{int(named.group(1))} (a copied or renamed file): "
                                   f"{_REWRITE}")
            return MapPair(
                pair_id=int(meta["pair_id"]),
                map_a=_read_map(z, "a"), map_b=_read_map(z, "b"),
                grid_a=GridSnapshot(z["a_grid"], float(meta["grid_a"]["resolution"]),
                                    tuple(meta["grid_a"]["origin"])),
                grid_b=GridSnapshot(z["b_grid"], float(meta["grid_b"]["resolution"]),
                                    tuple(meta["grid_b"]["origin"])),
                transform=Rigid2D(theta, (tx, ty)), overlap=float(meta["overlap"]),
                world_id=str(meta["world_id"]), seed=int(meta["seed"]),
                explorer=str(meta["explorer"]), step=int(meta["step"]),
                episode=int(meta["episode"]), snapshot=int(meta["snapshot"]),
                extra=dict(meta.get("extra", {})),
            )
    except DatasetError:
        raise
    except FileNotFoundError:
        raise
    except (OSError, zipfile.BadZipFile, KeyError, ValueError, TypeError, EOFError) as exc:
        raise DatasetError(f"{path}: corrupt or not a map-pair file ({exc}): {_REWRITE}"
                           ) from exc


def pair_files(root: str | Path, *, clean_temp: bool = False,
               count: int | None = None) -> dict[int, Path]:
    """The pair files of dataset ``root`` by id. Left-over temporary files of an interrupted
    write are ignored (removed with ``clean_temp``); any other file in ``pairs/``, and with
    ``count`` (the manifest's :func:`pair_count`) a pair file of an id ``>= count``, is a
    :class:`DatasetError` naming the file and what to do."""
    folder = Path(root) / "pairs"
    found: dict[int, Path] = {}
    if not folder.is_dir():
        return found
    for p in sorted(folder.iterdir()):
        if p.name.startswith(TEMP_PREFIX):
            if clean_temp:
                p.unlink(missing_ok=True)
            continue
        match = PAIR_FILE.match(p.name)
        if match is None or not p.is_file():
            raise DatasetError(f"{p}: foreign file in a map-pair dataset "
                               "(expected pair_NNNNNN.npz)")
        pair_id = int(match.group(1))
        if count is not None and pair_id >= count:
            raise DatasetError(f"{p}: a stray file: this dataset holds pairs 0–{count - 1} "
                               f"(dataset.json: pairs={count}); move it out of {folder} or "
                               f"delete it")
        found[pair_id] = p
    return found


def pair_count(manifest: dict[str, Any]) -> int | None:
    """How many pairs a dataset's manifest says it holds (``pairs``), or ``None`` for a
    manifest written before that key existed.

    Raises:
        DatasetError: ``pairs`` is not an integer ``>= 0``.
    """
    count = manifest.get("pairs")
    if count is None:
        return None
    if isinstance(count, bool) or not isinstance(count, int) or count < 0:
        raise DatasetError(f"dataset.json: pairs must be an integer >= 0, got {count!r}")
    return count


def read_manifest(root: str | Path) -> dict[str, Any]:
    """``dataset.json`` of ``root`` (validated)."""
    path = Path(root) / "dataset.json"
    if not path.is_file():
        raise DatasetError(f"{path}: missing; {root} is not a map-pair dataset")
    try:
        manifest = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise DatasetError(f"{path}: unreadable ({exc})") from exc
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise DatasetError(f"{path}: not a {FORMAT} manifest")
    if manifest.get("version") != FORMAT_VERSION:
        raise DatasetError(f"{path}: version {manifest.get('version')!r} is not supported "
                           f"(this topomerge reads version {FORMAT_VERSION})")
    return manifest


def iter_pairs(root: str | Path) -> Iterator[MapPair]:
    """Pairs of dataset ``root`` in id order, read one at a time."""
    count = pair_count(read_manifest(root))
    for _, path in sorted(pair_files(root, count=count).items()):
        yield read_pair(path)


def load_pairs(root: str | Path) -> list[MapPair]:
    """All pairs of dataset ``root``, in id order (see the module docstring for the format).

    Raises:
        DatasetError: missing/foreign manifest, a foreign or stray file in ``pairs/``, or a
            corrupt pair file — each naming the file and what to do.
    """
    return list(iter_pairs(root))


def write_index(root: str | Path) -> list[dict[str, Any]]:
    """Rebuild ``index.json`` from the pair files; returns its rows."""
    rows = [pair.summary() for pair in iter_pairs(root)]
    atomic_write_json(Path(root) / "index.json", {"format": FORMAT, "version": FORMAT_VERSION,
                                                   "pairs": rows})
    return rows
