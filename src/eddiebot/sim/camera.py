"""The simulated Kinect v1: its depth noise configuration, on the real sensor's model
(:mod:`eddiebot.robot.kinect_model`: frames, intrinsics, message builders, re-exported here).
The simulator renders an ideal pinhole with the factory fx, fy, cx, cy, so the CameraInfo it
publishes carries zero distortion.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from eddiebot.msgs.std_msgs import Header
from eddiebot.robot.kinect_model import (
    DEPTH_OPTICAL_FRAME,
    KINECT_DEPTH,
    KINECT_RGB,
    RGB_OPTICAL_FRAME,
    CameraIntrinsics,
    camera_info_msg,
    depth_image_msg,
    rgb_image_msg,
    stamp_from_ns,
)

__all__ = [
    "DEPTH_OPTICAL_FRAME",
    "KINECT_DEPTH",
    "KINECT_RGB",
    "RGB_OPTICAL_FRAME",
    "CameraIntrinsics",
    "KinectConfig",
    "camera_info_msg",
    "depth_image_msg",
    "ground_truth_odometry_msg",
    "rgb_image_msg",
    "stamp_from_ns",
]


@dataclass(frozen=True)
class KinectConfig:
    """Simulated Kinect v1. Distances in metres, poses relative to ``base_footprint``.

    Depth behaviour: the Kinect measures disparity in 1/8-pixel steps, so depth comes in
    steps of ``disparity_step_coeff · z²`` (≈ 2.85 mm at 1 m, 11 mm at 2 m, 46 mm at 4 m).
    Noise is added in disparity (``noise_disparity_sigma`` steps, so the range noise grows
    with z²) before quantisation; pixels at a depth edge (a 4-neighbour differs by more than
    ``edge_threshold`` of the depth) get ``edge_noise_factor`` times the noise and are dropped
    with probability ``edge_dropout``; every pixel is dropped with probability ``dropout``.
    No return (0) closer than ``min_range`` or beyond ``max_range``. Noise is seeded:
    the same ``seed`` and frame index give the same image.

    ``noise_correlation_px`` makes the disparity noise spatially correlated, as the real
    sensor's is: the PS1080 finds each pixel's disparity by correlating a window of the IR
    speckle image (9×9 or 9×7 pixels, Konolige & Mihelich, ROS wiki
    ``kinect_calibration/technical``) with the stored reference pattern, so neighbouring
    pixels share most of their window and their errors; the depth image is accordingly
    shifted by about half a window against the IR image (≈ 3 px ibid., −4.8 / −3.9 px in
    Smisek et al. 2011, "3D with Kinect"), and its true lateral resolution is coarser than
    640×480 (Khoshelham & Elberink 2012; Nguyen et al. 2012, "Modeling Kinect sensor
    noise", measure a lateral edge noise of ≈ 0.8 px, i.e. edges blurred over about a
    pixel, beside the axial σ that grows with z²). The value is the side of a square box
    window in pixels of the native 640×480 image (9 models the 9×9 window); it scales with
    the rendered width (4.5 px at 320×240). The noise is white noise summed over that
    window and renormalised, so every pixel's σ stays ``noise_disparity_sigma`` while two
    pixels d apart along a row or column correlate by 1 − d/window (the overlap of their
    windows: a triangle, zero beyond the window; a fractional window in rendered pixels is
    a mix of the two nearest whole boxes with that slope, `eddiebot.sim.render.noise_boxes`).
    0 (or anything up to one rendered pixel) keeps independent per-pixel noise.
    """

    rgb: CameraIntrinsics = KINECT_RGB
    depth: CameraIntrinsics = KINECT_DEPTH
    rgb_position: tuple[float, float, float] = (-0.120, -0.0125, 0.6083)
    """camera_rgb_frame in base_footprint (x forward, y left, z up; facing +x)."""
    depth_position: tuple[float, float, float] = (-0.120, 0.0125, 0.6083)
    """camera_depth_frame in base_footprint."""
    min_range: float = 0.5
    max_range: float = 8.0
    disparity_step_coeff: float = 2.85e-3
    noise_disparity_sigma: float = 0.5
    noise_correlation_px: float = 0.0
    """Side of the disparity-noise correlation window in native 640×480 pixels (0: independent)."""
    edge_threshold: float = 0.05
    edge_noise_factor: float = 3.0
    edge_dropout: float = 0.3
    dropout: float = 0.002
    seed: int = 0
    shading: bool = True
    """Lambert-like shading of faces by orientation and a mild distance falloff."""

    def at_resolution(self, width: int, height: int) -> KinectConfig:
        """This configuration rendering both streams at another resolution."""
        return replace(self, rgb=self.rgb.scaled(width, height),
                       depth=self.depth.scaled(width, height))


def ground_truth_odometry_msg(x: float, y: float, theta: float, v: float, w: float,
                              stamp_ns: int = 0, frame_id: str = "map",
                              child_frame_id: str = "base_footprint") -> Any:
    """``nav_msgs/Odometry`` of the true pose (for ``/ground_truth/odom``): pose in
    ``frame_id`` (m, rad), twist in the child frame (m/s, rad/s), zero covariance."""
    from eddiebot.geometry import yaw_to_quaternion
    from eddiebot.msgs.nav_msgs import Odometry

    msg = Odometry(header=Header(stamp=stamp_from_ns(stamp_ns), frame_id=frame_id),
                   child_frame_id=child_frame_id)
    msg.pose.pose.position.x, msg.pose.pose.position.y = float(x), float(y)
    q = msg.pose.pose.orientation
    q.x, q.y, q.z, q.w = (float(c) for c in yaw_to_quaternion(float(theta)))
    msg.twist.twist.linear.x = float(v)
    msg.twist.twist.angular.z = float(w)
    return msg
