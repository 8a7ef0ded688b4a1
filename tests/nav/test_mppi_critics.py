"""MPPI critics on hand-made trajectories; the numeric cases of Nav2's
``nav2_mppi_controller/test/critics_tests.cpp`` (Jazzy) where they are data, and the
costmap critics against costs written into the grid."""

from __future__ import annotations

import math

import numpy as np
import pytest
from navtest_helpers import make_costmap

from eddiebot.nav.controllers.mppi import MPPIConfig
from eddiebot.nav.controllers.mppi.critics import (
    ConstraintCritic,
    CostCritic,
    CostCriticConfig,
    CriticData,
    GoalAngleCritic,
    GoalAngleCriticConfig,
    GoalCritic,
    ObstaclesCritic,
    PathAlignCritic,
    PathAngleCritic,
    PathAngleCriticConfig,
    PathFollowCritic,
    PreferForwardCritic,
    TwirlingCritic,
    VelocityDeadbandCritic,
    VelocityDeadbandCriticConfig,
    normalize_angles,
)

B, T = 1000, 30


def data(*, pose=(0.0, 0.0, 0.0), goal=(0.0, 0.0, 0.0), path=None, costmap=None, dt=0.1,
         shape=(B, T), goal_tolerance=None) -> CriticData:
    z = np.zeros(shape)
    return CriticData(pose=np.array(pose, float), goal=np.array(goal, float),
                      path=np.zeros((10, 3)) if path is None else np.asarray(path, float),
                      vx=z.copy(), wz=z.copy(), traj_x=z.copy(), traj_y=z.copy(),
                      traj_yaw=z.copy(), costs=np.zeros(shape[0]), model_dt=dt,
                      costmap=costmap, goal_tolerance=goal_tolerance)


def test_normalize_angles() -> None:
    a = normalize_angles([0.0, math.pi, -math.pi, 3 * math.pi / 2, -7.0])
    assert a == pytest.approx([0.0, -math.pi, -math.pi, -math.pi / 2, -7.0 + 2 * math.pi])


def test_constraint_critic() -> None:
    # upstream's case has no vy_max set (0 in the critic): limits 0.5 and -0.35
    critic = ConstraintCritic(None, MPPIConfig(vy_max=0.0))
    d = data()
    d.vx[:] = 0.40
    critic.score(d)
    assert d.costs.sum() == pytest.approx(0.0, abs=1e-9)
    d.vx[-1] = 0.60
    critic.score(d)
    assert d.costs[-1] == pytest.approx(1.2, abs=0.01)  # 0.1 over × 0.1 s × 30 × weight 4
    d.costs[:] = 0.0
    d.vx[1] = -0.45
    critic.score(d)
    assert d.costs[1] == pytest.approx(1.2, abs=0.01)
    # with the controller's vy_max (0.5 by default) the magnitude limit is hypot(0.5, 0.5)
    critic = ConstraintCritic(None, MPPIConfig())
    d = data()
    d.vx[:] = 0.75
    critic.score(d)
    assert d.costs[0] == pytest.approx((0.75 - math.hypot(0.5, 0.5)) * 0.1 * 30 * 4.0)


def test_goal_angle_critic() -> None:
    path = np.zeros((10, 3))
    path[9] = (10.0, 0.0, 3.14)
    critic = GoalAngleCritic()
    for x, expected in ((1.0, 0.0), (9.2, 0.0), (9.7, 9.42)):
        d = data(pose=(x, 0, 0), goal=(10.0, 0, 0), path=path)
        critic.score(d)
        assert d.costs[0] == pytest.approx(expected, abs=0.02)  # (3.14 - 0) × weight 3
    sym = GoalAngleCritic(GoalAngleCriticConfig(symmetric_yaw_tolerance=True))
    d = data(pose=(9.7, 0, 0), goal=(10.0, 0, 0), path=path)
    sym.score(d)
    assert d.costs[0] == pytest.approx(0.0, abs=0.02)


