"""The simulator node (Gazebo's role): the firmware emulator's plant in a world.

The node owns a ``FirmwareEmulator`` and puts it in the context (``resources["emulator"]``)
so the real board node talks to it through the in-process serial link — the same driver,
protocol and odometry as on the robot. Each physics tick (``physics_rate``) it advances the
emulator to the sim time, turns the wheels' position change into ground motion with slip
and collisions, and moves the scripted people. IR and PING readings are computed from the
true pose when the driver asks the board for ADC or PING, so they travel through the
firmware's commands like on the robot.

Publishes the Kinect streams (``/image_raw``, ``/camera_info``, ``/depth/image_raw``,
``/depth/camera_info``; one stamp per frame), ``/ground_truth/odom``, ``/sim/collisions``
(std_msgs/UInt32) and, through ``ClockPublisher``, ``/clock``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from eddiebot.core.node import Node
from eddiebot.core.qos import qos_profile_sensor_data
from eddiebot.msgs.nav_msgs import Odometry
from eddiebot.msgs.sensor_msgs import CameraInfo, Image
from eddiebot.msgs.std_msgs import UInt32
from eddiebot.robot.constants import (
    BATTERY_ADC_INDEX,
    BATTERY_DIVIDER,
    IR_SENSORS,
    PING_SENSORS,
    POSITIONS_PER_REV,
    profile_for_name,
    sharp_distance_to_voltage,
)
from eddiebot.robot.emulator import FirmwareEmulator
from eddiebot.sim.camera import (
    DEPTH_OPTICAL_FRAME,
    RGB_OPTICAL_FRAME,
    KinectConfig,
    camera_info_msg,
    depth_image_msg,
    ground_truth_odometry_msg,
    rgb_image_msg,
)
from eddiebot.sim.physics import (
    DriveParams,
    RobotState,
    collision_geometry,
    init_people,
    people_positions,
    step,
    step_people,
)
from eddiebot.sim.ranges import mounts_from_table, range_reading
from eddiebot.sim.render import Renderer
from eddiebot.sim.world import World
from eddiebot.sim.worlds import load_world

__all__ = ["SimSensors", "SimulatorNode"]

_RAD_PER_POSITION = 2.0 * math.pi / POSITIONS_PER_REV


class SimSensors:
    """The emulator's sensor source: IR and PING from the simulated world."""

    def __init__(self, sim: SimulatorNode) -> None:
        self.sim = sim
        self.mounts = mounts_from_table((*IR_SENSORS, *PING_SENSORS))
        self.ping_by_pin = {s.index: s.name for s in PING_SENSORS}
        self.ir_by_channel = {s.index: s.name for s in IR_SENSORS}
        self.battery_v = 12.6

    def _reading(self, name: str) -> float:
        return range_reading(self.sim.world, self.sim.state.pose, self.mounts[name],
                             self.sim.people_now(), self.sim.rng)

    def ping_range_m(self, pin: int, time_s: float) -> float:
        name = self.ping_by_pin.get(pin)
        return self._reading(name) if name is not None else math.inf

    def adc_volts(self, channel: int, time_s: float) -> float:
        if channel == BATTERY_ADC_INDEX:
            return self.battery_v / BATTERY_DIVIDER
        name = self.ir_by_channel.get(channel)
        if name is None:
            return 0.0
        return sharp_distance_to_voltage(self._reading(name))


