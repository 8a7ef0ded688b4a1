"""Odometry links between consecutive nodes: their information from the odometry's covariance,
the small-displacement and moving tests (`RGBD/LinearUpdate`, `RGBD/AngularUpdate`) and
refinement by 2D scan matching (`RGBD/NeighborLinkRefining`)."""

from __future__ import annotations

import numpy as np

from eddiebot.vslam.icp import icp_2d
from eddiebot.vslam.memory import Link, Node
from eddiebot.vslam.occupancy import Scan2D
from eddiebot.vslam.rtabmap.state import F64, RtabmapState
from eddiebot.vslam.transforms import from_xyz_yaw, xyz_rpy, yaw_of

_DEFAULT_ODOM_VARIANCE = 0.001


class OdometryLinks(RtabmapState):
    """Neighbour links from odometry (wheel encoders, visual or ICP odometry)."""

    def _moving(self, delta: F64) -> bool:
        """Upstream rehearsal's test: a translation beyond `RGBD/LinearUpdate` or a rotation
        beyond `RGBD/AngularUpdate` on any axis (0 = any motion)."""
        x, y, z, roll, pitch, yaw = xyz_rpy(delta)
        p = self.params
        return bool(max(abs(x), abs(y), abs(z)) > p.rgbd_linear_update
                    or max(abs(roll), abs(pitch), abs(yaw)) > p.rgbd_angular_update)

    def _small_displacement(self, delta: F64) -> bool:
        p = self.params
        if p.rgbd_linear_update <= 0 and p.rgbd_angular_update <= 0:
            return False
        x, y, z, roll, pitch, yaw = xyz_rpy(delta)
        return (
            max(abs(x), abs(y), abs(z)) <= p.rgbd_linear_update
            and max(abs(roll), abs(pitch), abs(yaw)) <= p.rgbd_angular_update
        )

    def _odom_information(self, covariance: F64 | None) -> F64:
        if covariance is None:
            var = np.full(6, _DEFAULT_ODOM_VARIANCE)
        else:
            var = np.diag(np.asarray(covariance, dtype=np.float64).reshape(6, 6)).copy()
            if var[0] >= 9999 or var[0] == 1.0 or var[0] <= 0:
                var = np.full(6, _DEFAULT_ODOM_VARIANCE)
            var[var <= 0] = _DEFAULT_ODOM_VARIANCE
        if self.params.reg_force_3dof:
            var[2:5] = np.where(var[2:5] <= 0, 1.0, var[2:5])
        return np.asarray(np.diag(1.0 / var), dtype=np.float64)

    def _refine_with_scan(self, link: Link, prev: Node, scan: Scan2D) -> Link:
        """`RGBD/NeighborLinkRefining`: 2D ICP of this scan against the previous node's scan."""
        prev_scan = None if prev.data is None else prev.data.scan_points
        cur = scan.points_in_base()
        if prev_scan is None or prev_scan.shape[0] < 10 or cur.shape[0] < 10:
            return link
        guess = link.transform
        result = icp_2d(prev_scan, cur, np.array([guess[0, 3], guess[1, 3], yaw_of(guess)]))
        if result is None:
            # failure: keep odometry, multiply its covariance by 100
            return Link(link.from_id, link.to_id, link.type, link.transform,
                        link.information / 100.0)
        t = from_xyz_yaw(result.x, result.y, result.theta)
        t[2, 3] = guess[2, 3]
        lin = 1.0 / result.linear_variance
        ang = 1.0 / result.angular_variance
        info = np.diag([lin, lin, link.information[2, 2], link.information[3, 3],
                        link.information[4, 4], ang])
        return Link(link.from_id, link.to_id, link.type, t, info)