def test_goal_critic() -> None:
    path = np.zeros((10, 3))
    critic = GoalCritic()
    d = data(pose=(1.0, 0, 0), goal=(10.0, 0, 0), path=path)
    critic.score(d)
    assert d.costs.sum() == 0.0
    d = data(pose=(1.0, 0, 0), goal=(0.5, 0, 0), path=path)
    critic.score(d)
    assert d.costs[2] == pytest.approx(2.5)  # mean distance 0.5 × weight 5
    assert d.costs.sum() == pytest.approx(2500.0)


def test_path_angle_critic_modes() -> None:
    path = np.zeros((10, 3))
    path[9, 0] = 0.15
    critic = PathAngleCritic()
    d = data(goal=(0.15, 0, 0), path=path)
    critic.score(d)
    assert d.costs.sum() == 0.0  # within threshold_to_consider of the goal
    path[9, 0] = 0.95

    def score(mode: int, px: float, py: float) -> float:
        c = PathAngleCritic(PathAngleCriticConfig(mode=mode))
        p = path.copy()
        p[6, :2] = (px, py)
        d = data(goal=(0.95, 0, 0), path=p)
        d.furthest_reached_path_point = 2  # offset 4 → the 6th point
        c.score(d)
        return float(d.costs[0])

    assert score(0, 1.0, 0.0) == 0.0
    assert score(0, -1.0, 4.0) == pytest.approx(math.atan2(4, -1) * 2.2, abs=1e-2)  # 3.9947
    assert score(1, 1.0, 0.0) == 0.0
    assert score(1, -1.0, 0.0) == 0.0  # behind, and direction does not matter
    assert score(1, -1.0, 4.0) == pytest.approx(2.9167, abs=1e-2)
    assert score(2, -1.0, 0.0) == 0.0
    assert score(2, -1.0, 4.0) == pytest.approx(2.9167, abs=1e-2)
    # without reversing (vx_min 0) "no directional preference" falls back to forward
    c = PathAngleCritic(PathAngleCriticConfig(mode=1), MPPIConfig(vx_min=0.0))
    assert c.mode == 0


def test_prefer_forward_critic() -> None:
    critic = PreferForwardCritic()
    d = data(pose=(1.0, 0, 0), goal=(0.15, 0, 0))
    d.vx[:] = 1.0
    critic.score(d)
    assert d.costs.sum() == 0.0
    d.vx[:] = -1.0
    critic.score(d)
    assert d.costs[0] == pytest.approx(15.0)  # 1.0 × 0.1 s × weight 5 × 30 steps


def test_twirling_critic() -> None:
    critic = TwirlingCritic()
    d = data(pose=(1.0, 0, 0), goal=(0.15, 0, 0), goal_tolerance=0.25)
    critic.score(d)
    assert d.costs.sum() == 0.0
    d.wz[0] = 10.0
    critic.score(d)
    assert d.costs[0] == pytest.approx(100.0)  # mean 10 × weight 10
    d = data(pose=(0.2, 0, 0), goal=(0.15, 0, 0), goal_tolerance=0.25)
    d.wz[0] = 10.0
    critic.score(d)
    assert d.costs[0] == 0.0  # inside the goal checker's tolerance


def test_path_follow_critic() -> None:
    cm = make_costmap(np.zeros((60, 60), dtype=np.int8), resolution=0.1)
    path = np.zeros((6, 3))
    path[5, 0] = 1.8
    critic = PathFollowCritic()
    d = data(pose=(2.0, 0, 0), goal=(1.8, 0, 0), path=path, costmap=cm)
    critic.score(d)
    assert d.costs.sum() == 0.0
    path[5, 0] = 0.15
    d = data(pose=(2.0, 0, 0), goal=(0.15, 0, 0), path=path, costmap=cm)
    critic.score(d)
    assert d.costs.sum() == pytest.approx(750.0, abs=1e-2)  # 0.15 × weight 5 × 1000


