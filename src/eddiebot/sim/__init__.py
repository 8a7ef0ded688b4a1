"""The simulator's pure cores: world model and files, differential-drive physics,
Kinect RGB-D rendering, IR/PING range models and ground-truth maps.

What a simulator node calls::

    world = load_world("office")                       # or a path to a world YAML file
    geom = collision_geometry(world)
    state = RobotState(*world.start)
    state = step(state, (w_left, w_right), dt, geom, DriveParams(), rng, people=...)
    renderer = Renderer(world, KinectConfig())
    frame = renderer.frame(state.pose, frame_index)    # rgb8 + 16UC1 mm
    ranges = range_readings(world, state.pose)         # metres, keyed "ir/left", ...
    maps = cached_ground_truth(world)                  # .scan / .footprint OccupancyMaps

Nothing here reads a clock, a topic or (except `load_world*` and `cached_ground_truth`)
a file.
"""

from eddiebot.sim.camera import (
    DEPTH_OPTICAL_FRAME,
    KINECT_DEPTH,
    KINECT_RGB,
    RGB_OPTICAL_FRAME,
    CameraIntrinsics,
    KinectConfig,
    camera_info_msg,
    depth_image_msg,
    ground_truth_odometry_msg,
    rgb_image_msg,
)
from eddiebot.sim.errors import SimError, UnknownWorldError, WorldFileError
from eddiebot.sim.ground_truth import (
    GroundTruthMaps,
    cached_ground_truth,
    footprint_map,
    ground_truth_maps,
    scan_slice_map,
)
from eddiebot.sim.physics import (
    CollisionGeometry,
    DriveParams,
    PeopleState,
    RobotState,
    collision_geometry,
    init_people,
    people_positions,
    step,
    step_people,
    twist_to_wheel_speeds,
    wheel_speeds_to_twist,
)
from eddiebot.sim.ranges import (
    IR_MODEL,
    PING_MODEL,
    RANGE_MOUNTS,
    RangeModel,
    RangeMount,
    range_reading,
    range_readings,
)
from eddiebot.sim.render import KinectFrame, Renderer, camera_pose, kinect_depth, render_view
from eddiebot.sim.world import (
    ROBOT_HEIGHT,
    ROBOT_RADIUS,
    Person,
    Prism,
    World,
    load_world_file,
    parse_world,
    world_from_nav2_map,
)
from eddiebot.sim.worlds import list_worlds, load_world, world_path

__all__ = [
    "DEPTH_OPTICAL_FRAME",
    "IR_MODEL",
    "KINECT_DEPTH",
    "KINECT_RGB",
    "PING_MODEL",
    "RANGE_MOUNTS",
    "RGB_OPTICAL_FRAME",
    "ROBOT_HEIGHT",
    "ROBOT_RADIUS",
    "CameraIntrinsics",
    "CollisionGeometry",
    "DriveParams",
    "GroundTruthMaps",
    "KinectConfig",
    "KinectFrame",
    "PeopleState",
    "Person",
    "Prism",
    "RangeModel",
    "RangeMount",
    "Renderer",
    "RobotState",
    "SimError",
    "UnknownWorldError",
    "World",
    "WorldFileError",
    "cached_ground_truth",
    "camera_info_msg",
    "camera_pose",
    "collision_geometry",
    "depth_image_msg",
    "footprint_map",
    "ground_truth_maps",
    "ground_truth_odometry_msg",
    "init_people",
    "kinect_depth",
    "list_worlds",
    "load_world",
    "load_world_file",
    "parse_world",
    "people_positions",
    "range_reading",
    "range_readings",
    "render_view",
    "rgb_image_msg",
    "scan_slice_map",
    "step",
    "step_people",
    "twist_to_wheel_speeds",
    "wheel_speeds_to_twist",
    "world_from_nav2_map",
    "world_path",
]
