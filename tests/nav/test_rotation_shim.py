"""``nav2_rotation_shim_controller::RotationShimController``: the cases of Nav2 Jazzy's
``nav2_rotation_shim_controller/test/test_shim_controller.cpp`` as data, then the shim in
front of MPPI and RPP in a kinematic simulation, its collision check and its parameters.

Upstream's cases put the robot at the origin of ``base_link`` with the path in that frame;
here the path and the robot are shifted by ``O`` into a 6 × 6 m costmap (the shim measures
the sampled point's bearing in the robot's frame, so the shift changes nothing).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from navtest_helpers import make_costmap

from eddiebot.nav.controllers import (
    CONTROLLER_PLUGINS,
    RotationShimConfig,
    RotationShimController,
    SimpleGoalChecker,
    SimpleGoalCheckerConfig,
    build_controller_server,
)
from eddiebot.nav.controllers.mppi import MPPIController
from eddiebot.nav.controllers.rpp import RegulatedPurePursuitController
from eddiebot.nav.cost_values import FREE_SPACE, INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE
from eddiebot.nav.errors import (
    ControllerError,
    InvalidPath,
    NoValidControl,
    ParameterError,
    UnsupportedPlugin,
)
from eddiebot.nav.nodes.params_audit import audit_nav2_params
from eddiebot.nav.plugins import PluginContext
from eddiebot.nav.types import Twist2D

SHIM = "nav2_rotation_shim_controller::RotationShimController"
RPP = "nav2_regulated_pure_pursuit_controller::RegulatedPurePursuitController"
MPPI = "nav2_mppi_controller::MPPIController"
O = np.array([3.0, 3.0, 0.0])  # upstream's base_link origin, inside the test costmap


class Recorder:
    """A primary controller that records what it is given and answers a fixed command."""

    def __init__(self) -> None:
        self.cmd = Twist2D(0.2, 0.0, 0.1)
        self.plans: list[np.ndarray] = []
        self.calls = 0
        self.speed_limits: list[tuple[float, bool]] = []
        self.tolerances: list[float] = []
        self.resets = 0

    def set_plan(self, path: Any) -> None:
        p = np.asarray(path, dtype=float)
        if p.shape[0] == 0:
            raise InvalidPath("received an empty or malformed plan")
        self.plans.append(p)

    def set_speed_limit(self, speed_limit: float, percentage: bool) -> None:
        self.speed_limits.append((speed_limit, percentage))

    def set_goal_tolerance(self, xy_tolerance: float) -> None:
        self.tolerances.append(xy_tolerance)

    def reset(self) -> None:
        self.resets += 1

    def compute_velocity_commands(self, pose: Any, velocity: Twist2D, path: Any, costmap: Any,
                                  dt: float | None = None) -> Twist2D:
        if not self.plans:
            raise InvalidPath("received plan with zero length")
        self.calls += 1
        return self.cmd


def shim(freq: float = 20.0, primary: Any = None, **params: Any) -> RotationShimController:
    cfg = RotationShimConfig(primary_controller=RPP, **params)
    return RotationShimController(cfg, primary if primary is not None else Recorder(), "PathFollower",
                                  freq)


def path_of(*xy_yaw: tuple[float, ...], n: int = 0) -> np.ndarray:
    """Poses relative to ``O`` (``(x, y)`` or ``(x, y, yaw)``), padded with zero poses to ``n``
    as upstream's ``path.poses.resize(n)``."""
    rows = [(*p, 0.0)[:3] if len(p) == 2 else p for p in xy_yaw]
    rows += [(0.0, 0.0, 0.0)] * max(0, n - len(rows))
    return np.asarray(rows, dtype=float) + O


def at(x: float, y: float, yaw: float = 0.0) -> np.ndarray:
    """The robot's pose ``(x, y, yaw)`` relative to ``O``."""
    return O + np.array([x, y, yaw])


