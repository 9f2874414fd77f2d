"""The map-merge tool: merge two or more robots' saved occupancy maps into one, from the
command line (``python -m fusion merge MAP MAP [MAP ...] --out DIR``) or from Python
(:func:`merge_files`, :func:`merge_maps_n`).

Why: a robot builder with ROS maps from separate runs or robots, and no known initial poses,
needs the merged map and the transforms between the maps without writing Python.

Inputs (:func:`load_input`):

* a ROS ``map_server`` YAML and its PGM/PNG (:func:`topo.maps.load_ros_map`: ``resolution``,
  ``origin`` with its yaw, ``negate``, ``occupied_thresh``, ``free_thresh``, ``mode``);
* a plain image (``.pgm``, ``.png``, ``.jpg``, ``.bmp``) at ``--resolution`` m/pixel, read
  with ``map_server``'s default thresholds (``--plain ros``) or the DungeonMaps rule
  (``--plain dungeon``: grey > 150 free, darker occupied);
* a map-pair file of this project (``pair_NNNNNN.npz``, :mod:`fusion.evaluation.pairs`): both
  of its grids, or one of them with ``FILE.npz:a`` / ``FILE.npz:b``.

Every map is cropped to its known cells and resampled to the merge resolution (the first
map's, or ``--out-resolution``). Every pair is aligned by :func:`fusion.grid_merge.merge_grids`
(its calibrated confidence and accept rule: by default the confidence model fitted on real
sensor maps and its threshold, ``--confidence-model real``, :data:`CONFIDENCE_MODELS`; ``sim``
is the env's); the accepted pairs are assembled by
:func:`fusion.team.consistent_edges` (look-alike merges broken by the cycle check left out) and
:func:`fusion.team.frames_from`; the largest consistent group is merged into the frame of its
first map and every other map is listed as not merged, with why.

Outputs in ``--out DIR`` (each file written atomically): ``merged.yaml`` + ``merged.pgm`` (a
trinary map ``map_server`` loads: occupied where any merged map is occupied, else free where
any is free), ``merged.png`` (each map's cells in its own colour), ``transforms.yaml`` and
``transforms.json`` (every map's transform into the reference map's frame: ``x``, ``y``,
``yaw``, ``confidence``, ``method``, ``merged`` and ``why`` not). When no two maps merge, no
merged map is written (an old one is removed) unless ``--write-unmerged``.

Exit codes: :data:`EXIT_MERGED` (0) every map merged; :data:`EXIT_NOT_MERGED` (1) some map not
merged; :data:`EXIT_BAD_INPUT` (2) a file that is not a usable map or a bad argument, with a
one-line error naming the file and what is wrong.
"""

from __future__ import annotations

import argparse
import io
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import networkx as nx
import numpy as np
from scipy import ndimage

from fusion.decision import REAL_MAP_MODEL, MergeRule, model_threshold
from fusion.grid_layers import LayerCache, pooled_layers
from fusion.grid_merge import GridMergeConfig, GridMergeResult, merge_grids
from fusion.rigid import Rigid2D
from fusion.team import Edge, consistent_edges, frames_from
from topo.fileio import atomic_write_bytes, atomic_write_json
from topo.grid import CellState
from topo.maps import (
    FloorPlan,
    MapFileError,
    load_dungeon_png,
    load_plain_image,
    load_ros_map,
    save_ros_map,
)
from topo.validation import check_real

EXIT_MERGED = 0
"""Exit code: every map merged."""
EXIT_NOT_MERGED = 1
"""Exit code: some map not merged."""
EXIT_BAD_INPUT = 2
"""Exit code: a file that is not a usable map, or a bad argument (exit codes of :func:`main`)."""

IMAGE_SUFFIXES = (".pgm", ".png", ".jpg", ".jpeg", ".bmp")
"""Suffixes read as plain images (no YAML: ``--resolution`` gives their scale)."""

MERGED_FILES = ("merged.yaml", "merged.pgm", "merged.png")
"""The merged map's files in the output folder."""

PALETTE = np.array([(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40),
                    (148, 103, 189), (140, 86, 75), (227, 119, 194), (127, 127, 127),
                    (188, 189, 34), (23, 190, 207)], dtype=np.float64)
