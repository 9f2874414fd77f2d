"""Frontier planning on hand-made grids: the shared map of CoordinatedFrontier (teammate's
evidence moved by the merge transform), goals given up, and the teammate's goal steering the
choice."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.frontier_planning import FrontierConfig, frontier_map
from agents.scripted import Blackboard, CoordinatedFrontier, Frontier
from envs.explore.config import RobotConfig, SonarConfig
from fusion import Rigid2D
from topo.grid import OccupancyGrid

CFG = FrontierConfig()


def grid_with(free_boxes, wall_boxes=()) -> OccupancyGrid:
    """A 0.1 m grid over ±8 m: cells in ``free_boxes`` (xmin, ymin, xmax, ymax) free, in
    ``wall_boxes`` occupied (hit many times), the rest unknown."""
    g = OccupancyGrid(0.1, (-8.0, -8.0, 8.0, 8.0))
    xy = g.cell_to_world(np.argwhere(np.ones(g.shape, bool))).reshape(*g.shape, 2)
    for value, boxes in ((-2.0, free_boxes), (3.0, wall_boxes)):
        for x0, y0, x1, y1 in boxes:
            inside = ((xy[..., 0] >= x0) & (xy[..., 0] < x1) & (xy[..., 1] >= y0)
                      & (xy[..., 1] < y1))
            g.log_odds[inside] = value
    g._states[:] = g._classify(g.log_odds)
    return g


def frontier_xy(fmap) -> np.ndarray:
    cells = np.argwhere(fmap.labels > 0)
    return fmap.cell_to_xy(cells)


# own robot: a room x in [-4, 0), y in [-3, 3) with walls above and below; open at x = 0
OWN = grid_with([(-4.0, -3.0, 0.0, 3.0)], [(-4.0, 3.0, 0.0, 3.3), (-4.0, -3.3, 0.0, -3.0),
                                          (-4.3, -3.3, -4.0, 3.3)])


def test_frontier_of_own_grid_is_at_the_opening():
    fmap = frontier_map(OWN, np.array([-3.0, 0.0]), CFG)
    xy = frontier_xy(fmap)
    assert len(xy) > 30 and np.all(np.abs(xy[:, 0]) < 0.3)  # the open side, x ≈ 0
    (cluster,) = fmap.clusters(CFG.min_cluster_cells)
    assert math.isfinite(cluster["cost"]) and 2.5 < cluster["cost"] < 6.0


def test_teammate_evidence_moved_by_the_transform_removes_explored_frontiers():
    # the teammate knows x in [0, 4) of the same room; its frame is ours rotated by 90°:
    # p_mate = R(90°) p_own, so (x, y) lands at (-y, x)
    to_mate = Rigid2D(math.pi / 2, (0.0, 0.0))
    mate = grid_with([(-3.0, 0.0, 3.0, 4.0)], [(3.0, 0.0, 3.3, 4.0), (-3.3, 0.0, -3.0, 4.0)])
    fmap = frontier_map(OWN, np.array([-3.0, 0.0]), CFG, teammates=[(mate, to_mate)])
    xy = frontier_xy(fmap)
    # the opening at x = 0 is explored by the teammate; the shared map's frontier is at x ≈ 4,
    # reached through the teammate's free cells
    assert len(xy) > 30 and np.all(xy[:, 0] > 3.5)
    (cluster,) = fmap.clusters(CFG.min_cluster_cells)
    assert 6.0 < cluster["cost"] < 10.0
    # a wrong transform (no rotation) puts the teammate's evidence elsewhere: opening stays
    wrong = frontier_map(OWN, np.array([-3.0, 0.0]), CFG, teammates=[(mate, Rigid2D())])
    assert np.any(np.abs(frontier_xy(wrong)[:, 0]) < 0.3)


def test_excluded_points_drop_frontier_cells_within_the_give_up_radius():
    fmap = frontier_map(OWN, np.array([-3.0, 0.0]), CFG, exclude=np.array([[0.0, 1.5]]))
    xy = frontier_xy(fmap)
    assert len(xy) > 10
    assert np.all(np.hypot(xy[:, 0], xy[:, 1] - 1.5) >= CFG.give_up_radius)
    assert np.any(xy[:, 1] < 0.0)


# a corridor y in [-1, 1) from x = -3 to 5 with walls along it: frontiers at both ends, the
# left one nearer to a robot at x = 0
CORRIDOR = grid_with([(-3.0, -1.0, 5.0, 1.0)], [(-3.0, 1.0, 5.0, 1.3), (-3.0, -1.3, 5.0, -1.0)])
NO_ECHO = {"sonar": np.ones(8, np.float32), "teammate": np.zeros(5, np.float32)}


class Maps:
    """Stands in for the env an explorer is bound to: fixed grids per robot and a merge
    transform in use (``None``: not merged)."""

    possible_agents = ("robot_0", "robot_1")
    config = SimpleNamespace(sonar=SonarConfig(), robot=RobotConfig())

    def __init__(self, grids, transform=None):
        self.grids, self.transform = grids, transform

    def robot_map(self, agent):
        return SimpleNamespace(grid=self.grids[agent])

    def merge_state(self):
        return SimpleNamespace(transform=self.transform)


def bound(explorer, agent="robot_0", mate_grid=None, transform=None):
    explorer.bind(Maps({agent: CORRIDOR, "robot_1" if agent == "robot_0" else "robot_0":
                        mate_grid if mate_grid is not None else grid_with([])}, transform),
                  agent)
    explorer.reset(0)
    return explorer


def info_at(x: float, y: float = 0.0) -> dict:
    return {"odometry": np.array([x, y, 0.0])}


def test_frontier_goes_to_the_nearer_end_then_gives_it_up_when_reached():
    robot = bound(Frontier())
    robot.act(NO_ECHO, info_at(0.0))
    goal = robot.plan.goal
    assert goal[0] < -2.5
    # arriving there does not clear it (the map is frozen): the goal is given up and the
    # robot heads for the other end
    robot.act(NO_ECHO, info_at(*goal))
    assert any(np.allclose(g, goal) for g in robot.given_up)
    assert robot.plan.goal[0] > 4.0
    assert robot.events["given_up_reached"] == 1


def test_an_unbound_frontier_explorer_says_to_bind_it():
    robot = Frontier()
    robot.reset(0)
    with pytest.raises(RuntimeError, match=r"bind it first \(explorer.bind\(env, agent\)"):
        robot.act(NO_ECHO, info_at(0.0))
    with pytest.raises(TypeError, match="env must be a two_robot_explore env"):
        robot.bind(object(), "robot_0")
    with pytest.raises(ValueError, match=r"agent must be one of \['robot_0', 'robot_1'\], got 'r2'"):
        robot.bind(Maps({}), "r2")
    with pytest.raises(ValueError, match="must be 'robot_1', got 'robot_0'"):
        CoordinatedFrontier(1, Blackboard()).bind(Maps({}), "robot_0")


def test_coordinated_robot_leaves_the_teammates_goal_to_the_teammate():
    alone = bound(Frontier())
    alone.act(NO_ECHO, info_at(0.0))
    assert alone.plan.goal[0] < -2.5
    board = Blackboard()
    # merged (identity transform); the teammate knows nothing extra and goes left
    robot = bound(CoordinatedFrontier(0, board), transform=Rigid2D())
    board.goals[1] = np.array([-2.9, 0.0])
    robot.act(NO_ECHO, info_at(0.0))
    assert robot.plan.goal[0] > 4.0
    np.testing.assert_allclose(board.goals[0], robot.plan.goal, atol=1.0)



def test_coordinated_robot_leaves_the_end_nearer_its_teammate_to_the_teammate():
    robot = bound(CoordinatedFrontier(0, Blackboard()), transform=Rigid2D())
    # no goal announced; the teammate is seen (merge transform) 2 m left of the robot
    seen = {**NO_ECHO, "teammate": np.array([-2.0, 0.0, 1.0, 0.0, 1.0], np.float32)}
    robot.act(seen, info_at(0.0))
    assert robot.events["assigned"] == 1
    assert robot.plan.goal[0] > 4.0
    assert np.linalg.norm(robot.plan.path[0]) < 0.2  # its own path, not the teammate's
    # without the assignment it takes the nearer end whatever the teammate does
    lone = bound(CoordinatedFrontier(1, Blackboard(), assign=False, mate_penalty=0.0),
                 agent="robot_1", transform=Rigid2D())
    lone.act(seen, info_at(0.0))
    assert lone.plan.goal[0] < -2.5 and "assigned" not in lone.events


# ---------------------------------------------------------------------------- teams of N
# a T of corridors: y in [-1, 1) from x = -3 to 5, and x in [0, 2) from y = 1 up to 5; open
# at its three ends (left x = -3, right x = 5, top y = 5). From (0.5, 0) the left end is the
# nearest, the top the farthest.
TEE = grid_with([(-3.0, -1.0, 5.0, 1.0), (0.0, 1.0, 2.0, 5.0)],
                [(-3.0, -1.3, 5.0, -1.0), (-3.0, 1.0, 0.0, 1.3), (2.0, 1.0, 5.0, 1.3),
                 (-0.3, 1.3, 0.0, 5.0), (2.0, 1.3, 2.3, 5.0)])
START = (0.5, 0.0)


class TeamMaps(Maps):
    """A bound env of ``n`` robots with the team interface: every robot in every robot's
    fused map (identity frames), in contact as ``contacts`` says; teammates know nothing."""

    def __init__(self, n, contacts):
        super().__init__({f"robot_{i}": TEE if i == 0 else grid_with([]) for i in range(n)})
        self.possible_agents = tuple(f"robot_{i}" for i in range(n))
        self.contacts = contacts

    def teammate_map(self, agent, teammate):
        return self.robot_map(teammate)

    def merge_state(self):
        frames = tuple({j: Rigid2D() for j in range(len(self.possible_agents))}
                       for _ in self.possible_agents)
        return SimpleNamespace(transform=Rigid2D(), frames=frames, contacts=self.contacts)


def seen_at(*teammates, valid=True):
    """A ``teammates`` observation of robot 0 at :data:`START` facing +x: teammates at these
    points (own frame), all in contact."""
    rows = np.zeros((len(teammates), 7), np.float32)
    for k, (x, y) in enumerate(teammates):
        rows[k] = (x - START[0], y - START[1], 1.0, 0.0, float(valid), 1.0, 0.0)
    return {"sonar": np.ones(8, np.float32), "teammates": rows}


def end_of(goal) -> str:
    x, y = goal
    return "top" if y > 3.0 else ("left" if x < 0.0 else "right")


def test_alone_the_robot_takes_the_nearest_end_of_the_tee():
    robot = Frontier()
    robot.bind(TeamMaps(3, ((), (), ())), "robot_0")
    robot.reset(0)
    robot.act(seen_at((-2.0, 0.0), (1.0, 4.0)), info_at(*START))
    assert end_of(robot.plan.goal) == "left"


@pytest.mark.parametrize(("contacts", "expected"), [
    (((1, 2), (0, 2), (0, 1)), "right"),  # both teammates: each takes the end it is at
    (((1,), (0,), ()), "right"),  # robot 1 only: the joint pair, robot 1 keeps the left
])
def test_robots_in_contact_are_assigned_distinct_ends(contacts, expected):
    robot = CoordinatedFrontier(0, Blackboard())
    robot.bind(TeamMaps(3, contacts), "robot_0")
    robot.reset(0)
    robot.act(seen_at((-2.0, 0.0), (1.0, 4.0)), info_at(*START))
    assert robot.events["assigned"] == 1
    assert end_of(robot.plan.goal) == expected


def test_three_robots_spread_over_the_three_ends():
    board = Blackboard()
    env = TeamMaps(3, ((1, 2), (0, 2), (0, 1)))
    robot = CoordinatedFrontier(0, board)
    robot.bind(env, "robot_0")
    robot.reset(0)
    # robot 1 at the left end, robot 2 at the right end: robot 0 is left the top
    robot.act(seen_at((-2.0, 0.0), (4.0, 0.0)), info_at(*START))
    assert end_of(robot.plan.goal) == "top"
    np.testing.assert_allclose(board.goals[0], robot.plan.goal, atol=1.0)


def test_a_teammates_goal_counts_only_while_in_contact():
    left = np.array([-2.9, 0.0])
    for contacts, expected in ((((), (), ()), "left"), (((1,), (0,), ()), "right")):
        board = Blackboard()
        robot = CoordinatedFrontier(0, board)
        robot.bind(TeamMaps(3, contacts), "robot_0")
        robot.reset(0)
        board.goals[1] = left  # robot 1 heads for the left end (its frame = this one)
        # positions unknown (invalid rows): no assignment, only the announced goal
        robot.act(seen_at((0.0, 0.0), (0.0, 0.0), valid=False), info_at(*START))
        assert "assigned" not in robot.events
        assert end_of(robot.plan.goal) == expected, contacts


def test_coordinated_frontier_names_bad_indices():
    for bad in (-1, 1.5, True, "0"):
        with pytest.raises(ValueError, match=rf"index must be an int >= 0, got {bad!r}"):
            CoordinatedFrontier(bad, Blackboard())
    with pytest.raises(ValueError, match="must be 'robot_3', got 'robot_1'"):
        CoordinatedFrontier(3, Blackboard()).bind(TeamMaps(4, ((),) * 4), "robot_1")


# ------------------------------------------------------------------ windows and the whole map
# rooms along a corridor with doorways and open ends: frontiers near and far
ROOMS = grid_with(
    [(-7.0, -1.0, 7.0, 1.0), (-6.0, 1.0, -2.0, 6.0), (2.0, 1.0, 6.0, 5.0), (-1.0, -6.0, 3.0, -1.0)],
    [(-7.0, -1.3, -1.0, -1.0), (3.0, -1.3, 7.0, -1.0), (-2.0, 1.0, 2.0, 1.3),
     (6.0, 1.0, 7.0, 1.3), (-6.3, 1.0, -6.0, 6.0), (-2.0, 1.3, -1.7, 6.0),
     (1.7, 1.3, 2.0, 5.0), (6.0, 1.3, 6.3, 5.0), (-1.3, -6.0, -1.0, -1.3),
     (3.0, -6.0, 3.3, -1.3)])
ROOMS_FREE = np.argwhere(ROOMS.states() == 1)


def whole_map_choice(pose, goal):
    """The cluster Frontier chose before windows: every cluster's cost from one search of the
    whole map, the current goal's (cheapest cell within give_up_radius) favoured."""
    clusters = frontier_map(ROOMS, pose, CFG).clusters(CFG.min_cluster_cells)
    if not clusters:
        return None
    fmap = frontier_map(ROOMS, pose, CFG)

    def current(c):
        xy = fmap.cell_to_xy(np.array([c["cell"]]))[0]
        return goal is not None and np.linalg.norm(xy - goal) < CFG.give_up_radius

    return min(clusters, key=lambda c: c["cost"] - CFG.hysteresis * current(c))