@pytest.fixture
def costmap() -> Any:
    return make_costmap(np.zeros((120, 120), dtype=np.int8))


def test_defaults_are_jazzys() -> None:
    cfg = RotationShimConfig(primary_controller=MPPI)
    assert (cfg.angular_dist_threshold, cfg.angular_disengage_threshold,
            cfg.forward_sampling_distance, cfg.rotate_to_heading_angular_vel,
            cfg.max_angular_accel, cfg.max_cost_threshold, cfg.simulate_ahead_time) == (
        0.785, 0.3925, 0.5, 1.8, 3.2, 254.0, 1.0)
    assert (cfg.rotate_to_goal_heading, cfg.rotate_to_heading_once, cfg.closed_loop,
            cfg.use_path_orientations) == (False, False, True, False)


# --- lifecycleTransitions / testDynamicParameter ----------------------------------------------
def _build(block: dict[str, Any]) -> Any:
    return build_controller_server({"controller_plugins": ["PathFollower"],
                                    "PathFollower": block}).controllers["PathFollower"]


@pytest.mark.parametrize(("primary", "match"), [
    (None, "PathFollower.primary_controller"),                  # upstream: configure throws
    ("", "PathFollower.primary_controller"),
    ("HI", "PathFollower.primary_controller.*unknown controllers plugin"),
    (SHIM, "cannot be its own primary"),
])
def test_a_bad_primary_is_refused_naming_the_key(primary: Any, match: str) -> None:
    block: dict[str, Any] = {"plugin": SHIM}
    if primary is not None:
        block["primary_controller"] = primary
    with pytest.raises(UnsupportedPlugin, match=match) as err:
        _build(block)
    assert err.value.key == "PathFollower.primary_controller"


def test_primary_configured_from_the_same_block_and_speed_limit_passed_through() -> None:
    ctrl = _build({"plugin": SHIM, "primary_controller": RPP, "desired_linear_vel": 0.3,
                   "angular_dist_threshold": 0.5})
    assert isinstance(ctrl, RotationShimController)
    assert isinstance(ctrl.primary, RegulatedPurePursuitController)
    assert ctrl.primary.config.desired_linear_vel == 0.3
    assert ctrl.config.angular_dist_threshold == 0.5
    ctrl.set_speed_limit(50.0, True)  # upstream: setSpeedLimit(50.0, true)
    assert ctrl.primary._desired_linear_vel == pytest.approx(0.15)


def test_every_parameter_is_read() -> None:
    # testDynamicParameter's values, given at configure time
    ctrl = _build({"plugin": SHIM, "primary_controller": RPP,
                   "angular_dist_threshold": 7.0, "forward_sampling_distance": 7.0,
                   "rotate_to_heading_angular_vel": 7.0, "max_angular_accel": 7.0,
                   "simulate_ahead_time": 7.0,
                   "max_cost_threshold": float(INSCRIBED_INFLATED_OBSTACLE),
                   "rotate_to_goal_heading": True, "rotate_to_heading_once": True,
                   "closed_loop": False, "use_path_orientations": True,
                   "angular_disengage_threshold": 0.1})
    c = ctrl.config
    assert (c.angular_dist_threshold, c.forward_sampling_distance,
            c.rotate_to_heading_angular_vel, c.max_angular_accel, c.simulate_ahead_time,
            c.max_cost_threshold, c.angular_disengage_threshold) == (
        7.0, 7.0, 7.0, 7.0, 7.0, 253.0, 0.1)
    assert (c.rotate_to_goal_heading, c.rotate_to_heading_once, c.closed_loop,
            c.use_path_orientations) == (True, True, False, True)


@pytest.mark.parametrize(("key", "value"), [
    ("max_angular_accel", 0.0), ("rotate_to_heading_angular_vel", -1.0),
    ("forward_sampling_distance", -0.5), ("angular_dist_threshold", float("nan")),
    ("closed_loop", "sometimes"),
])
def test_bad_values_are_refused_naming_the_key(key: str, value: Any) -> None:
    with pytest.raises(ParameterError, match=rf"PathFollower.*{key}"):
        _build({"plugin": SHIM, "primary_controller": RPP, key: value})