"""Colour of each input map's walls in ``merged.png`` (repeats after ten maps)."""

CONFIDENCE_MODELS = {"real": REAL_MAP_MODEL, "sim": "grid"}
"""``--confidence-model`` → the calibrated model the pairs' confidence is computed by: ``real``
(the default) fitted on real sensor-map pairs, ``sim`` the env's (fitted on its simulated
maps); each with its own accept threshold (:func:`tool_config`)."""

_UNKNOWN, _FREE, _OCC = int(CellState.UNKNOWN), int(CellState.FREE), int(CellState.OCCUPIED)


@dataclass(frozen=True, slots=True, eq=False)
class InputMap:
    """One map to merge: cell-state codes ``states[iy, ix]`` (row 0 at the bottom,
    :class:`topo.CellState`), ``resolution`` (m), ``origin`` of cell (0, 0)'s lower-left
    corner, its ``name`` and the ``source`` file, and the ROS origin's ``yaw`` about ``pivot``
    (the file's own origin, kept when the map is cropped). A grid for
    :func:`fusion.grid_merge.merge_grids`: its cells are in the unturned grid frame,
    :attr:`frame` takes them into the map's."""

    name: str
    source: str
    states: np.ndarray
    resolution: float
    origin: tuple[float, float]
    yaw: float = 0.0
    pivot: tuple[float, float] = (0.0, 0.0)

    @property
    def frame(self) -> Rigid2D:
        """The grid's frame → the map's frame: a turn by ``yaw`` about ``pivot``."""
        o = np.asarray(self.pivot, dtype=np.float64)
        turn = Rigid2D(self.yaw)
        return Rigid2D(self.yaw, o - turn.apply(o[None])[0])

    def centre(self) -> np.ndarray:
        """Mean position of the known cells (grid frame): where transforms are compared."""
        rows, cols = np.nonzero(self.states != _UNKNOWN)
        return np.asarray(self.origin) + (np.array([cols.mean(), rows.mean()]) + 0.5
                                          ) * self.resolution


def _from_plan(plan: FloorPlan, source: str) -> InputMap:
    states = np.full(plan.free.shape, _UNKNOWN, dtype=np.int8)
    states[plan.free] = _FREE
    states[plan.occupied] = _OCC
    origin = (float(plan.origin[0]), float(plan.origin[1]))
    return InputMap(plan.name, source, states, float(plan.resolution), origin,
                    float(plan.yaw), origin)


def _plain_image(path: Path, resolution: float | None, plain: str) -> FloorPlan:
    if resolution is None:
        load_plain_image(path, 1.0)  # a missing file or no image says so first
        raise MapFileError(f"{path}: a plain image has no scale: give --resolution (metres "
                           "per pixel)")
    if plain == "dungeon":
        return load_dungeon_png(path, resolution)
    return load_plain_image(path, resolution)  # map_saver's default thresholds


def _pair_grids(spec: str) -> list[InputMap]:
    from fusion.evaluation.pairs import DatasetError, read_pair

    file, _, which = spec.partition(".npz:")
    path = Path(file + ".npz" if which else spec)
    if which not in ("", "a", "b"):
        raise MapFileError(f"{spec}: a map-pair file's grid is ':a' or ':b', got {which!r}")
    if not path.is_file():
        raise MapFileError(f"{path}: map-pair file not found")
    try:
        pair = read_pair(path)
    except DatasetError as exc:
        raise MapFileError(str(exc)) from exc
    grids = {"a": pair.grid_a, "b": pair.grid_b}
    return [InputMap(f"{path.stem}:{k}", f"{path}:{k}", np.asarray(g.states, dtype=np.int8),
                     float(g.resolution), (float(g.origin[0]), float(g.origin[1])))
            for k, g in grids.items() if which in ("", k)]