class SimulatorNode(Node):
    default_node_name = "simulator"

    def __init__(self, node_name: str = default_node_name, *, world: World | None = None,
                 **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        world_name = str(self.declare_parameter("world", "office").value)
        self.seed = int(self.declare_parameter("seed", 0).value)
        self.physics_rate = float(self.declare_parameter("physics_rate", 100.0).value)
        camera_rate = float(self.declare_parameter("camera_rate", 30.0).value)
        width = int(self.declare_parameter("camera_width", 640).value)
        height = int(self.declare_parameter("camera_height", 480).value)
        self.publish_rgb = bool(self.declare_parameter("publish_rgb", True).value)
        ground_truth_rate = float(self.declare_parameter("ground_truth_rate", 50.0).value)
        firmware = str(self.declare_parameter("firmware", "1.1").value)
        self.params = DriveParams(
            slip_std=float(self.declare_parameter("slip_std", 0.01).value),
            slip_bias_left=float(self.declare_parameter("slip_bias_left", 0.0).value),
            slip_bias_right=float(self.declare_parameter("slip_bias_right", 0.0).value),
        )
        start = self.declare_parameter("start", []).value
        self.world = world if world is not None else load_world(world_name)
        x0, y0, th0 = (tuple(float(v) for v in start) if start else self.world.start)
        self.state = RobotState(x=x0, y=y0, theta=th0, time=self.get_clock().now_ns() * 1e-9)
        self.rng = np.random.default_rng(self.seed)
        self.geometry = collision_geometry(self.world)
        self.people = init_people(self.world)
        self.emulator = FirmwareEmulator(profile_for_name(firmware), sensors=SimSensors(self),
                                         start_ns=self.get_clock().now_ns())
        self.context.resources["emulator"] = self.emulator
        self.context.resources["simulator"] = self
        self._last_wheels = self.emulator.plant.wheel_positions
        self._last_ns = self.get_clock().now_ns()
        self.collisions = 0
        config = KinectConfig(seed=self.seed, noise_correlation_px=float(self.declare_parameter(
            "noise_correlation_px", KinectConfig.noise_correlation_px).value))
        if (width, height) != (config.depth.width, config.depth.height):
            config = config.at_resolution(width, height)
        self.kinect = config
        self.renderer = Renderer(self.world, config)
        self.frame_index = 0
        self.rgb_pub = self.create_publisher(Image, "/image_raw", qos_profile_sensor_data)
        self.rgb_info_pub = self.create_publisher(CameraInfo, "/camera_info", qos_profile_sensor_data)
        self.depth_pub = self.create_publisher(Image, "/depth/image_raw", qos_profile_sensor_data)
        self.depth_info_pub = self.create_publisher(CameraInfo, "/depth/camera_info",
                                                    qos_profile_sensor_data)
        self.truth_pub = self.create_publisher(Odometry, "/ground_truth/odom", 10)
        self.collision_pub = self.create_publisher(UInt32, "/sim/collisions", 10)
        self.create_timer(1.0 / self.physics_rate, self._physics)
        if camera_rate > 0:
            self.create_timer(1.0 / camera_rate, self._camera)
        if ground_truth_rate > 0:
            self.create_timer(1.0 / ground_truth_rate, self._ground_truth)
        self.get_logger().info(
            f"world {self.world.name!r}, start ({x0:.2f}, {y0:.2f}, {th0:.2f}), seed {self.seed}, "
            f"Kinect {width}x{height} at {camera_rate:g} Hz"
        )

    def people_now(self) -> Any:
        return people_positions(self.world, self.people) if self.world.people else None

    # -- physics ---------------------------------------------------------------------------
    def _physics(self) -> None:
        now = self.get_clock().now_ns()
        dt = (now - self._last_ns) * 1e-9
        if dt <= 0:
            return
        self._last_ns = now
        self.emulator.advance_to_ns(now)
        wheels = self.emulator.plant.wheel_positions
        speeds = ((wheels[0] - self._last_wheels[0]) * _RAD_PER_POSITION / dt,
                  (wheels[1] - self._last_wheels[1]) * _RAD_PER_POSITION / dt)
        self._last_wheels = wheels
        people = self.people_now()
        self.state = step(self.state, speeds, dt, self.geometry, self.params, self.rng, people=people)
        if self.world.people:
            self.people = step_people(self.world, self.people, self.state, dt)
        if self.state.collisions != self.collisions:
            self.collisions = self.state.collisions
            self.get_logger().warning(f"collision #{self.collisions} at ({self.state.x:.2f}, {self.state.y:.2f})")
            self.collision_pub.publish(UInt32(data=self.collisions))

    # -- sensors ---------------------------------------------------------------------------
    def _camera(self) -> None:
        stamp = self.get_clock().now_ns()
        pose = self.state.pose
        people = self.people_now()
        depth = self.renderer.depth(pose, self.frame_index, people)
        self.frame_index += 1
        # camera_info first, so a consumer holding the latest info can use each image at once
        self.depth_info_pub.publish(camera_info_msg(self.kinect.depth, stamp, DEPTH_OPTICAL_FRAME))
        if self.publish_rgb:
            self.rgb_info_pub.publish(camera_info_msg(self.kinect.rgb, stamp, RGB_OPTICAL_FRAME))
            rgb = self.renderer.rgb(pose, people)
            self.rgb_pub.publish(rgb_image_msg(rgb, stamp, RGB_OPTICAL_FRAME))
        self.depth_pub.publish(depth_image_msg(depth, stamp, DEPTH_OPTICAL_FRAME))

    def _ground_truth(self) -> None:
        st = self.state
        self.truth_pub.publish(
            ground_truth_odometry_msg(st.x, st.y, st.theta, st.v, st.w, self.get_clock().now_ns(), "world")
        )

    def destroy_node(self) -> None:
        if self.context.resources.get("simulator") is self:
            del self.context.resources["simulator"]
        super().destroy_node()