@settings(max_examples=40, deadline=None)
@given(cell=st.integers(0, len(ROOMS_FREE) - 1), goal_cell=st.none() | st.integers(0, 10**6),
       radius=st.sampled_from([1.0, 2.0, 4.0]))
def test_windowed_search_chooses_what_the_whole_map_would(cell, goal_cell, radius):
    pose = ROOMS.cell_to_world(ROOMS_FREE[cell][None])[0]
    goal = None
    if goal_cell is not None:
        front = frontier_xy(frontier_map(ROOMS, pose, CFG))
        goal = front[goal_cell % len(front)] + 0.3 if len(front) else None
    expected = whole_map_choice(pose, goal)
    # as Frontier._select: widen the window until its answer is exact
    slack = CFG.hysteresis if goal is not None else 0.0
    while True:
        fmap = frontier_map(ROOMS, pose, CFG, radius=radius)
        got = fmap.nearest(CFG.min_cluster_cells, goal, CFG.give_up_radius, CFG.hysteresis)
        if math.isinf(fmap.exact_below) or (got is not None
                                            and got["cost"] + slack < fmap.exact_below):
            break
        radius *= 2.0
    assert (got is None) == (expected is None)
    if got is not None:
        assert got["cost"] == pytest.approx(expected["cost"], abs=1e-9)
        path = fmap.path_to(got["cell"])
        assert np.linalg.norm(path[0] - pose) < 0.15 and np.allclose(
            path[-1], fmap.cell_to_xy(np.array([got["cell"]]))[0])