def load_input(spec: str, resolution: float | None = None, plain: str = "ros"
               ) -> list[InputMap]:
    """The map(s) of one command-line argument (module docstring; a map-pair file gives two).

    Raises:
        MapFileError: the file is missing, not a map of a known format, malformed (the message
            names it and what is wrong), or has no known cell.
    """
    path = Path(spec)
    suffix = path.suffix.lower()
    if ".npz:" in spec or suffix == ".npz":
        maps = _pair_grids(spec)
    elif suffix in (".yaml", ".yml"):
        maps = [_from_plan(load_ros_map(path, allow_yaw=True), spec)]
    elif suffix in IMAGE_SUFFIXES:
        maps = [_from_plan(_plain_image(path, resolution, plain), spec)]
    elif not path.exists():
        raise MapFileError(f"{path}: file not found")
    else:
        kind = repr(suffix) if suffix else "without a suffix"
        raise MapFileError(f"{path}: not a map file (unknown format {kind}"
                           f"; expected a ROS map .yaml, an image {'/'.join(IMAGE_SUFFIXES)} or "
                           "a map-pair .npz)")
    out = []
    for m in maps:
        if not (m.states == _OCC).any():
            what = "all unknown" if not (m.states == _FREE).any() else "no occupied cell"
            raise MapFileError(f"{m.source}: empty map ({what}): nothing to align")
        out.append(_cropped(m))
    return out


def _cropped(m: InputMap) -> InputMap:
    """``m`` cut to the bounding box of its known cells (origin moved to match)."""
    rows, cols = np.nonzero(m.states != _UNKNOWN)
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    origin = (m.origin[0] + c0 * m.resolution, m.origin[1] + r0 * m.resolution)
    return InputMap(m.name, m.source, np.ascontiguousarray(m.states[r0:r1, c0:c1]),
                    m.resolution, origin, m.yaw, m.pivot)


def resampled(m: InputMap, resolution: float) -> InputMap:
    """``m`` at ``resolution`` m/cell: pooled when coarser (a cell is occupied if any fine cell
    is, free if most are: :func:`fusion.grid_layers.pooled_layers`), nearest cell when finer;
    ``m`` itself when already at it. The rotation about ``origin`` (``yaw``) is kept, the
    origin moves to the corner of the known cells."""
    if math.isclose(m.resolution, resolution, rel_tol=1e-9):
        return m
    if m.resolution < resolution:
        wall, free, origin = pooled_layers(m, resolution)
        states = np.where(wall, _OCC, np.where(free, _FREE, _UNKNOWN)).astype(np.int8)
        # pooled_layers crops to the known cells; its origin is in the grid frame, as m's
        return InputMap(m.name, m.source, states, resolution, (float(origin[0]),
                                                               float(origin[1])), m.yaw,
                        m.pivot)
    zoom = m.resolution / resolution
    shape = (max(1, round(m.states.shape[0] * zoom)), max(1, round(m.states.shape[1] * zoom)))
    states = ndimage.zoom(m.states, (shape[0] / m.states.shape[0],
                                     shape[1] / m.states.shape[1]), order=0, grid_mode=True,
                          mode="grid-constant", cval=_UNKNOWN)
    return InputMap(m.name, m.source, states.astype(np.int8), resolution, m.origin, m.yaw,
                    m.pivot)


@dataclass(frozen=True, slots=True)
class Placement:
    """One input map in the merge (a row of ``transforms.yaml``).

    Attributes:
        name, source: the map and its file.
        merged: whether it is in the merged map.
        transform: its map frame → the reference map's frame (``None`` when not merged).
        confidence: the least confidence of the pairwise merges that place it (1 for the
            reference; for a map not merged, its best pair's).
        method: how it was placed.
        why: why it was not merged (``None`` when merged).
    """

    name: str
    source: str
    merged: bool
    transform: Rigid2D | None
    confidence: float
    method: str
    why: str | None = None

    def row(self) -> dict[str, Any]:
        """Its JSON-safe row of ``transforms.yaml``/``.json`` (``x``, ``y``, ``yaw`` ``None``
        when not merged)."""
        t = self.transform
        return {"name": self.name, "source": self.source, "merged": self.merged,
                "x": None if t is None else float(t.T[0]),
                "y": None if t is None else float(t.T[1]),
                "yaw": None if t is None else float(t.theta),
                "yaw_deg": None if t is None else float(t.degrees),
                "confidence": round(float(self.confidence), 6), "method": self.method,
                "why": self.why}