def test_path_align_critic() -> None:
    occ = np.zeros((40, 40), dtype=np.int8)
    cm = make_costmap(occ, resolution=0.1)
    critic = PathAlignCritic()
    path = np.zeros((10, 3))
    path[9, 0] = 0.15
    d = data(pose=(1.0, 0, 0), goal=(0.15, 0, 0), path=path, costmap=cm)
    d.furthest_reached_path_point = 21
    critic.score(d)
    assert d.costs.sum() == 0.0
    path = np.zeros((22, 3))
    path[:, 0] = np.minimum(np.arange(22) * 0.1, 0.9)
    d = data(goal=(0.9, 0, 0), path=path, costmap=cm)
    d.furthest_reached_path_point = 21
    d.traj_x[:] = 0.66
    critic.score(d)
    # trajectories that do not move stay matched to path point 0: 0.66 m × weight 10
    assert d.costs.sum() == pytest.approx(6600.0, abs=1e-2)
    occ[11:31, 11:31] = 100  # 1.1-3 m occupied: the path through it is not followed
    cm = make_costmap(occ, resolution=0.1)
    path[:, :2] = 1.5
    d = data(goal=(1.5, 0, 0), path=path, costmap=cm)
    d.furthest_reached_path_point = 21
    d.traj_x[:] = 0.66
    critic.score(d)
    assert d.costs.sum() == 0.0


def test_velocity_deadband_critic() -> None:
    critic = VelocityDeadbandCritic(VelocityDeadbandCriticConfig(
        deadband_velocities=(0.08, 0.08, 0.08)))
    d = data()
    d.vx[:] = 0.8
    d.wz[:] = 0.8
    critic.score(d)
    assert d.costs.sum() == 0.0
    d.vx[:] = 0.01
    d.wz[:] = 0.021
    critic.score(d)
    # DiffDrive: (0.07 + 0.059) × 0.1 s × 30 × weight 35 (upstream's Omni case adds vy: 19.845)
    assert d.costs[1] == pytest.approx(13.545, abs=0.01)


def _grid_costmap(size: int = 40, resolution: float = 0.1):
    cm = make_costmap(np.zeros((size, size), dtype=np.int8), resolution=resolution,
                      robot_radius=0.2, inflation_radius=0.55, cost_scaling_factor=3.0)
    return cm


def test_cost_critic_sums_sampled_cells() -> None:
    cm = _grid_costmap()
    g = cm.master.data
    g[5, 5] = 100   # cell of (0.55, 0.55)
    g[5, 15] = 220  # cell of (1.55, 0.55)
    g[5, 25] = 254  # lethal
    critic = CostCritic(CostCriticConfig(near_collision_cost=200))
    d = data(goal=(3.5, 3.5, 0), shape=(4, 4), costmap=cm)
    xs = np.array([[0.55, 9, 0.55, 9],     # two sampled points on cost 100
                   [1.55, 9, 0.25, 9],     # one point at/above near_collision_cost: critical
                   [2.55, 9, 0.25, 9],     # lethal: collision
                   [0.25, 9, 0.35, 9]])    # free
    d.traj_x[:] = xs
    d.traj_y[:] = 0.55
    critic.score(d)
    per_point = 3.81 / 254.0 / 2  # weight / 254 over the 2 sampled points (step 2 of 4)
    assert d.costs == pytest.approx([200 * per_point, 300 * per_point, 1e6 * per_point, 0.0])
    assert not d.fail_flag
    # near the goal only the critical costs count
    d = data(goal=(0.3, 0.3, 0), shape=(4, 4), costmap=cm)
    d.traj_x[:] = xs
    d.traj_y[:] = 0.55
    critic.score(d)
    assert d.costs[0] == 0.0 and d.costs[1] == pytest.approx(300 * per_point)
    # every trajectory colliding raises the fail flag; off the map is a collision when
    # unknown space is not tracked
    d = data(goal=(3.5, 3.5, 0), shape=(2, 4), costmap=cm)
    d.traj_x[:] = [[2.55, 0, 0, 0], [-1.0, 0, 0, 0]]
    d.traj_y[:] = 0.55
    critic.score(d)
    assert d.fail_flag and d.costs == pytest.approx([1e6 * per_point] * 2)