def test_primary_errors_name_the_shims_block() -> None:
    with pytest.raises(ParameterError, match=r"PathFollower.*batch_size"):
        _build({"plugin": SHIM, "primary_controller": MPPI, "batch_size": -5})


def test_registered_under_nav2s_name() -> None:
    assert SHIM in CONTROLLER_PLUGINS
    assert "nav2_rotation_shim_controller/RotationShimController" in CONTROLLER_PLUGINS


# --- setPlanAndSampledPointsTests ---------------------------------------------------------
def test_set_plan_and_sampled_points() -> None:
    ctrl = shim()
    path = path_of((0, 0), (0.1, 0.1), (1.0, 1.0), (10.0, 10.0), n=10)
    assert ctrl.path_updated is False
    ctrl.set_plan(path)
    assert ctrl.path.shape == (10, 3)
    assert ctrl.path_updated is True
    np.testing.assert_array_equal(ctrl.primary.plans[-1], path)  # passed through
    # default forward sampling 0.5: (0.1, 0.1) is too close, (1, 1) is the first far enough
    np.testing.assert_allclose(ctrl.sampled_path_point()[:2], O[:2] + 1.0)
    ctrl.path = np.zeros((0, 3))  # upstream sets an empty plan; our primaries refuse one
    with pytest.raises(ControllerError, match="too short"):
        ctrl.sampled_path_point()
    ctrl.path = path[:1]
    with pytest.raises(ControllerError, match="too short"):
        ctrl.sampled_path_point()


def test_sampled_point_falls_back_to_the_goal() -> None:
    ctrl = shim()
    ctrl.set_plan(path_of((0, 0), (0.1, 0.0), (0.2, 0.3)))
    np.testing.assert_allclose(ctrl.sampled_path_point()[:2], O[:2] + np.array([0.2, 0.3]))


# --- rotationAndTransformTests: controller_frequency 1 -------------------------------------
@pytest.mark.parametrize(("distance", "expected"), [(0.7, 1.8), (-0.7, -1.8), (0.87, 1.8)])
def test_rotate_command(costmap: Any, distance: float, expected: float) -> None:
    ctrl = shim(freq=1.0)
    path = path_of((0, 0), (0.15, 0.15), (1.0, 1.0), (10.0, 10.0), n=10)
    ctrl.set_plan(path)
    cmd = ctrl.rotate_command(distance, path[1], Twist2D(), costmap)
    assert (cmd.vx, cmd.vy, cmd.wz) == (0.0, 0.0, expected)


def test_heading_error_in_the_robots_frame() -> None:
    ctrl = shim()
    ctrl.set_plan(path_of((0, 0), (0.0, 1.0)))
    assert ctrl.heading_error(O) == pytest.approx(math.pi / 2)
    assert ctrl.heading_error(at(0.0, 0.0, math.pi / 2)) == pytest.approx(0.0)
    assert ctrl.heading_error(at(0.0, 0.0, math.pi)) == pytest.approx(-math.pi / 2)
    with_orientations = shim(use_path_orientations=True)
    with_orientations.set_plan(path_of((0, 0, 0.0), (0.0, 1.0, -0.4)))
    assert with_orientations.heading_error(at(0.0, 0.0, 0.3)) == pytest.approx(-0.7)