@dataclass(frozen=True, slots=True, eq=False)
class TeamMerge:
    """What :func:`merge_maps_n` found: ``placements`` (one per input, in order), the
    ``reference`` input whose frame the merged map is in, the ``pairs`` ``(i, j) →``
    :class:`fusion.grid_merge.GridMergeResult` (j's grid frame → i's), the ``merged`` map
    (:class:`topo.maps.FloorPlan`, ``None`` when no two maps merged) and ``owner``, the index
    (among the merged maps, in input order) of the map that decided each of its cells (−1:
    unknown)."""

    placements: list[Placement]
    reference: int
    pairs: dict[tuple[int, int], GridMergeResult] = field(default_factory=dict)
    merged: FloorPlan | None = None
    owner: np.ndarray | None = None

    @property
    def all_merged(self) -> bool:
        """Whether every input map is in the merged map."""
        return all(p.merged for p in self.placements)


def merge_maps_n(maps: Sequence[InputMap], config: GridMergeConfig | None = None,
                 rule: MergeRule | None = None) -> TeamMerge:
    """Merge two or more maps of one resolution (module docstring).

    Args:
        maps: the maps (:func:`load_input`, :func:`resampled` to one resolution).
        config: the pairwise alignment's settings.
        rule: the team rule (its ``team_min_unconfirmed`` for three maps or more).

    Returns:
        a :class:`TeamMerge`.

    Raises:
        ValueError: fewer than two maps, maps at different resolutions, or a map too large
            for the alignment (:data:`fusion.inputs.MAX_POOLED_CELLS`), naming the files.
    """
    if len(maps) < 2:
        raise ValueError(f"maps: need two or more maps to merge, got {len(maps)}")
    res = maps[0].resolution
    for m in maps[1:]:
        if not math.isclose(m.resolution, res, rel_tol=1e-9):
            raise ValueError(f"maps: {m.name} is at {m.resolution:g} m, not {res:g} m: "
                             "resample it first (fusion.mapmerge.resampled)")
    rule = rule or MergeRule()
    pairs, edges = {}, []
    grids = [LayerCache(m) for m in maps]  # each map pooled once for all its pairs
    for i in range(len(maps)):
        for j in range(i + 1, len(maps)):
            try:
                r = merge_grids(grids[i], grids[j], config)
            except ValueError as exc:  # a map beyond fusion.inputs' bounds: name the files
                raise ValueError(f"{maps[i].source} and {maps[j].source}: {exc}") from exc
            pairs[(i, j)] = r
            if r.accepted:
                edges.append(Edge(i, j, r.transform, float(r.confidence)))
    centres = {k: m.centre() for k, m in enumerate(maps)}
    check = consistent_edges(edges, centres,
                             min_unconfirmed=rule.team_min_unconfirmed(len(maps)))
    graph = nx.Graph()
    graph.add_nodes_from(range(len(maps)))
    graph.add_edges_from(check.consistent)
    groups = sorted(nx.connected_components(graph), key=lambda g: (-len(g), min(g)))
    group = groups[0]
    root = min(group)
    frames = frames_from(root, {p: e for p, e in check.consistent.items() if p[0] in group},
                         centres) if len(group) > 1 else {root: (Rigid2D.identity(),) * 2}
    placements = []
    for k, m in enumerate(maps):
        if k in frames:
            # k's map frame → k's grid → root's grid → root's map frame
            t = maps[root].frame @ frames[k][0] @ m.frame.inverse()
            if k == root:
                conf, method = 1.0, "reference"
            else:
                path = nx.shortest_path(graph, root, k)
                conf = min(check.consistent[tuple(sorted(ab))].confidence
                           for ab in zip(path, path[1:], strict=False))
                method = ("merge_grids" if len(path) == 2 else
                          "merge_grids via " + ", ".join(maps[v].name for v in path[1:-1]))
            placements.append(Placement(m.name, m.source, len(group) > 1, t, conf, method,
                                        None if len(group) > 1 else _why(k, maps, pairs,
                                                                         check)))
        else:
            best = max((r.confidence for p, r in pairs.items() if k in p), default=0.0)
            placements.append(Placement(m.name, m.source, False, None, best, "merge_grids",
                                        _why(k, maps, pairs, check)))
    out = TeamMerge(placements, root, pairs)
    if len(group) > 1:
        out = TeamMerge(placements, root, pairs,
                        *merged_plan([maps[k] for k in sorted(group)],
                                     [placements[k].transform for k in sorted(group)],
                                     maps[root]))
    return out


