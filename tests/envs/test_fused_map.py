"""``env.fused_map(agent)``: a robot's fused occupancy grid in its own frame, read through the
env. Before a merge it is the robot's own grid; after one (rigid merges, or the pose graph)
it knows more and its walls lie on the world's walls; it is read-only, cached per step,
deterministic, and reading it leaves the episode as it was.

The merges come from Frontier explorers (``agents.scripted``) on 10 m buildings with frequent
merge steps: seeds on which the pair merges within a few hundred steps."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import SMALL

from agents.scripted import Frontier
from envs import multi_robot_explore_v0, two_robot_explore_v0
from fusion.evaluation.bending import wall_share
from fusion.local_align import NEAR_FEATURES

FAST = {"merge_every": 5, "grid_merge_every": 10, "topo_every": 5}
"""Merge steps every 5 steps, grid alignments every 10: early merges on small buildings."""

GRAPH = {"pose_graph": True, "anchor_every": 25, "merge_every": 5}
"""The pose graph with short anchors (windows of 4 × 25 steps): early links."""

RIGID_SEED, GRAPH_SEED = 3, 2
"""Seeds whose pair merges early under :data:`FAST` / :data:`GRAPH` (perfect odometry)."""


def _episode(env, seed: int, steps: int, until_merged: bool = False, read=None) -> list:
    """Drive ``env`` with seeded Frontier explorers for up to ``steps`` steps (stopping at the
    first step with a teammate in robot 0's fused map if ``until_merged``); ``read(env)`` is
    called after every step. Returns each step's observations and infos."""
    team = {a: Frontier() for a in env.possible_agents}
    obs, infos = env.reset(seed=seed)
    seeds = np.random.SeedSequence(seed).spawn(len(team))
    for (agent, explorer), s in zip(team.items(), seeds, strict=True):
        explorer.bind(env, agent)
        explorer.reset(int(s.generate_state(1)[0]))
    trace = []
    for _ in range(steps):
        if not env.agents:
            break
        obs, _, _, _, infos = env.step({a: team[a].act(obs[a], infos[a]) for a in env.agents})
        trace.append((obs, infos))
        if read is not None:
            read(env)
        if until_merged and env.shared.members:
            break
    return trace


def _merged(mapping: dict, seed: int):
    env = two_robot_explore_v0.parallel_env(world={"size": (10.0, 10.0)}, max_cycles=800,
                                            mapping=mapping)
    _episode(env, seed, 800, until_merged=True)
    assert env.shared.members, f"seed {seed} did not merge in {env.steps} steps"
    return env


@pytest.fixture(scope="module")
def rigid():
    return _merged(FAST, RIGID_SEED)


@pytest.fixture(scope="module")
def graph():
    pytest.importorskip("gtsam")
    return _merged(GRAPH, GRAPH_SEED)


def _centres(snap, mask: np.ndarray) -> np.ndarray:
    rows, cols = np.nonzero(mask)
    return np.stack([snap.origin[0] + (cols + 0.5) * snap.resolution,
                     snap.origin[1] + (rows + 0.5) * snap.resolution], axis=1)


def _check_fused(env, agent: str) -> None:
    """After a merge with perfect odometry: ``agent``'s fused map holds both robots, knows
    more than its own map, and its walls (its own and those added) lie on the world's."""
    i = env.possible_agents.index(agent)
    fused, own = env.fused_map(agent), env.robot_map(agent)
    assert fused.robots == env.merge_state().fused[i] == (0, 1)
    assert fused.states.shape == own.grid.shape and fused.resolution == own.grid.resolution
    np.testing.assert_allclose(fused.origin, own.grid.origin)
    known = own.grid.known_mask()
    assert fused.known_cells == np.count_nonzero(fused.known_mask()) > known.sum() + 100
    to_world = env.frames[i]
    segments = env.world.segments
    occupied = fused.occupied_mask()
    added = occupied & ~own.grid.occupied_mask()
    assert added.sum() > 100
    assert wall_share(_centres(fused, occupied), to_world, segments) > 0.85
    assert wall_share(_centres(fused, added), to_world, segments) > 0.8


def test_rigid_merge_fuses_the_teammate_onto_the_true_walls(rigid):
    for agent in rigid.possible_agents:
        _check_fused(rigid, agent)
        # the larger cell state wins: what the robot knows stays known
        own = rigid.robot_map(agent).grid.known_mask()
        assert not (own & ~rigid.fused_map(agent).known_mask()).any()
    # robot 0's fused map is the shared map's: every cell it knows, the shared map knows
    fused = rigid.fused_map("robot_0")
    assert not (fused.known_mask() & ~rigid.shared.ever).any()


def test_pose_graph_fuses_the_teammate_onto_the_true_walls(graph):
    for agent in graph.possible_agents:
        _check_fused(graph, agent)
    # with perfect odometry every accepted window alignment is right (5°, 0.5 m) at its anchors
    errors = graph._graph.link_errors()
    assert errors and max(rot for rot, _ in errors) < 5.0
    assert max(trans for _, trans in errors) < 0.5
    # searches near the estimate carry their evidence and a calibrated confidence, not 1
    near = [rec for rec in graph._graph.records if rec.features is not None]
    assert near and all(tuple(rec.features) == NEAR_FEATURES and 0 < rec.confidence < 1
                        for rec in near)
    # on a merge step robot 0's shared map is recomposed: the same cells
    assert graph.steps % GRAPH["merge_every"] == 0
    np.testing.assert_array_equal(graph.fused_map("robot_0").known_mask(), graph.shared.ever)


@pytest.mark.parametrize("mapping", [FAST, GRAPH], ids=["rigid", "pose_graph"])
def test_before_a_merge_it_is_the_robots_own_grid(mapping):
    if mapping.get("pose_graph"):
        pytest.importorskip("gtsam")
    env = two_robot_explore_v0.parallel_env(mapping=mapping, **SMALL)
    _episode(env, 0, 40)
    assert not env.shared.members
    for i, agent in enumerate(env.possible_agents):
        fused = env.fused_map(agent)
        np.testing.assert_array_equal(fused.states, env.robot_map(agent).grid.states())
        assert fused.robots == (i,) and fused.step == env.steps == 40


def test_a_team_reads_every_robots_fused_map():
    # every merge accepted (as tests/envs/test_merging.py), a 5 m range: fused maps come
    # and go, some from teammates' maps kept since their last contact
    mapping = {**FAST, "accept_threshold": 0.0, "team_accept_threshold": 0.0}
    env = multi_robot_explore_v0.parallel_env(n_robots=3, world={"size": (12.0, 12.0)},
                                              comm={"range": 5.0}, max_cycles=800,
                                              mapping=mapping)
    seen = set()

    def read(env):
        state = env.merge_state()
        for i, agent in enumerate(env.possible_agents):
            fused = env.fused_map(agent)
            assert fused.robots == state.fused[i]
            if len(fused.robots) == 1:
                np.testing.assert_array_equal(fused.states, env.robot_map(agent).grid.states())
            seen.add(fused.robots)

    _episode(env, 2, 150, read=read)
    assert any(len(r) > 1 for r in seen)  # some robot fused a teammate


def test_read_only_cached_per_step_and_never_changed_by_later_steps(rigid):
    snap = rigid.fused_map("robot_1")
    assert rigid.fused_map("robot_1") is snap
    with pytest.raises(ValueError, match="read-only"):
        snap.states[0, 0] = 1
    with pytest.raises(dataclasses.FrozenInstanceError):
        snap.robots = (1,)
    env = two_robot_explore_v0.parallel_env(mapping=FAST, **SMALL)
    _episode(env, 0, 5)
    first = env.fused_map("robot_0")
    kept = first.states.copy()
    env.step({a: np.array([0.5, 0.3], dtype=np.float32) for a in env.agents})
    later = env.fused_map("robot_0")
    assert later is not first and later.step == first.step + 1
    np.testing.assert_array_equal(first.states, kept)


def test_bad_agent_is_the_error_robot_map_gives():
    env = two_robot_explore_v0.parallel_env(**SMALL)
    with pytest.raises(RuntimeError, match="call reset"):
        env.fused_map("robot_0")
    env.reset(seed=0)
    for bad in ("robot_2", 0):
        with pytest.raises(ValueError) as want:
            env.robot_map(bad)
        with pytest.raises(ValueError, match=r"agent must be one of \['robot_0', 'robot_1'\], "
                                             r"got ") as got:
            env.fused_map(bad)
        assert str(got.value) == str(want.value)


@pytest.mark.parametrize("mapping", [FAST, GRAPH], ids=["rigid", "pose_graph"])
def test_same_seed_same_maps_and_reading_changes_nothing(mapping):
    """Two runs of a seed give identical fused maps; a run that reads every robot's fused map
    every step steps exactly as one that never reads it."""
    if mapping.get("pose_graph"):
        pytest.importorskip("gtsam")
    seed = GRAPH_SEED if mapping.get("pose_graph") else RIGID_SEED
    snaps = []

    def read(env):
        snaps.append([env.fused_map(a) for a in env.possible_agents])

    def run(reader):
        env = two_robot_explore_v0.parallel_env(world={"size": (10.0, 10.0)}, max_cycles=800,
                                                mapping=mapping)
        return env, _episode(env, seed, 330, read=reader)

    env_a, trace_a = run(read)
    env_b, trace_b = run(None)
    assert env_a.shared.members  # the runs cover a merge
    assert len(trace_a) == len(trace_b)
    for (obs_a, info_a), (obs_b, info_b) in zip(trace_a, trace_b, strict=True):
        for agent in obs_a:
            for key in obs_a[agent]:
                np.testing.assert_array_equal(obs_a[agent][key], obs_b[agent][key])
            assert repr(info_a[agent]) == repr(info_b[agent])
    last = snaps[-1]
    for agent, snap in zip(env_b.possible_agents, last, strict=True):
        again = env_b.fused_map(agent)
        np.testing.assert_array_equal(again.states, snap.states)
        assert (again.robots, again.step, again.known_cells) == (snap.robots, snap.step,
                                                                   snap.known_cells)


def test_the_renderers_fused_panel_draws_the_pose_graphs_fused_map(graph):
    """``render()``'s fused panel is robot 0's ``fused_map``: with the pose graph, its
    corrected submaps — not its own map with the teammate moved in rigidly."""
    pytest.importorskip("pygame")
    from envs.explore.mapping import fused_states
    from envs.explore.render import PANEL, Renderer

    class Rigid:  # the env as the renderer reads it, its fused map composed rigidly
        def __init__(self, env):
            self._env = env

        def __getattr__(self, name):
            return getattr(self._env, name)

        def _fused_window(self, r):
            env = self._env
            return fused_states(env.maps[r], [(env.views.view(r, j), to_r) for j, to_r
                                              in env.merge_state().frames[r].items() if j != r])

    renderer = Renderer("rgb_array", 4)
    try:
        drawn, rigid = renderer.draw(graph), renderer.draw(Rigid(graph))
    finally:
        renderer.close()
    panel = (slice(0, PANEL), slice(PANEL, 2 * PANEL))  # the top right panel, (row, col)
    assert not np.array_equal(drawn[panel], rigid[panel])
    others = (slice(PANEL, 2 * PANEL), slice(0, 2 * PANEL))
    np.testing.assert_array_equal(drawn[others], rigid[others])


def test_pose_graph_fused_map_holds_only_the_submaps_received(graph):
    """Under communication limits a robot's fused map holds a teammate's submaps as of their
    last contact: none if they never met, the closed ones after that, all while in contact."""
    g, maps = graph._graph, graph.maps

    class Apart:  # robots out of contact, last in contact at step ``seen``
        def __init__(self, seen):
            self.seen = np.array([[graph.steps, seen], [seen, graph.steps]])

        def in_contact(self, i, j):
            return i == j

    def known(views):
        return maps[0].grid.model.classify(g.fused_log_odds(0, maps, views)) != 0

    live = known(graph.views)  # unlimited communication: in contact
    never, early = known(Apart(-1)), known(Apart(2 * GRAPH["anchor_every"]))
    just_lost = known(Apart(graph.steps))
    own = graph.robot_map("robot_0").grid.known_mask()
    assert never.sum() < early.sum() < just_lost.sum() <= live.sum()
    # more evidence can cancel a cell's log-odds back to unknown, rarely
    assert (early & ~just_lost).sum() < 0.01 * early.sum()
    assert (just_lost & ~live).sum() < 0.01 * just_lost.sum()
    assert abs(int(never.sum()) - int(own.sum())) < 0.05 * own.sum()  # its own map, corrected
    assert len(g.received(0, 1, maps, Apart(2 * GRAPH["anchor_every"]))) == 2
    assert g.received(0, 1, maps, Apart(-1)) == []


def test_with_perfect_odometry_the_working_map_stays_as_scanned(graph):
    """Robot 0 has a teammate, so its working map is straightened on merge steps; with
    perfect odometry every correction is (nearly) the identity and the map stays the one its
    scans made (``scanned_map``)."""
    work = graph.robot_map("robot_0").grid
    scanned = graph.scanned_map("robot_0")
    assert scanned.robots == (0,) and scanned.states.shape == work.shape
    known = scanned.known_mask() | work.known_mask()
    differ = np.count_nonzero(scanned.states != work.states())
    assert differ <= 0.01 * np.count_nonzero(known)


def test_without_the_pose_graph_the_scanned_map_is_the_own_map(rigid):
    for agent in rigid.possible_agents:
        np.testing.assert_array_equal(rigid.scanned_map(agent).states,
                                      rigid.robot_map(agent).grid.states())
    with pytest.raises(ValueError, match=r"agent must be one of \['robot_0', 'robot_1'\], "
                                         r"got 'robot_9'"):
        rigid.scanned_map("robot_9")