# --- computeVelocityTests: controller_frequency 1 ------------------------------------------
def test_compute_velocity(costmap: Any) -> None:
    ctrl = shim(freq=1.0)
    pose, vel = O.copy(), Twist2D()
    # no path: straight to the primary, which has no plan
    with pytest.raises(InvalidPath):
        ctrl.compute_velocity_commands(pose, vel, None, costmap)
    # the sampled point (-1, -1) is behind: rotate in place
    ctrl.set_plan(path_of((0, 0), (0.1, 0.1), (-1.0, -1.0), (10.0, 10.0), n=10))
    cmd = ctrl.compute_velocity_commands(pose, vel, None, costmap)
    assert abs(cmd.wz) == 1.8 and cmd.vx == 0.0
    assert ctrl.in_rotation and ctrl.primary.calls == 0
    # the sampled point (1, 0) is ahead: the primary drives
    ctrl.set_plan(path_of((0, 0), (0.1, 0.1), (1.0, 0.0), (10.0, 10.0), n=10))
    cmd = ctrl.compute_velocity_commands(pose, vel, None, costmap)
    assert cmd == ctrl.primary.cmd and ctrl.primary.calls == 1
    assert not ctrl.path_updated and not ctrl.in_rotation


# --- openLoopRotationTests / computeVelocityGoalRotationTests / accelerationTests -------------
GOAL_PATH = ((0.0, 0.0), (0.05, 0.05), (0.10, 0.10))
#: quaternion z -0.3826834, w 0.9238795: yaw -pi/4
RIGHT, LEFT = -math.pi / 4, math.pi / 4


def _goal_heading(freq: float, **params: Any) -> RotationShimController:
    ctrl = shim(freq=freq, rotate_to_goal_heading=True, **params)
    ctrl.set_goal_tolerance(1.0)  # checker.xy_goal_tolerance 1.0: the goal is within it
    return ctrl


def test_open_loop_rotation(costmap: Any) -> None:
    ctrl = _goal_heading(20.0, closed_loop=False)
    ctrl.set_plan(path_of(*GOAL_PATH, (0.2, 0.2, RIGHT)))
    cmd = ctrl.compute_velocity_commands(O, Twist2D(), None, costmap)
    assert cmd.wz == pytest.approx(-0.16, abs=1e-4)
    # odometry saying 1.8 rad/s is not used open loop: the last command is
    cmd = ctrl.compute_velocity_commands(O, Twist2D(0.0, 0.0, 1.8), None, costmap)
    assert cmd.wz == pytest.approx(-0.32, abs=1e-4)


@pytest.mark.parametrize(("goal_yaw", "expected"), [(RIGHT, -1.8), (LEFT, 1.8)])
def test_goal_rotation(costmap: Any, goal_yaw: float, expected: float) -> None:
    # upstream's case leaves controller_frequency undeclared (an unbounded acceleration
    # window); at 1 Hz the 3.2 rad/s^2 window holds 1.8 rad/s as well
    ctrl = _goal_heading(1.0)
    ctrl.set_plan(path_of(*GOAL_PATH, (0.2, 0.2, goal_yaw)))
    cmd = ctrl.compute_velocity_commands(O, Twist2D(), None, costmap)
    assert cmd.wz == expected and cmd.vx == 0.0
    assert ctrl.primary.calls == 0


def test_acceleration_and_stopping_limits(costmap: Any) -> None:
    ctrl = _goal_heading(20.0, max_angular_accel=0.5)
    ctrl.set_plan(path_of(*GOAL_PATH, (0.2, 0.2, RIGHT)))
    assert ctrl.compute_velocity_commands(O, Twist2D(), None, costmap).wz == -0.025
    # at -1.8 rad/s, pi/4 from the heading: slow to what can stop there
    cmd = ctrl.compute_velocity_commands(O, Twist2D(0.0, 0.0, -1.8), None, costmap)
    assert cmd.wz == pytest.approx(-math.sqrt(2 * 0.5 * math.pi / 4), abs=1e-4)