def merged_plan(maps: Sequence[InputMap], to_ref: Sequence[Rigid2D], ref: InputMap
                ) -> tuple[FloorPlan, np.ndarray]:
    """:func:`rasterise` into the cells of ``ref``'s grid, as a plan in ``ref``'s map frame
    (origin and yaw as ``map_server`` reads them), and the owner of each cell."""
    plan, owner = rasterise(maps, to_ref, ref.frame.inverse(), ref.resolution)
    corner = ref.frame.apply(np.asarray([plan.origin], dtype=np.float64))[0]
    return FloorPlan(plan.free, plan.occupied, plan.resolution,
                     (float(corner[0]), float(corner[1])), "merged", ref.yaw), owner


def _why(k: int, maps: Sequence[InputMap], pairs: dict, check: Any) -> str:
    """Why map ``k`` is not in the merged group."""
    left = {"disputed by the cycle check": check.disputed,
            "contradicted by the other merges": check.rejected,
            "below the team's confidence for a merge no cycle confirms": check.unconfirmed}
    for what, which in left.items():
        mine = [p for p in which if k in p]
        if mine:
            others = ", ".join(maps[b if a == k else a].name for a, b in mine)
            return f"its merge with {others} was left out: {what}"
    accepted = [p for p, r in pairs.items() if k in p and r.accepted]
    if accepted:
        return "merged only with maps outside the largest merged group"
    p, r = max(((p, r) for p, r in pairs.items() if k in p),
               key=lambda pr: pr[1].confidence)
    other = maps[p[1] if p[0] == k else p[0]].name
    return (f"no pair accepted (best: with {other}, confidence {r.confidence:.2f}: "
            f"{r.reason})")


def rasterise(maps: Sequence[InputMap], to_ref: Sequence[Rigid2D], ref_from_map: Rigid2D,
              resolution: float) -> tuple[FloorPlan, np.ndarray]:
    """The maps drawn into one grid: occupied where any is occupied, else free where any is
    free (``map_server``'s view of a merged map). ``to_ref``: each map's frame → the reference
    map's frame; ``ref_from_map``: the reference map's frame → the output grid's frame (the
    reference grid's: the output is axis-aligned with the reference map's cells). Returns the
    plan and ``owner``, the index of the map that decided each cell (−1: unknown).

    Nearest-cell lookup by ``scipy.ndimage.affine_transform`` (order 0)."""
    into = [ref_from_map @ t @ m.frame for m, t in zip(maps, to_ref, strict=True)]
    corners = []
    for m, g in zip(maps, into, strict=True):
        h, w = m.states.shape
        box = np.array([[0, 0], [w, 0], [0, h], [w, h]], dtype=np.float64) * m.resolution
        corners.append(g.apply(box + np.asarray(m.origin)))
    pts = np.vstack(corners)
    lo = np.floor(pts.min(axis=0) / resolution) * resolution
    shape = tuple(int(v) for v in np.ceil((pts.max(axis=0) - lo) / resolution).astype(int)[::-1])
    occ = np.zeros(shape, dtype=bool)
    free = np.zeros(shape, dtype=bool)
    owner = np.full(shape, -1, dtype=np.int16)
    for k, (m, g, c) in enumerate(zip(maps, into, corners, strict=True)):
        inv = g.inverse()  # output (world) → map k's grid frame
        # only the output cells within map k's box (and a cell more) can see it
        c0, r0 = np.maximum(np.floor((c.min(axis=0) - lo) / resolution).astype(int) - 1, 0)
        c1, r1 = np.minimum(np.ceil((c.max(axis=0) - lo) / resolution).astype(int) + 1,
                            shape[::-1])
        # output index (row, col) → world centre → k's cell index (row, col)
        a = inv.R[::-1, ::-1] * (resolution / m.resolution)
        centre0 = lo + (np.array([c0, r0]) + 0.5) * resolution
        off_xy = (inv.apply(centre0[None])[0] - np.asarray(m.origin)) / m.resolution - 0.5
        st = ndimage.affine_transform(m.states, a, offset=off_xy[::-1],
                                      output_shape=(r1 - r0, c1 - c0), order=0,
                                      mode="constant", cval=_UNKNOWN)
        box = np.s_[r0:r1, c0:c1]
        is_occ, is_free = st == _OCC, st == _FREE
        owner[box][is_occ & ~occ[box]] = k
        owner[box][is_free & ~occ[box] & ~free[box] & (owner[box] < 0)] = k
        occ[box] |= is_occ
        free[box] |= is_free
    free &= ~occ
    plan = FloorPlan(free, occ, resolution, (float(lo[0]), float(lo[1])), "merged")
    return plan, owner