def test_a_window_that_holds_every_known_cell_gives_the_same_map():
    pose = np.array([-3.0, 0.0])
    full = frontier_map(OWN, pose, CFG)
    rows, cols = np.nonzero(OWN.states())
    box = (rows.min() - 5, rows.max() + 5, cols.min() - 5, cols.max() + 5)
    fast = frontier_map(OWN, pose, CFG, within=box)
    np.testing.assert_array_equal(fast.labels, full.labels)
    np.testing.assert_array_equal(fast.cost_to, full.cost_to)
    # a box cutting through known cells is noticed: the whole grid is searched
    cut = frontier_map(OWN, pose, CFG, within=(rows.min(), rows.max() - 10, cols.min(),
                                                cols.max()))
    np.testing.assert_array_equal(cut.labels, full.labels)
    outside = frontier_map(OWN, pose, CFG, within=(-50, -10, -50, -10))
    np.testing.assert_array_equal(outside.labels, full.labels)
    with pytest.raises(ValueError, match="radius applies without teammates only"):
        frontier_map(OWN, pose, CFG, radius=2.0, teammates=[(OWN, Rigid2D())])
    with pytest.raises(ValueError, match=r"FrontierConfig.search_radius must be > 0.0, got 0.0"):
        FrontierConfig(search_radius=0.0)


