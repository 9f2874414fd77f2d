"""The team's pose graph: every robot's map as a chain of anchors, merges as many local links.

Maps built on drifting odometry bend, and no single rigid transform aligns two bent maps. Here
each robot's trajectory is a chain of **anchors** (poses along it, in the robot's own odometry
frame) joined by odometry edges; a robot that revisits a place adds a **loop closure** between
two of its anchors; a merge of two robots' local maps adds a **link** between an anchor of each.
Each robot pair's links are kept only as a pairwise-consistent set (PCM, Mangelson et al.
2018: the largest set whose every two links agree through the two robots' own trajectories),
then GTSAM's Levenberg–Marquardt optimises each connected component of robots, with a robust
(Huber) kernel on loop closures and links; a link the optimum still cannot explain is dropped
and the component optimised again — with three or more robots this is where a link
inconsistent with another pair's is caught. A robot's fused trajectory is its component's
anchors expressed in its own frame.

Conventions (:class:`fusion.Rigid2D`, ``p_A = R p_B + T``): an anchor pose ``X`` maps the
anchor's local frame into its robot's odometry frame; a relative measurement
``Z_ab = X_a⁻¹ X_b`` is anchor ``b``'s pose in anchor ``a``'s frame. ``sigmas`` are standard
deviations ``(x, y, θ)``: metres along ``a``'s axes, radians.

Requires the ``slam`` extra (``pip install 'topomerge[slam]'``: GTSAM).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import networkx as nx
import numpy as np
from scipy.stats import chi2

from fusion.rigid import Rigid2D
from topo.validation import check_int, check_real, config_from

MIN_SIGMA = 1e-4
"""Smallest standard deviation given to GTSAM (m or rad): perfect odometry stays stiff without
making the system ill-conditioned."""

Anchor = tuple[int, int]
"""An anchor's key: ``(robot, index along the robot's chain)``."""


@dataclass(frozen=True, slots=True)
class PoseGraphConfig:
    """How the pose graph keeps links and optimises.

    Attributes:
        consistency_quantile: two measurements agree when the squared Mahalanobis norm of
            their disagreement is below this quantile of χ² with 3 degrees of freedom.
        min_links: a robot pair is joined only by a consistent set of at least this many
            links — one link alone is one look-alike away from a folded map.
        max_links_per_pair: the most confident links of a pair that the consistency search
            considers (its agreement tests grow with the square of this, its maximal-clique
            search exponentially at worst).
        huber_k: the Huber kernel's threshold (in standard deviations) on loop closures and
            links.
        max_drops: links the optimum explains worst that are dropped per component at most
            (each drop costs one optimisation more).
    """

    consistency_quantile: float = 0.99
    min_links: int = 2
    max_links_per_pair: int = 64
    huber_k: float = 1.345
    max_drops: int = 4

    def __post_init__(self) -> None:
        check_real(self.consistency_quantile, "consistency_quantile", low=0.0, high=1.0,
                   high_inclusive=False)
        check_int(self.min_links, "min_links", low=1)
        check_int(self.max_links_per_pair, "max_links_per_pair", low=1)
        check_real(self.huber_k, "huber_k", low=0.0)
        check_int(self.max_drops, "max_drops", low=0)

    @property
    def chi2_bound(self) -> float:
        """The squared Mahalanobis bound of two agreeing measurements."""
        return float(chi2.ppf(self.consistency_quantile, 3))


@dataclass(frozen=True, slots=True)
class Measurement:
    """A relative pose between two anchors: ``relative`` is ``b``'s pose in ``a``'s frame.

    Attributes:
        a, b: the anchors.
        relative: ``Z_ab``.
        sigmas: its standard deviations ``(x, y, θ)`` (m, m, rad).
        confidence: the calibrated probability that it is right (links and loops; 1 for
            odometry).
    """

    a: Anchor
    b: Anchor
    relative: Rigid2D
    sigmas: tuple[float, float, float]
    confidence: float = 1.0

    @property
    def pos_var(self) -> float:
        """Position variance (m²), the mean of the x and y variances."""
        return (self.sigmas[0] ** 2 + self.sigmas[1] ** 2) / 2

    @property
    def rot_var(self) -> float:
        """Heading variance (rad²)."""
        return self.sigmas[2] ** 2


@dataclass(slots=True)
class _Chain:
    poses: list[Rigid2D] = field(default_factory=list)  # odometry poses of the anchors
    pos_var: list[float] = field(default_factory=list)  # cumulated along the chain
    rot_var: list[float] = field(default_factory=list)
    length: list[float] = field(default_factory=list)  # path length from the first anchor
    sigmas: list[tuple[float, float, float]] = field(default_factory=list)  # edge k-1 → k


def _gtsam():
    try:
        import gtsam
    except ImportError as exc:
        raise ImportError("fusion.posegraph needs GTSAM: pip install 'topomerge[slam]'") from exc
    return gtsam


def _sigmas(value: object, name: str) -> tuple[float, float, float]:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence | np.ndarray):
        raise TypeError(f"{name} must be 3 standard deviations (x, y, theta), got "
                        f"{type(value).__name__}")
    if len(value) != 3:
        raise ValueError(f"{name} must be 3 standard deviations (x, y, theta), got {len(value)}")
    return tuple(check_real(s, f"{name}[{i}]", low=0.0, low_inclusive=True)
                 for i, s in enumerate(value))


class PoseGraph:
    """Anchors of ``n_robots`` trajectories, their loop closures and the links between them.

    Build it as the robots move (:meth:`add_anchor`, :meth:`add_loop`, :meth:`add_link`),
    call :meth:`optimise` when the robots' maps are needed, then read :meth:`trajectory`,
    :meth:`corrections`, :meth:`component` and :meth:`links`. Nothing is random: the same
    calls give the same result.

    Args:
        n_robots: the team's size (≥ 1).
        config: a :class:`PoseGraphConfig`, a dict of its fields, or ``None``.

    Raises:
        ImportError: GTSAM is not installed (the ``slam`` extra), on the first
            :meth:`optimise`.
    """

    def __init__(self, n_robots: int, config: PoseGraphConfig | dict | None = None) -> None:
        self.n_robots = check_int(n_robots, "n_robots", low=1)
        self.config = config_from(PoseGraphConfig, config)
        self._chains = [_Chain() for _ in range(self.n_robots)]
        self._loops: list[Measurement] = []
        self._links: dict[tuple[int, int], list[Measurement]] = {}
        self._kept: dict[tuple[int, int], list[Measurement]] = {}
        self._dropped: set[int] = set()  # ids of links the optimum refused
        self._agreement: dict[tuple[int, int], float] = {}  # PCM's χ² of two links, by id
        self._estimate: dict[Anchor, Rigid2D] = {}  # in the component's reference frame
        self._groups: list[frozenset[int]] = []  # the components at the last optimise
        self._bound = self.config.chi2_bound
        self._factors: dict[object, object] = {}  # GTSAM factors, by edge or measurement id
        self._dirty = True

    # ----------------------------------------------------------------- building
    def add_anchor(self, robot: int, pose: Rigid2D,
                   sigmas: Sequence[float] = (0.0, 0.0, 0.0)) -> int:
        """Append an anchor at odometry ``pose`` to ``robot``'s chain; ``sigmas`` is the
        odometry's uncertainty since the previous anchor (ignored for the first). Returns the
        anchor's index."""
        chain = self._chains[self._robot(robot, "robot")]
        if not isinstance(pose, Rigid2D):
            raise TypeError(f"pose must be a fusion.Rigid2D, got {type(pose).__name__}")
        s = _sigmas(sigmas, "sigmas")
        first = not chain.poses
        chain.pos_var.append(0.0 if first else chain.pos_var[-1] + (s[0] ** 2 + s[1] ** 2) / 2)
        chain.rot_var.append(0.0 if first else chain.rot_var[-1] + s[2] ** 2)
        step = 0.0 if first else float(np.hypot(*(pose.T - chain.poses[-1].T)))
        chain.length.append(step + (chain.length[-1] if chain.length else 0.0))
        chain.poses.append(pose)
        chain.sigmas.append(s)
        self._dirty = True
        return len(chain.poses) - 1

    def add_loop(self, robot: int, a: int, b: int, relative: Rigid2D,
                 sigmas: Sequence[float], confidence: float = 1.0) -> bool:
        """A loop closure inside ``robot``'s map: anchor ``b``'s pose in anchor ``a``'s frame.
        Kept (``True``) when it agrees with the odometry between them within the odometry's
        accumulated uncertainty; otherwise refused (``False``) and never used."""
        m = self._measurement((robot, a), (robot, b), relative, sigmas, confidence)
        if robot != m.a[0] or m.a[0] != m.b[0]:
            raise ValueError("a loop closure joins two anchors of one robot")
        d = self._chain_relative(robot, a, b)
        pos_var, rot_var = self._chain_var(robot, a, b)
        if _chi2(m.relative, d, pos_var + m.pos_var, rot_var + m.rot_var) > self._bound:
            return False
        self._loops.append(m)
        self._dirty = True
        return True

    def add_link(self, a: Anchor, b: Anchor, relative: Rigid2D, sigmas: Sequence[float],
                 confidence: float) -> None:
        """A link between two robots' anchors (``a[0] != b[0]``): anchor ``b``'s pose in
        anchor ``a``'s frame, from a merge of their local maps. Whether it is used is decided
        with the pair's other links at :meth:`optimise`."""
        m = self._measurement(a, b, relative, sigmas, confidence)
        if m.a[0] == m.b[0]:
            raise ValueError(f"a link joins two robots' anchors, got {m.a} and {m.b}")
        if m.a[0] > m.b[0]:
            m = Measurement(m.b, m.a, m.relative.inverse(), m.sigmas, m.confidence)
        self._links.setdefault((m.a[0], m.b[0]), []).append(m)
        self._dirty = True

    # --------------------------------------------------------------- optimising
    def optimise(self) -> None:
        """Select each pair's consistent links and optimise every component of robots."""
        if not self._dirty:
            return
        gtsam = _gtsam()
        self._kept = {pair: self._consistent(links) for pair, links in sorted(self._links.items())}
        self._dropped = set()
        for robots in self._components():
            self._settle(gtsam, robots)
        self._groups = self._components()  # what component() reads until the next change
        self._dirty = False

    def _settle(self, gtsam, robots: frozenset[int]) -> None:
        """Optimise ``robots``, dropping the link the optimum explains worst while one is
        beyond the consistency bound (at most ``max_drops``); a drop that splits the
        component settles each part on its own."""
        values = self._optimise_component(gtsam, robots)
        for _ in range(self.config.max_drops):
            worst = self._worst_link(gtsam, robots, values)
            if worst is None:
                break
            self._dropped.add(id(worst))
            parts = self._components_of(robots)
            if len(parts) > 1:
                for part in parts:
                    self._settle(gtsam, part)
                return
            values = self._optimise_component(gtsam, robots)
        self._store(gtsam, values, robots)

    # ------------------------------------------------------------------ reading
    def component(self, robot: int) -> frozenset[int]:
        """The robots whose maps ``robot``'s fused map holds (itself included)."""
        self._robot(robot, "robot")
        self.optimise()
        return next(c for c in self._groups if robot in c)

    def trajectory(self, robot: int, frame: int | None = None) -> np.ndarray:
        """``robot``'s optimised anchors as ``(K, 3)`` rows ``(x, y, θ)`` in ``frame``'s
        odometry frame (default: ``robot``'s own, pinned at its first anchor).

        Raises:
            ValueError: ``frame`` is not in ``robot``'s component."""
        poses = self.corrected_poses(robot, frame)
        return np.array([[p.T[0], p.T[1], p.theta] for p in poses]).reshape(-1, 3)

    def corrected_poses(self, robot: int, frame: int | None = None) -> list[Rigid2D]:
        """:meth:`trajectory` as :class:`fusion.Rigid2D` poses."""
        to_frame = self._to_frame(self._robot(robot, "robot"), frame)
        return [to_frame @ self._estimate[(robot, k)]
                for k in range(len(self._chains[robot].poses))]

    def correction(self, robot: int, index: int, frame: int | None = None) -> Rigid2D:
        """:meth:`corrections`' entry for anchor ``index`` of ``robot`` alone (what reading
        one anchor costs, not all of them).

        Raises:
            ValueError: ``index`` is not an anchor of ``robot`` (negative counts from the
                newest); ``frame`` as :meth:`corrected_poses`."""
        poses = self._chains[self._robot(robot, "robot")].poses
        k = check_int(index, "index", low=-len(poses))
        if k >= len(poses):
            raise ValueError(f"index must be < {len(poses)} (robot {robot}'s anchors), got {k}")
        to_frame = self._to_frame(robot, frame)
        k %= len(poses)
        return to_frame @ self._estimate[(robot, k)] @ poses[k].inverse()

    def corrections(self, robot: int, frame: int | None = None) -> list[Rigid2D]:
        """Per anchor of ``robot``, the motion taking what the robot mapped near that anchor
        (in its odometry frame) into ``frame``'s map: ``P_k · X_k⁻¹`` with ``P_k`` the
        anchor's optimised pose in ``frame`` and ``X_k`` its odometry pose. Rendering each
        anchor's submap with its own correction is what unbends the map."""
        return [p @ x.inverse() for p, x in zip(self.corrected_poses(robot, frame),
                                                 self._chains[robot].poses, strict=True)]

    def links(self, i: int, j: int) -> tuple[list[Measurement], list[Measurement]]:
        """Robots ``i``'s and ``j``'s links as ``(kept, rejected)``, each ``a`` on robot
        ``min(i, j)``."""
        pair = tuple(sorted((self._robot(i, "i"), self._robot(j, "j"))))
        self.optimise()
        kept = [m for m in self._kept.get(pair, []) if id(m) not in self._dropped]
        ids = {id(m) for m in kept}
        return kept, [m for m in self._links.get(pair, []) if id(m) not in ids]

    def loops(self, robot: int) -> list[Measurement]:
        """``robot``'s loop closures in use: those :meth:`add_loop` kept."""
        r = self._robot(robot, "robot")
        return [m for m in self._loops if m.a[0] == r]

    # ---------------------------------------------------------------- internals
    def _robot(self, robot: object, name: str) -> int:
        r = check_int(robot, name, low=0)
        if r >= self.n_robots:
            raise ValueError(f"{name} must be < n_robots={self.n_robots}, got {r}")
        return r

    def _measurement(self, a: Anchor, b: Anchor, relative: Rigid2D, sigmas: Sequence[float],
                     confidence: float) -> Measurement:
        keys = []
        for name, key in (("a", a), ("b", b)):
            if not (isinstance(key, tuple) and len(key) == 2):
                raise TypeError(f"{name} must be an anchor (robot, index), got {key!r}")
            r = self._robot(key[0], f"{name}[0] (robot)")
            k = check_int(key[1], f"{name}[1] (anchor index)", low=0)
            if k >= len(self._chains[r].poses):
                raise ValueError(f"{name}: robot {r} has {len(self._chains[r].poses)} anchors, "
                                 f"got index {k}")
            keys.append((r, k))
        if not isinstance(relative, Rigid2D):
            raise TypeError(f"relative must be a fusion.Rigid2D, got {type(relative).__name__}")
        s = _sigmas(sigmas, "sigmas")
        if min(s) <= 0:
            raise ValueError(f"sigmas must be > 0, got {s}")
        c = check_real(confidence, "confidence", low=0.0, low_inclusive=True, high=1.0)
        return Measurement(keys[0], keys[1], relative, s, c)

    def _chain_relative(self, robot: int, a: int, b: int) -> Rigid2D:
        poses = self._chains[robot].poses
        return poses[a].inverse() @ poses[b]

    def _chain_var(self, robot: int, a: int, b: int) -> tuple[float, float]:
        """Position and heading variance of the odometry between anchors ``a`` and ``b``: the
        steps' own, plus the heading's random walk swung over the path between them
        (``σθ² L² / 3`` for a path of length ``L``)."""
        c = self._chains[robot]
        rot = abs(c.rot_var[b] - c.rot_var[a])
        length = abs(c.length[b] - c.length[a])
        return abs(c.pos_var[b] - c.pos_var[a]) + rot * length ** 2 / 3, rot

    def _consistent(self, links: list[Measurement]) -> list[Measurement]:
        """The largest pairwise-consistent subset (most confident on ties), if it has at
        least ``min_links`` links; else none."""
        links = sorted(links, key=lambda m: -m.confidence)[: self.config.max_links_per_pair]
        graph = nx.Graph()
        graph.add_nodes_from(range(len(links)))
        bound = self._bound
        for u in range(len(links)):
            for v in range(u + 1, len(links)):
                key = (id(links[u]), id(links[v]))
                if key not in self._agreement:  # links and chains never change: once is enough
                    self._agreement[key] = self._agree(links[u], links[v])
                if self._agreement[key] <= bound:
                    graph.add_edge(u, v)
        best = max(nx.find_cliques(graph),
                   key=lambda c: (len(c), sum(links[k].confidence for k in c), -min(c)))
        if len(best) < self.config.min_links:
            return []
        return [links[k] for k in sorted(best)]

    def _agree(self, m: Measurement, n: Measurement) -> float:
        """χ² of the loop ``a_m → b_m → b_n → a_n → a_m`` through both robots' odometry."""
        (i, a1), (j, b1) = m.a, m.b
        (_, a2), (_, b2) = n.a, n.b
        dj = self._chain_relative(j, b1, b2)
        di = self._chain_relative(i, a2, a1)
        loop = m.relative @ dj @ n.relative.inverse() @ di
        pj, rj = self._chain_var(j, b1, b2)
        pi, ri = self._chain_var(i, a2, a1)
        # a link's heading error swings the other end by the distance between the links
        lever = float(np.dot(dj.T, dj.T))
        pos_var = m.pos_var + n.pos_var + pj + pi + m.rot_var * lever
        return _chi2(loop, Rigid2D(), pos_var, m.rot_var + n.rot_var + rj + ri)

    def _used(self, pair: tuple[int, int]) -> list[Measurement]:
        return [m for m in self._kept.get(pair, []) if id(m) not in self._dropped]

    def _components(self) -> list[frozenset[int]]:
        return self._components_of(range(self.n_robots))

    def _components_of(self, robots) -> list[frozenset[int]]:
        graph = nx.Graph()
        graph.add_nodes_from(robots)
        graph.add_edges_from(p for p in self._kept if set(p) <= set(robots)
                             and len(self._used(p)) >= self.config.min_links)
        return sorted((frozenset(c) for c in nx.connected_components(graph)), key=min)

    def _initial_frames(self, robots: frozenset[int]) -> dict[int, Rigid2D]:
        """Each robot's odometry frame in the component's (its lowest robot's), along a
        spanning tree of the pairs' most confident links."""
        ref = min(robots)
        frames = {ref: Rigid2D()}
        graph = nx.Graph()
        for (i, j) in self._kept:
            used = self._used((i, j))
            if {i, j} <= robots and len(used) >= self.config.min_links:
                graph.add_edge(i, j, link=used[0])
        for i, j in nx.bfs_edges(graph, ref) if graph.number_of_nodes() else []:
            m = graph.edges[i, j]["link"]
            (ra, ka), (rb, kb) = m.a, m.b
            xa, xb = self._chains[ra].poses[ka], self._chains[rb].poses[kb]
            if ra == i:  # frame_j = frame_i · X_a · Z · X_b⁻¹
                frames[j] = frames[i] @ xa @ m.relative @ xb.inverse()
            else:
                frames[j] = frames[i] @ xb @ m.relative.inverse() @ xa.inverse()
        return frames

    def _optimise_component(self, gtsam, robots: frozenset[int]):
        frames = self._initial_frames(robots)
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        ref = min(robots)
        noise = gtsam.noiseModel
        huber = noise.mEstimator.Huber.Create(self.config.huber_k)
        for r in sorted(robots):
            chain = self._chains[r]
            for k, pose in enumerate(chain.poses):
                values.insert(_key(gtsam, r, k), _pose2(gtsam, frames[r] @ pose))
                if k:
                    graph.add(self._odometry_factor(gtsam, r, k))
        graph.add(gtsam.PriorFactorPose2(_key(gtsam, ref, 0),
                                         _pose2(gtsam, self._chains[ref].poses[0]),
                                         noise.Diagonal.Sigmas(np.full(3, MIN_SIGMA))))
        robust = [m for m in self._loops if m.a[0] in robots]
        for pair in sorted(self._kept):
            if set(pair) <= robots:
                robust += self._used(pair)
        for m in robust:
            factor = self._factors.get(id(m))
            if factor is None:  # measurements never change: one factor each
                model = noise.Robust.Create(huber, noise.Diagonal.Sigmas(np.asarray(m.sigmas)))
                factor = gtsam.BetweenFactorPose2(_key(gtsam, *m.a), _key(gtsam, *m.b),
                                                  _pose2(gtsam, m.relative), model)
                self._factors[id(m)] = factor
            graph.add(factor)
        return gtsam.LevenbergMarquardtOptimizer(graph, values,
                                                 gtsam.LevenbergMarquardtParams()).optimize()

    def _odometry_factor(self, gtsam, robot: int, k: int):
        """The odometry edge from anchor ``k - 1`` to ``k`` of ``robot`` as a GTSAM factor
        (made once: a chain's anchors never change)."""
        factor = self._factors.get((robot, k))
        if factor is None:
            chain = self._chains[robot]
            d = chain.poses[k - 1].inverse() @ chain.poses[k]
            s = np.maximum(np.asarray(chain.sigmas[k]), MIN_SIGMA)
            factor = gtsam.BetweenFactorPose2(_key(gtsam, robot, k - 1), _key(gtsam, robot, k),
                                              _pose2(gtsam, d), gtsam.noiseModel.Diagonal.Sigmas(s))
            self._factors[(robot, k)] = factor
        return factor

    def _worst_link(self, gtsam, robots: frozenset[int], values) -> Measurement | None:
        """The used link the optimum explains worst, if it is beyond the consistency bound."""
        worst, worst_chi2 = None, self._bound
        for pair in sorted(self._kept):
            if not set(pair) <= robots:
                continue
            for m in self._used(pair):
                # the residual d⁻¹ z of _chi2, in GTSAM (d: the optimum's relative pose)
                d = values.atPose2(_key(gtsam, *m.a)).between(values.atPose2(_key(gtsam, *m.b)))
                e = d.between(self._factors[id(m)].measured())
                value = ((e.x() ** 2 + e.y() ** 2) / max(m.pos_var, 1e-12)
                         + e.theta() ** 2 / max(m.rot_var, 1e-12))
                if value > worst_chi2:
                    worst, worst_chi2 = m, value
        return worst

    def _store(self, gtsam, values, robots: frozenset[int]) -> None:
        for r in robots:
            for k in range(len(self._chains[r].poses)):
                self._estimate[(r, k)] = _rigid(values.atPose2(_key(gtsam, r, k)))

    def _to_frame(self, robot: int, frame: int | None) -> Rigid2D:
        """The optimised graph's motion from ``robot``'s component frame into ``frame``'s
        odometry frame (default: ``robot``'s own), after checking ``frame`` is in that
        component."""
        frame = robot if frame is None else self._robot(frame, "frame")
        self.optimise()
        if frame not in self.component(robot):
            raise ValueError(f"robot {frame} is not in robot {robot}'s component "
                             f"{sorted(self.component(robot))}")
        return self._pin(frame).inverse()

    def _pin(self, robot: int) -> Rigid2D:
        """``robot``'s odometry frame in its component's frame, pinned at its first anchor."""
        return self._estimate[(robot, 0)] @ self._chains[robot].poses[0].inverse()


def _chi2(z: Rigid2D, d: Rigid2D, pos_var: float, rot_var: float) -> float:
    """Squared Mahalanobis norm of ``d⁻¹ z`` (isotropic position, heading variances)."""
    e = d.inverse() @ z
    return float(np.dot(e.T, e.T)) / max(pos_var, 1e-12) + e.theta ** 2 / max(rot_var, 1e-12)


def _key(gtsam, robot: int, k: int) -> int:
    return gtsam.symbol(chr(ord("a") + robot), k)


def _pose2(gtsam, t: Rigid2D):
    return gtsam.Pose2(float(t.T[0]), float(t.T[1]), t.theta)


def _rigid(p) -> Rigid2D:
    return Rigid2D(p.theta(), (p.x(), p.y()))