def picture(team: TeamMerge) -> np.ndarray:
    """``merged.png``'s RGB image (row 0 at the top): unknown grey, free white, each map's
    walls in its :data:`PALETTE` colour (the map whose cell it is), free space faintly so."""
    plan = team.merged
    rgb = np.full((*plan.free.shape, 3), 205.0)
    owner = np.maximum(team.owner, 0)
    colour = PALETTE[owner % len(PALETTE)]
    rgb[plan.free] = 255.0 - 0.15 * (255.0 - colour[plan.free])
    rgb[plan.occupied] = colour[plan.occupied]
    return np.ascontiguousarray(rgb[::-1].astype(np.uint8))


def write_outputs(team: TeamMerge, out: Path, *, write_unmerged: bool = False,
                  maps: Sequence[InputMap] = ()) -> list[Path]:
    """Write the merge into folder ``out`` (module docstring); returns the files written."""
    from PIL import Image

    out.mkdir(parents=True, exist_ok=True)
    written = []
    rows = [p.row() for p in team.placements]
    drawn = ([k for k, p in enumerate(team.placements) if p.merged]
             or ([team.reference] if write_unmerged else []))
    for n, k in enumerate(drawn):  # merged.png's colour of each drawn map (picture's order)
        rows[k]["colour"] = "#{:02x}{:02x}{:02x}".format(*PALETTE[n % len(PALETTE)].astype(int))
    doc = {"reference": team.placements[team.reference].name,
           "frame": "the reference map's frame (its ROS origin frame)",
           "all_merged": team.all_merged, "maps": rows}
    written.append(atomic_write_json(out / "transforms.json", doc, allow_nan=False))
    import yaml

    written.append(atomic_write_bytes(out / "transforms.yaml",
                                      yaml.safe_dump(doc, sort_keys=False).encode()))
    if team.merged is None and write_unmerged and maps:
        ref = maps[team.reference]
        team = TeamMerge(team.placements, team.reference, team.pairs,
                         *merged_plan([ref], [Rigid2D.identity()], ref))
    if team.merged is None:
        for name in MERGED_FILES:  # an earlier run's merged map would look like this one's
            (out / name).unlink(missing_ok=True)
        return written
    written.append(save_ros_map(team.merged, out / "merged.yaml"))
    buf = io.BytesIO()
    Image.fromarray(picture(team)).save(buf, format="PNG")
    written.append(atomic_write_bytes(out / "merged.png", buf.getvalue()))
    return written


def tool_config(confidence_model: str = "real") -> GridMergeConfig:
    """The pairwise alignment's settings of the tool: the defaults, with the confidence model
    ``confidence_model`` names (:data:`CONFIDENCE_MODELS`) and its threshold
    (:func:`fusion.decision.model_threshold`; the env's own default for ``sim``).

    Raises:
        ValueError: ``confidence_model`` not a key of :data:`CONFIDENCE_MODELS`.
    """
    if confidence_model not in CONFIDENCE_MODELS:
        raise ValueError(f"confidence_model must be one of {sorted(CONFIDENCE_MODELS)}, got "
                         f"{confidence_model!r}")
    if confidence_model == "sim":
        return GridMergeConfig()
    name = CONFIDENCE_MODELS[confidence_model]
    return GridMergeConfig(confidence_model=name, accept_threshold=model_threshold(name))