def test_obstacles_critic_distances_from_inflation() -> None:
    cm = _grid_costmap()
    g = cm.master.data
    g[5, 5] = 100
    g[5, 15] = 240
    critic = ObstaclesCritic()
    d = data(goal=(3.5, 3.5, 0), shape=(3, 2), costmap=cm)
    d.traj_x[:] = [[0.55, 0.25], [1.55, 0.25], [0.25, 0.25]]
    d.traj_y[:] = 0.55
    critic.score(d)
    scale, radius = 3.0, 0.55
    dist100 = (math.log(253.0) - math.log(100.0)) / scale   # 0.309 m beyond inscribed
    dist240 = (math.log(253.0) - math.log(240.0)) / scale   # 0.0176 m: inside the margin
    rep = np.array([radius - dist100, radius - dist240, 0.0]) / 2  # normalised by T = 2
    raw = np.array([0.0, 0.10 - dist240, 0.0])
    assert d.costs == pytest.approx(20.0 * raw + 1.5 * rep)
    assert not d.fail_flag


def test_cost_critic_footprint_checks() -> None:
    from eddiebot.maps import OccupancyMap
    from eddiebot.nav.costmap import build_costmap
    from eddiebot.nav.errors import ControllerError

    critic = CostCritic(CostCriticConfig(consider_footprint=True))
    d = data(goal=(3.5, 3.5, 0), shape=(1, 2), costmap=_grid_costmap())
    with pytest.raises(ControllerError, match="consider_footprint"):
        critic.score(d)  # a robot_radius costmap has no footprint polygon
    occ = np.zeros((40, 40), dtype=np.int8)
    occ[:, 20] = 100  # a wall at x = 2.0-2.1
    cm = build_costmap({"resolution": 0.1, "footprint": "[[0.3, 0.1], [0.3, -0.1], "
                        "[-0.3, -0.1], [-0.3, 0.1]]", "footprint_padding": 0.0,
                        "plugins": ["static_layer", "inflation_layer"],
                        "inflation_layer": {"inflation_radius": 0.5, "cost_scaling_factor": 3.0}},
                       "fp")
    cm.set_static_map(OccupancyMap(occ, 0.1))
    cm.update_map((0.0, 0.0, 0.0))
    # the centre at x = 1.75 is 0.3 m from the wall, above the cost at the circumscribed
    # radius: the footprint decides. The 0.6 m long footprint along x reaches the wall, across
    # it (yaw 90°) it does not and the centre's cost counts
    d = data(goal=(3.5, 3.5, 0), shape=(2, 2), costmap=cm)
    d.traj_x[:] = 1.75
    d.traj_y[:] = 2.0
    d.traj_yaw[0] = 0.0
    d.traj_yaw[1] = math.pi / 2
    centre = cm.master.cost_at_world(1.75, 2.0)
    assert centre == int(252 * math.exp(-3.0 * (0.3 - 0.1)))
    critic.score(d)
    assert d.costs[0] == pytest.approx(1e6 * 3.81 / 254.0)  # 1 sampled point
    assert d.costs[1] == pytest.approx(centre * 3.81 / 254.0)
    # upstream skips free cells before any footprint check: a free centre never collides
    d = data(goal=(3.5, 3.5, 0), shape=(1, 2), costmap=cm)
    d.traj_x[:] = 1.0
    d.traj_y[:] = 2.0
    critic.score(d)
    assert d.costs[0] == 0.0
