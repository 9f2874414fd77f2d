"""Drawing topological maps: every node kind has its colour (a map from extract_topomap, with
gateways, used to fail ``python -m fusion.evaluation``'s pictures)."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from topo.graph import NodeKind, TopoMap  # noqa: E402
from topo.plotting import KIND_COLOURS, kind_legend_handles, plot_topomap, save_figure  # noqa: E402


def test_every_kind_is_drawn(tmp_path):
    assert set(KIND_COLOURS) == set(NodeKind)
    kinds = [k.label for k in NodeKind]
    m = TopoMap.from_arrays([[0, 0], [1, 0], [1, 1], [0, 1]], [[0, 1], [1, 2], [2, 3]], kinds)
    fig, ax = plt.subplots()
    plot_topomap(ax, m)
    ax.legend(handles=kind_legend_handles())
    out = save_figure(fig, tmp_path / "map.png")
    plt.close(fig)
    assert out.read_bytes().startswith(b"\x89PNG")
    assert len(kind_legend_handles()) == len(NodeKind)