def test_goal_rotation_waits_for_the_goal_tolerance(costmap: Any) -> None:
    ctrl = shim(rotate_to_goal_heading=True)
    ctrl.set_goal_tolerance(0.25)
    ctrl.set_plan(path_of((0.0, 0.0), (0.3, 0.0), (0.6, 0.0, LEFT)))
    ctrl.compute_velocity_commands(O, Twist2D(), None, costmap)
    assert ctrl.primary.calls == 1  # 0.6 m out: the primary drives
    cmd = ctrl.compute_velocity_commands(at(0.45, 0.0), Twist2D(), None, costmap)
    assert cmd.vx == 0.0 and cmd.wz > 0.0 and ctrl.primary.calls == 1
    assert ctrl.primary.tolerances == [0.25]


# --- isGoalChangedTest ----------------------------------------------------------------------
def test_is_goal_changed() -> None:
    ctrl = shim(rotate_to_heading_once=True)
    path = path_of((0.0, 0.0), (2.0, 2.0))
    assert ctrl.is_goal_changed(path) is True  # no current path
    ctrl.set_plan(path)
    assert ctrl.is_goal_changed(path) is False
    moved = path.copy()
    moved[-1, 0] = O[0] + 3.0
    assert ctrl.is_goal_changed(moved) is True


def test_rotate_to_heading_once_skips_replans_of_the_same_goal(costmap: Any) -> None:
    once = shim(rotate_to_heading_once=True)
    every = shim()
    first = path_of((0.0, 0.0), (1.0, 0.0), (2.0, 0.0))
    for ctrl in (once, every):
        ctrl.set_plan(first)
        ctrl.compute_velocity_commands(O, Twist2D(), None, costmap)  # aligned: handed over
        # a replan of the same goal that starts off behind the robot
        ctrl.set_plan(path_of((0.0, 0.0), (-1.0, 0.5), (2.0, 0.0)))
    assert once.path_updated is False and every.path_updated is True
    assert once.compute_velocity_commands(O, Twist2D(), None, costmap) == once.primary.cmd
    assert every.compute_velocity_commands(O, Twist2D(), None, costmap).vx == 0.0


# --- maxCostThresholdTest and the collision check ------------------------------------------
def test_max_cost_threshold(costmap: Any) -> None:
    ctrl = shim(max_cost_threshold=float(FREE_SPACE))
    path = path_of((0, 0), (0.15, 0.15), (1.0, 1.0), n=4)
    ctrl.set_plan(path)
    # with a threshold of 0 even free space is a collision
    with pytest.raises(NoValidControl):
        ctrl.rotate_command(1.5, path[1], Twist2D(), costmap)
    assert shim().rotate_command(1.5, path[1], Twist2D(), costmap).wz == pytest.approx(0.16)


def _boxed_in() -> Any:
    """A long thin robot (0.9 × 0.3 m) along x with a wall 0.05 m from its side: turning
    either way swings a corner into the wall (0.16 rad, one second at the first command's
    accel-limited 0.16 rad/s, is enough)."""
    occ = np.zeros((120, 120), dtype=np.int8)
    occ[64:68, :] = 100  # wall at y = 3.20 .. 3.40
    cm = make_costmap(occ, inflation_radius=0.1)
    cm.set_footprint(np.array([[0.45, 0.15], [0.45, -0.15], [-0.45, -0.15], [-0.45, 0.15]]))
    return cm


def test_a_rotation_that_would_hit_hands_over_to_the_primary() -> None:
    cm = _boxed_in()
    pose = O.copy()  # footprint y 2.85 .. 3.15, wall from 3.20
    assert cm.master.footprint_cost(
        np.array([[3.45, 3.15], [3.45, 2.85], [2.55, 2.85], [2.55, 3.15]])) < LETHAL_OBSTACLE
    ctrl = shim()
    ctrl.set_plan(path_of((0.0, 0.0), (0.0, -1.0), (0.0, -2.0)))  # to the right: -pi/2
    with pytest.raises(NoValidControl, match="collision ahead"):
        ctrl.rotate_command(ctrl.heading_error(pose), pose, Twist2D(), cm)
    cmd = ctrl.compute_velocity_commands(pose, Twist2D(), None, cm)
    assert cmd == ctrl.primary.cmd and ctrl.path_updated is False
    # the same turn in open space is a rotation
    free = shim()
    free.set_plan(path_of((0.0, 0.0), (0.0, -1.0), (0.0, -2.0)))
    free_cm = make_costmap(np.zeros((120, 120), dtype=np.int8))
    free_cm.set_footprint(cm.footprint)
    assert free.compute_velocity_commands(pose, Twist2D(), None, free_cm).wz < 0.0


