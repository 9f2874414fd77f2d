"""Matplotlib drawing of topological maps (nodes coloured by kind, paths as polylines)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from topo.fileio import atomic_write
from topo.graph import NodeKind, TopoMap

KIND_COLOURS = {
    NodeKind.JUNCTION: "tab:red",
    NodeKind.DEAD_END: "tab:blue",
    NodeKind.CORNER: "tab:green",
    NodeKind.GATEWAY: "tab:purple",
}
"""One colour per node kind, shared by every figure."""


def plot_topomap(ax: Any, topomap: TopoMap, *, edge_colour: str = "0.35", marker: str = "o",
                 size: float = 36.0, label: str | None = None, kinds: bool = True,
                 zorder: int = 2) -> None:
    """Draw ``topomap`` on a matplotlib ``ax``: paths (polylines when known, else straight
    segments) and nodes coloured by kind (:data:`KIND_COLOURS`) or all in ``edge_colour``;
    nodes on the frontier (:attr:`TopoMap.frontier`) are drawn hollow."""
    for e, (u, v) in enumerate(topomap.edges):
        path = topomap.paths[e] if topomap.paths is not None else topomap.xy[[u, v]]
        ax.plot(path[:, 0], path[:, 1], color=edge_colour, lw=1.5, zorder=zorder,
                label=label if e == 0 else None)
    if topomap.n_nodes == 0:
        return
    if kinds:
        colours = [KIND_COLOURS[NodeKind(k)] for k in topomap.kinds]
    else:
        colours = [edge_colour] * topomap.n_nodes
    inner = ["none" if f else c for c, f in zip(colours, topomap.frontier.tolist(), strict=True)]
    outer = [c if f else "k" for c, f in zip(colours, topomap.frontier.tolist(), strict=True)]
    ax.scatter(topomap.xy[:, 0], topomap.xy[:, 1], facecolors=inner, edgecolors=outer, s=size,
               marker=marker, linewidths=np.where(topomap.frontier, 1.5, 0.5), zorder=zorder + 1,
               label=label if topomap.n_edges == 0 else None)


def kind_legend_handles() -> list[Any]:
    """Legend handles naming the node-kind colours."""
    from matplotlib.lines import Line2D

    return [Line2D([], [], marker="o", ls="", color=c, markeredgecolor="k", label=k.label)
            for k, c in KIND_COLOURS.items()]


def equal_axes(ax: Any, points: np.ndarray, margin: float = 0.08) -> None:
    """Square, equal-aspect limits around ``points`` with a relative margin."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = margin * float(max(hi - lo)) + 1e-9
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")


def save_figure(fig: Any, path: str | Path, dpi: int = 120) -> Path:
    """Write ``fig`` to ``path`` atomically (:func:`topo.fileio.atomic_write`), creating the
    folder; the format follows the suffix. Returns the path."""
    fmt = Path(path).suffix.lstrip(".") or "png"
    return atomic_write(path, lambda fh: fig.savefig(fh, format=fmt, dpi=dpi,
                                                     bbox_inches="tight"))
