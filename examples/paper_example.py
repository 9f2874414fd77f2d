"""The paper's example end to end: ICP-SVD (τ = 0.1, the paper's initialisation) and the
exhaustive-search baseline (then ICP-SVD refinement from its best result) on a 4-vertex map A and
a 7-vertex map B whose true relation is the paper's R (≈ 17.44°) and T = (−36.461, −25.258).

Prints, for each method, the recovered R and T, the error against the truth, iterations /
evaluations and time; writes ``out/paper_fig8_merged.png`` and ``out/paper_fig9_convergence.png``.

    python examples/paper_example.py [--out out]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fusion import Rigid2D, exhaustive_search, icp_svd, paper_example, similarity  # noqa: E402
from fusion.paper import PAPER_ITERATIONS, PAPER_TAU  # noqa: E402
from topo.plotting import equal_axes, kind_legend_handles, plot_topomap, save_figure  # noqa: E402


def median_time(fn: Callable[[], object], repeats: int) -> float:
    """Median wall time of ``fn()`` over ``repeats`` calls, after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def fmt_rigid(t: Rigid2D) -> str:
    r = t.R
    return (f"R=[[{r[0, 0]:.4f}, {r[0, 1]:.4f}], [{r[1, 0]:.4f}, {r[1, 1]:.4f}]] "
            f"({t.degrees:7.2f}°)  T=({t.T[0]:8.3f}, {t.T[1]:8.3f})")


def main(out: Path) -> dict[str, float]:
    ex = paper_example()
    M, D = ex.map_a.endpoints(), ex.map_b.endpoints()
    centroid = D.mean(axis=0)

    plain = icp_svd(M, D, tau=PAPER_TAU)
    search = exhaustive_search(ex.map_a, ex.map_b, step_deg=2.0, eps=ex.eps)
    refined = [icp_svd(M, D, tau=PAPER_TAU, init=p.transform, max_distance=ex.eps)
               for p in search.ties]
    full = icp_svd(M, ex.truth.inverse().apply(M), tau=PAPER_TAU)  # full overlap: A's vertices only

    t_icp = median_time(lambda: icp_svd(M, D, tau=PAPER_TAU), 200)
    t_search = median_time(lambda: exhaustive_search(ex.map_a, ex.map_b, 2.0, ex.eps), 20)
    t_refine = median_time(lambda: icp_svd(M, D, tau=PAPER_TAU, init=search.transform,
                                           max_distance=ex.eps), 200)

    def errors(t: Rigid2D) -> str:
        return (f"rot err {math.degrees(t.rotation_error(ex.truth)):6.2f}°  "
                f"trans err {t.translation_error(ex.truth, at=centroid):7.3f}  "
                f"ω={similarity(ex.map_a, ex.map_b, t, ex.eps)}")

    print("The paper's example: map A (4 vertices) fixed, map B (7 vertices) moved onto A.")
    print(f"  truth                  {fmt_rigid(ex.truth)}")
    print(f"  paper reports          R=[[0.9540, -0.2997], [0.2997, 0.9540]] (  17.44°)  "
          f"T=( -36.461,  -25.258), {PAPER_ITERATIONS} iterations at τ={PAPER_TAU}")
    print()
    print(f"{'method':<28}{'estimate':<78}{'error against the truth':<50}{'work':<28}time")
    rows = [
        ("ICP-SVD, full overlap", full.transform,
         f"{full.iterations} iterations", "—"),
        ("ICP-SVD (paper's init)", plain.transform,
         f"{plain.iterations} iterations", f"{t_icp * 1e6:8.1f} µs"),
        ("exhaustive search (2°)", search.transform,
         f"{search.evaluations} fusions", f"{t_search * 1e3:8.2f} ms"),
    ]
    for k, (p, r) in enumerate(zip(search.ties, refined, strict=True)):
        rows.append((f"  + ICP refine, optimum {k + 1}", r.transform,
                     f"{r.iterations} iterations (from {p.transform.degrees:.0f}°)",
                     f"{t_refine * 1e6:8.1f} µs" if k == 0 else ""))
    for name, t, work, tm in rows:
        print(f"{name:<28}{fmt_rigid(t):<78}{errors(t):<50}{work:<28}{tm}")
    print()
    print(f"exhaustive search: {search.evaluations} fusions = 4 × 7 × 181 angles (0..360° "
          f"inclusive; {search.distinct_evaluations} distinct); best ω = {search.score} reached "
          f"by {len(search.ties)} distinct optima at "
          + ", ".join(f"{p.transform.degrees % 360:.0f}°" for p in search.ties)
          + " — ambiguous, like the paper's 136°/316° pair.")
    print(f"plain ICP-SVD from the paper's initialisation stops at a biased fixed point: B's "
          f"3 extra vertices pull its centroid ({plain.transform.degrees:.2f}° instead of "
          f"{ex.truth.degrees:.2f}°). Gating the pairs (max_distance) after a global start "
          "fixes it.")
    print(f"time: exhaustive search / ICP-SVD = {t_search / t_icp:,.0f}×")

    _fig8(ex, plain.transform, refined[0].transform if refined else search.transform,
          out / "paper_fig8_merged.png")
    _fig9(plain, full, refined, out / "paper_fig9_convergence.png")
    print(f"wrote {out / 'paper_fig8_merged.png'} and {out / 'paper_fig9_convergence.png'}")
    return {"icp_s": t_icp, "search_s": t_search}