def test_with_max_plan_age_a_plan_is_kept_while_its_goal_is_a_frontier():
    env = Maps({"robot_0": CORRIDOR, "robot_1": grid_with([])})
    robot = Frontier(FrontierConfig(replan_every=2, max_plan_age=8))
    robot.bind(env, "robot_0")
    robot.reset(0)
    robot.act(NO_ECHO, info_at(0.0))
    plan = robot.plan
    assert plan.goal[0] < -2.5
    for _ in range(5):  # checked at ages 2 and 4: the goal is still a frontier
        robot.act(NO_ECHO, info_at(0.0))
    assert robot.plan is plan and robot.events["plans"] == 1
    # the left end explored: at the next check the goal is no frontier, a new plan is made
    env.grids["robot_0"] = grid_with([(-6.0, -1.0, 5.0, 1.0)],
                                     [(-6.0, 1.0, 5.0, 1.3), (-6.0, -1.3, 5.0, -1.0),
                                      (-6.3, -1.3, -6.0, 1.3)])
    robot.act(NO_ECHO, info_at(0.0))
    assert robot.events["superseded"] == 1 and robot.events["plans"] == 2
    assert robot.plan.goal[0] > 4.0
    with pytest.raises(ValueError, match="FrontierConfig.max_plan_age must be >= 0, got -1"):
        FrontierConfig(max_plan_age=-1)
