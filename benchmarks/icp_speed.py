"""ICP-SVD speed against Open3D's point-to-point ``registration_icp`` on the same point sets.

Both solve the same problem with the same stopping rules: N points (a jittered lattice in a
10 m × 10 m square centred on the origin), moved by 8° and (0.25, −0.15) m, σ = 1 cm noise; 2-D
points are given to Open3D with z = 0; max correspondence distance 1 m; at most 30 iterations;
relative change 1e-6. Times are medians over interleaved repeats in this one process, so the
ratio is fair even on a busy machine. Also prints the brute-force/KD-tree crossover behind
``fusion.icp.BRUTE_FORCE_MAX_PAIRS`` and the exhaustive-search/ICP ratio on the paper's example.

    python benchmarks/icp_speed.py            (needs the `bench` extra for Open3D)
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from _timing import interleaved_medians

from fusion import Rigid2D, exhaustive_search, icp_svd, paper_example
from fusion import icp as icp_module
from fusion.paper import PAPER_TAU

TRUTH = Rigid2D.from_degrees(8.0, (0.25, -0.15))
MAX_ITER, REL, MAX_DIST = 30, 1e-6, 1.0


def lattice(n: int, rng: np.random.Generator, size: float = 10.0) -> np.ndarray:
    side = math.ceil(math.sqrt(n))
    spacing = size / side
    g = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:n]
    pts = (g - (side - 1) / 2) * spacing
    return pts + rng.uniform(-0.3, 0.3, pts.shape) * spacing


def load_open3d():
    try:
        import open3d as o3d
    except ImportError as exc:
        msg = str(exc)
        if "libusb" in msg:
            print(f"Open3D cannot load: {msg}\n  -> install Debian's libusb-1.0-0 "
                  "(apt-get install libusb-1.0-0); comparing without Open3D.")
        else:
            print(f"Open3D is not installed ({msg}) -> pip install -e '.[bench]'; "
                  "comparing without Open3D.")
        return None
    return o3d


def open3d_icp(o3d, M: np.ndarray, D: np.ndarray):
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.c_[D, np.zeros(len(D))]))
    dst = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.c_[M, np.zeros(len(M))]))
    est = o3d.pipelines.registration.TransformationEstimationPointToPoint()
    crit = o3d.pipelines.registration.ICPConvergenceCriteria(REL, REL, MAX_ITER)

    def run():
        return o3d.pipelines.registration.registration_icp(src, dst, MAX_DIST, np.eye(4), est,
                                                           crit)
    return run


def ours(M: np.ndarray, D: np.ndarray):
    init = Rigid2D.identity()
    return lambda: icp_svd(M, D, tau=None, rel_tol=REL, max_iter=MAX_ITER, init=init,
                           max_distance=MAX_DIST)


def errors(t: Rigid2D, at: np.ndarray) -> tuple[float, float]:
    return math.degrees(t.rotation_error(TRUTH)), t.translation_error(TRUTH, at=at)


def main() -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    rng = np.random.default_rng(0)
    o3d = load_open3d()
    print("ICP-SVD vs Open3D registration_icp (point-to-point), same data and stopping rules")
    print(f"{'N':>6} {'ours µs':>10} {'open3d µs':>10} {'ratio':>7} {'goal':>6} "
          f"{'ours it':>8} {'o3d it':>7} {'ours rot°/trans m':>20} {'o3d rot°/trans m':>20} "
          f"{'o3d det':>8}")
    for n in (10, 100, 1000):
        M = lattice(n, rng)
        D = TRUTH.inverse().apply(M) + rng.normal(0, 0.01, M.shape)
        fns = {"ours": ours(M, D)}
        if o3d is not None:
            fns["o3d"] = open3d_icp(o3d, M, D)
        med = interleaved_medians(fns, repeats=400 if n < 1000 else 60)
        res = fns["ours"]()
        e_ours = errors(res.transform, D.mean(axis=0))
        line = f"{n:>6} {med['ours'] * 1e6:>10.1f} "
        if o3d is not None:
            reg = fns["o3d"]()
            T = reg.transformation
            det = float(np.linalg.det(T[:2, :2]))
            t_o3d = Rigid2D(math.atan2(T[1, 0], T[0, 0]), T[:2, 3])
            e_o3d = errors(t_o3d, D.mean(axis=0))
            it_o3d = "-"  # Open3D does not report its iteration count
            ratio = med["ours"] / med["o3d"]
            goal = "≤1.5" if n <= 100 else "≤1.0"
            line += (f"{med['o3d'] * 1e6:>10.1f} {ratio:>7.2f} {goal:>6} {res.iterations:>8} "
                     f"{it_o3d:>7} {e_ours[0]:>10.4f}/{e_ours[1]:<9.4f} "
                     f"{e_o3d[0]:>10.4f}/{e_o3d[1]:<9.4f} {det:>8.3f}")
        else:
            line += f"{'-':>10} {'-':>7} {'':>6} {res.iterations:>8}"
        print(line)

    print("\nnearest-neighbour crossover (BRUTE_FORCE_MAX_PAIRS = "
          f"{icp_module.BRUTE_FORCE_MAX_PAIRS:,} pairs): median µs per icp_svd call")
    print(f"{'N':>6} {'pairs':>9} {'all-pairs':>10} {'KD-tree':>10}")
    default = icp_module.BRUTE_FORCE_MAX_PAIRS
    for n in (50, 100, 141, 200, 300):
        M = lattice(n, rng)
        D = TRUTH.inverse().apply(M) + rng.normal(0, 0.01, M.shape)
        out = {}
        for name, limit in (("brute", 10**12), ("tree", 0)):
            icp_module.BRUTE_FORCE_MAX_PAIRS = limit
            out[name] = interleaved_medians({"x": ours(M, D)}, 100)["x"]
        icp_module.BRUTE_FORCE_MAX_PAIRS = default
        print(f"{n:>6} {n * n:>9,} {out['brute'] * 1e6:>10.1f} {out['tree'] * 1e6:>10.1f}")

    ex = paper_example()
    M, D = ex.map_a.endpoints(), ex.map_b.endpoints()
    med = interleaved_medians({
        "icp": lambda: icp_svd(M, D, tau=PAPER_TAU),
        "search": lambda: exhaustive_search(ex.map_a, ex.map_b, 2.0, ex.eps),
    }, repeats=30)
    print(f"\npaper example: icp_svd {med['icp'] * 1e6:.1f} µs, exhaustive_search "
          f"{med['search'] * 1e3:.2f} ms (5068 fusions): exhaustive / ICP = "
          f"{med['search'] / med['icp']:,.0f}×")


if __name__ == "__main__":
    main()