def merge_files(specs: Sequence[str], out: str | Path, *, resolution: float | None = None,
                out_resolution: float | None = None, plain: str = "ros",
                write_unmerged: bool = False,
                config: GridMergeConfig | None = None,
                confidence_model: str = "real") -> TeamMerge:
    """Load the maps of ``specs`` (:func:`load_input`), resample them to ``out_resolution``
    (default: the first map's), merge them (:func:`merge_maps_n`; with ``config``, else
    :func:`tool_config` of ``confidence_model``) and write the outputs into ``out``
    (:func:`write_outputs`).

    Raises:
        MapFileError: a file that is not a usable map (named).
        ValueError: fewer than two maps, a bad ``resolution``/``out_resolution`` or
            ``confidence_model``.
    """
    config = config or tool_config(confidence_model)
    if resolution is not None:
        check_real(resolution, "--resolution", low=0.0)
    maps = [m for s in specs for m in load_input(s, resolution, plain)]
    if len(maps) < 2:
        raise ValueError(f"need two or more maps to merge, got {len(maps)}")
    target = maps[0].resolution if out_resolution is None else check_real(
        out_resolution, "--out-resolution", low=0.0)
    maps = [resampled(m, target) for m in maps]
    team = merge_maps_n(maps, config)
    write_outputs(team, Path(out), write_unmerged=write_unmerged, maps=maps)
    return team


def parser(prog: str = "python -m fusion merge") -> argparse.ArgumentParser:
    """The command line's parser (``prog``: the name its messages start with)."""
    p = argparse.ArgumentParser(
        prog=prog, description="Merge two or more robots' occupancy maps (ROS map_server "
        "YAML, plain images, map-pair .npz) into one map in the first map's frame, with every "
        "map's transform. Exit 0: all merged; 1: some map not merged; 2: bad input.")
    p.add_argument("maps", nargs="+", metavar="MAP", help="a map file (two or more maps)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--resolution", type=float, metavar="M",
                   help="metres per pixel of plain images (they store no scale)")
    p.add_argument("--out-resolution", type=float, metavar="M",
                   help="merge and write at this resolution (default: the first map's)")
    p.add_argument("--plain", choices=("ros", "dungeon"), default="ros",
                   help="how plain images are read: map_server's default thresholds (ros) "
                   "or grey > 150 free, darker occupied (dungeon)")
    p.add_argument("--confidence-model", choices=sorted(CONFIDENCE_MODELS), default="real",
                   help="the pairs' calibrated confidence and its accept threshold: fitted on "
                   "real sensor maps (real, the default) or on the simulator's (sim)")
    p.add_argument("--write-unmerged", action="store_true",
                   help="write merged.yaml/.pgm/.png even when no two maps merged")
    return p


def main(argv: Sequence[str] | None = None, prog: str = "python -m fusion merge") -> int:
    """The command line (module docstring): ``argv`` without the program and subcommand
    names (``None``: ``sys.argv[1:]``); ``prog`` names the command in messages (the
    ``topomerge merge`` console command passes its own). Returns the exit code (argparse's
    own usage errors exit 2 by ``SystemExit``)."""
    args = parser(prog).parse_args(argv)
    try:
        team = merge_files(args.maps, args.out, resolution=args.resolution,
                           out_resolution=args.out_resolution, plain=args.plain,
                           write_unmerged=args.write_unmerged,
                           confidence_model=args.confidence_model)
    except (MapFileError, ValueError, TypeError, OSError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    for p in team.placements:
        t = p.transform
        where = (f"x={t.T[0]:.3f} y={t.T[1]:.3f} yaw={t.degrees:.2f} deg "
                 f"confidence={p.confidence:.2f}" if p.merged else f"not merged: {p.why}")
        print(f"{p.name}: {where}")
    print(f"wrote {args.out}" + ("" if team.merged is not None or args.write_unmerged
                                 else " (transforms only: no merged map)"))
    return EXIT_MERGED if team.all_merged else EXIT_NOT_MERGED


__all__ = ["CONFIDENCE_MODELS", "EXIT_BAD_INPUT", "EXIT_MERGED", "EXIT_NOT_MERGED", "InputMap",
           "Placement", "TeamMerge", "load_input", "main", "merge_files", "merge_maps_n",
           "merged_plan", "parser", "picture", "rasterise", "resampled", "tool_config",
           "write_outputs"]
