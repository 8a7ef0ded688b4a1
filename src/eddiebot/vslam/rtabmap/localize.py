"""Localization mode (`Mem/IncrementalMemory` false): map→odom moves only for a localization the
odometry cache accepts."""

from __future__ import annotations

import numpy as np

from eddiebot.vslam.memory import Link
from eddiebot.vslam.rtabmap.state import F64, RtabmapState
from eddiebot.vslam.transforms import se3_inverse


class Localize(RtabmapState):
    """Turns accepted closures into map→odom in localization mode."""

    def _localize(self, closure_links: list[Link], odom: F64, odom_info: F64
                  ) -> tuple[F64, str]:
        """Localization mode: map→odom moves only for a localization the odometry cache
        accepts (`RGBD/MaxOdomCacheSize`, `RGBD/OptimizeMaxError`); returns the base pose in
        the map frame and why a localization was rejected ("" if none was)."""
        cache = self._odom_cache
        if cache is not None:
            cache.add(odom, odom_info)
        if not closure_links:
            return self.map_to_odom @ odom, ""
        if cache is None:  # RGBD/MaxOdomCacheSize 0: every localization as is
            link = closure_links[0]
            old_pose = self.optimized_poses.get(link.to_id)
            if old_pose is None:
                return self.map_to_odom @ odom, "the linked map node has no pose"
            pose = old_pose @ se3_inverse(link.transform)
            self.localization_covariance = np.asarray(np.linalg.inv(link.information))
        else:
            check = cache.localize(closure_links, self.optimized_poses)
            if check.pose is None:
                return self.map_to_odom @ odom, check.reason
            pose = check.pose
            self.localization_covariance = check.covariance
        self.map_to_odom = pose @ se3_inverse(odom)
        self._localized = True
        return pose, ""