def _fig8(ex, plain: Rigid2D, best: Rigid2D, path: Path) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(15, 5))
    panels = [
        ("Original maps (own frames)", None),
        ("Merged: ICP-SVD, paper's init", plain),
        ("Merged: exhaustive + gated ICP-SVD", best),
    ]
    for ax, (title, t) in zip(axes, panels, strict=True):
        if t is None:
            plot_topomap(ax, ex.map_a, edge_colour="tab:orange", label="map A")
            plot_topomap(ax, ex.map_b, edge_colour="tab:purple", marker="s", label="map B")
            pts = np.vstack([ex.map_a.xy, ex.map_b.xy])
        else:
            moved = ex.map_b.transformed(t)
            plot_topomap(ax, ex.map_a, edge_colour="tab:orange", label="map A", size=90)
            plot_topomap(ax, moved, edge_colour="tab:purple", marker="s",
                         label="map B moved onto A")
            pts = np.vstack([ex.map_a.xy, moved.xy])
        ax.set_title(title)
        equal_axes(ax, pts)
        ax.grid(alpha=0.3)
    axes[0].legend(handles=axes[0].get_legend_handles_labels()[0] + kind_legend_handles(),
                   loc="best", fontsize=8)
    fig.suptitle("Topological map fusion on the paper's example (cf. its Fig. 8)")
    save_figure(fig, path)
    plt.close(fig)


def _fig9(plain, full, refined, path: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 4.5))
    runs = [("full overlap", full), ("partial overlap, paper's init", plain)]
    runs += [(f"partial, gated from exhaustive optimum {k + 1}", r) for k, r in enumerate(refined)]
    for label, res in runs:
        deltas = res.deltas
        if len(deltas):
            ax.semilogy(np.arange(1, len(deltas) + 1), np.maximum(deltas, 1e-16), "o-",
                        label=f"{label} ({res.iterations} it.)")
    ax.axhline(PAPER_TAU, color="k", ls="--", lw=1, label=f"τ = {PAPER_TAU}")
    ax.set_xlabel("iteration")
    ax.set_ylabel("|f_k − f_{k−1}| (error difference of two iterations)")
    ax.set_title("ICP-SVD convergence (cf. the paper's Fig. 9)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    save_figure(fig, path)
    plt.close(fig)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out"), help="folder for the figures")
    main(parser.parse_args().out)