def test_unknown_space_blocks_a_rotation_only_when_tracked() -> None:
    occ = np.zeros((120, 120), dtype=np.int8)
    occ[64:68, :] = -1
    tracked = make_costmap(occ, inflation_radius=0.1, track_unknown_space=True)
    untracked = make_costmap(occ, inflation_radius=0.1)
    for cm in (tracked, untracked):
        cm.set_footprint(np.array([[0.45, 0.15], [0.45, -0.15], [-0.45, -0.15], [-0.45, 0.15]]))
    ctrl = shim()
    ctrl.set_plan(path_of((0.0, 0.0), (0.0, 1.0), (0.0, 2.0)))
    with pytest.raises(NoValidControl, match="potential collision"):
        ctrl.rotate_command(math.pi / 2, O, Twist2D(), tracked)
    assert ctrl.rotate_command(math.pi / 2, O, Twist2D(), untracked).wz > 0.0


# --- engage / disengage, pass-through -------------------------------------------------------
@pytest.mark.parametrize(("rotating", "expected_rotation"), [(False, False), (True, True)])
def test_disengage_threshold_while_rotating(costmap: Any, rotating: bool,
                                            expected_rotation: bool) -> None:
    ctrl = shim()
    ctrl.set_plan(path_of((0.0, 0.0), (math.cos(0.5), math.sin(0.5))))  # 0.5 rad off
    ctrl.in_rotation = rotating
    cmd = ctrl.compute_velocity_commands(O, Twist2D(), None, costmap)
    assert (cmd.vx == 0.0 and cmd.wz > 0.0) == expected_rotation
    assert ctrl.in_rotation == expected_rotation


def test_reset_and_tolerance_pass_through() -> None:
    ctrl = shim(closed_loop=False)
    ctrl.last_angular_vel = 1.0
    ctrl.reset()
    assert ctrl.primary.resets == 1 and ctrl.last_angular_vel is None
    ctrl.set_goal_tolerance(0.3)
    assert ctrl.primary.tolerances == [0.3] and ctrl.xy_goal_tolerance == 0.3


# --- the shim in front of MPPI and RPP: a kinematic run ---------------------------------------
def _jazzy_mppi() -> dict[str, Any]:
    """The FollowPath (MPPI) section of Nav2 Jazzy's sample parameters file, without plugin."""
    doc = yaml.safe_load((Path(__file__).resolve().parents[1] / "data" / "nav2"
                          / "nav2_params_jazzy.yaml").read_text())
    fp = dict(doc["controller_server"]["ros__parameters"]["FollowPath"])
    fp.pop("plugin")
    return fp


def _drive(ctrl: Any, path: np.ndarray, costmap: Any, start: np.ndarray,
           steps: int = 400) -> tuple[np.ndarray, bool, np.ndarray]:
    checker = SimpleGoalChecker(SimpleGoalCheckerConfig(xy_goal_tolerance=0.25,
                                                        yaw_goal_tolerance=6.3))
    pose, vel, log = start.astype(float).copy(), Twist2D(), []
    ctrl.set_plan(path)
    for _ in range(steps):
        if checker.is_goal_reached(pose, path[-1], vel):
            return pose, True, np.array(log)
        cmd = ctrl.compute_velocity_commands(pose, vel, None, costmap, 0.05)
        th = pose[2] + 0.5 * cmd.wz * 0.05
        pose[0] += cmd.vx * math.cos(th) * 0.05
        pose[1] += cmd.vx * math.sin(th) * 0.05
        pose[2] = (pose[2] + cmd.wz * 0.05 + math.pi) % (2 * math.pi) - math.pi
        vel = cmd
        log.append([pose[0], pose[1], pose[2], cmd.vx, cmd.wz])
    return pose, False, np.array(log)


