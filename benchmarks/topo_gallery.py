"""Gallery: every map in shared/maps with its extracted topological map (nodes coloured by kind),
written to ``out/topo_<name>.png``; prints the node counts.

    python benchmarks/topo_gallery.py [--out out]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from topo import load_floor_plan  # noqa: E402
from topo.extract import extract_topomap  # noqa: E402
from topo.plotting import kind_legend_handles, plot_topomap, save_figure  # noqa: E402

MAPS = Path(__file__).resolve().parents[2] / "shared" / "maps"


def main(out: Path) -> None:
    files = sorted((MAPS / "ros").glob("*.yaml")) + sorted((MAPS / "dungeon").glob("*.png"))
    print(f"{'map':<28}{'size (cells)':>14}{'nodes':>7}{'junct.':>7}{'dead':>6}{'corner':>7}")
    for path in files:
        plan = load_floor_plan(path)
        m = extract_topomap(plan.free, plan.resolution, plan.origin)
        img = np.full(plan.free.shape, 0.75)
        img[plan.free] = 1.0
        img[plan.occupied] = 0.15
        x0, y0, x1, y1 = plan.extent
        fig, ax = plt.subplots(figsize=(8, 8 * plan.free.shape[0] / plan.free.shape[1] + 0.6))
        ax.imshow(img, cmap="gray", vmin=0, vmax=1, origin="lower", extent=(x0, x1, y0, y1))
        plot_topomap(ax, m, edge_colour="tab:orange", size=30)
        ax.legend(handles=kind_legend_handles(), loc="upper right", fontsize=8)
        ax.set_title(f"{path.parent.name}/{path.name}: {m!r}", fontsize=9)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        save_figure(fig, out / f"topo_{path.parent.name}_{path.stem}.png")
        plt.close(fig)
        c = np.bincount(m.kinds, minlength=3)
        name = f"{path.parent.name}/{path.name}"
        print(f"{name:<28}{str(plan.free.shape):>14}{m.n_nodes:>7}{c[0]:>7}{c[1]:>6}{c[2]:>7}")
    print(f"wrote {len(files)} figures to {out}/topo_*.png")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out"))
    main(parser.parse_args().out)