@pytest.mark.parametrize("primary", [RPP, MPPI])
def test_turns_in_place_then_the_primary_drives(costmap: Any, primary: str) -> None:
    extra = ({**_jazzy_mppi(), "batch_size": 500, "vx_max": 0.4, "visualize": False}
             if primary == MPPI else {"use_rotate_to_heading": False})
    ctrl = RotationShimController.from_params(
        {"primary_controller": primary, **extra}, "FollowPath",
        PluginContext("controller_server", "FollowPath",
                      build_controller_server({}).config))
    if primary == MPPI:
        assert isinstance(ctrl.primary, MPPIController)
        ctrl.primary.optimizer.rng = np.random.default_rng(0)
    xs = np.linspace(3.0, 5.0, 41)
    path = np.stack([xs, np.full_like(xs, 3.0), np.zeros_like(xs)], axis=1)
    start = np.array([3.0, 3.0, math.pi])  # facing away from the path
    pose, reached, log = _drive(ctrl, path, costmap, start)
    assert reached, pose
    # the turn is in place: no forward speed until the heading is within the 0.785 threshold
    first_move = int(np.argmax(np.abs(log[:, 3]) > 1e-6))
    assert first_move > 0
    assert np.all(log[:first_move, 3] == 0.0)
    assert abs(log[first_move - 1, 2]) <= 0.785 + 0.1
    # the travelled position stayed on the spot while turning
    assert np.hypot(log[first_move - 1, 0] - 3.0, log[first_move - 1, 1] - 3.0) < 1e-9


# --- the parameters file audit --------------------------------------------------------------
def test_audit_keeps_the_shims_and_the_primarys_keys_and_names_the_rest() -> None:
    doc = {"controller_server": {"ros__parameters": {
        "controller_plugins": ["FollowPath"],
        "FollowPath": {"plugin": SHIM, "primary_controller": MPPI,
                       "angular_dist_threshold": 0.6, "time_steps": 40,
                       "critics": ["GoalCritic"], "GoalCritic": {"cost_weight": 5.0},
                       "foo": 1},
    }}}
    audit = audit_nav2_params(doc)
    assert audit.warnings == ("ignored: controller_server.FollowPath.foo",)
    fp = audit.supported["controller_server"]["ros__parameters"]["FollowPath"]
    assert fp == {"plugin": SHIM, "primary_controller": MPPI, "angular_dist_threshold": 0.6,
                  "time_steps": 40, "critics": ["GoalCritic"],
                  "GoalCritic": {"cost_weight": 5.0}}
    # an RPP primary: RPP's keys are known, MPPI's are not
    doc["controller_server"]["ros__parameters"]["FollowPath"] = {
        "plugin": SHIM, "primary_controller": RPP, "desired_linear_vel": 0.3, "time_steps": 40}
    assert audit_nav2_params(doc).warnings == ("ignored: controller_server.FollowPath.time_steps",)


@pytest.mark.parametrize("primary", [None, "nav2_graceful_controller::GracefulController"])
def test_audit_refuses_a_bad_primary(primary: Any) -> None:
    block: dict[str, Any] = {"plugin": SHIM}
    if primary:
        block["primary_controller"] = primary
    doc = {"controller_server": {"ros__parameters": {"controller_plugins": ["FollowPath"],
                                                     "FollowPath": block}}}
    with pytest.raises(UnsupportedPlugin) as err:
        audit_nav2_params(doc)
    assert err.value.key == "FollowPath.primary_controller"
